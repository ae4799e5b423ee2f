"""``fmath.matvec(M, v)``, a constant linear map (docs/writing-models.md, section 8): on numbers
the plain Python product summed left to right; traced, one operation printed as a C table and a
loop (O(rows + columns) lines of C, not O(rows x columns)); its derivative the same map on the
tangent; a matrix that is not a constant refused in one line naming the model, the function and
the rule."""
from __future__ import annotations

import ctypes as C
import functools
import math
import random

import pytest

from native_model import MSG, NativeModel, PgMsg, arr
from pogofmu import HybridModel, Parameter, Variable, fmath
from pogofmu.codegen.build import c_compiler, model_library
from pogofmu.codegen.cmodel import generate
from pogofmu.runtime.dual import Dual
from pogofmu.codegen.trace import TraceError, explore, symbol
from pogofmu.runtime.model import Params
from support import needs_mark

pytestmark = pytest.mark.own_fmus  # (exports its own FMUs, or needs none)

D = C.POINTER(C.c_double)
JVP = C.CFUNCTYPE(C.c_int, C.c_double, D, D, D, D, D, D, D, MSG)
needs_cc = needs_mark(c_compiler() is not None, "a C compiler (Debian gcc, or the ziglang PyPI package of pyproject.toml)")

# the reference: each row's products added left to right from 0.0, written here
def left_to_right(rows, v):
    return [functools.reduce(lambda acc, p: acc + p, (a * x for a, x in zip(row, v)), 0.0) for row in rows]


def test_on_numbers_it_is_the_products_added_left_to_right():
    rng = random.Random(30)
    rows = [[rng.uniform(-2, 2) for _ in range(7)] for _ in range(5)]
    for _ in range(50):
        v = [rng.uniform(-1e3, 1e3) * 10.0 ** rng.randint(-8, 8) for _ in range(7)]
        assert fmath.matvec(rows, v) == left_to_right(rows, v)
        assert fmath.matvec(fmath.Matrix(rows), v) == left_to_right(rows, v)
    # the order is Python's: 1 is lost against 1e100 left to right (a compensated or reversed sum gives 1.0)
    assert fmath.matvec([[1.0, 1.0, 1.0]], [1.0, 1e100, -1e100]) == [0.0]
    assert math.fsum([1.0, 1e100, -1e100]) == 1.0
    # integers: the exact product
    assert fmath.matvec([[1, 2], [3, -4], [0, 5]], [7, 11]) == [29.0, -23.0, 55.0]
    assert all(type(y) is float for y in fmath.matvec([[1, 2]], [3, 4]))
    assert fmath.matvec([], []) == [] and fmath.matvec([[], []], []) == [0.0, 0.0]


def test_a_dual_number_gets_the_same_map_on_its_tangent():
    y = fmath.matvec([[1.0, 2.0], [3.0, 4.0]], [Dual(1.0, 1.0), 5.0])
    assert [(d.v, d.d) for d in y] == [(11.0, 1.0), (23.0, 3.0)]
    y = fmath.matvec([[1.0, 2.0], [3.0, 4.0]], [Dual(1.0, 0.5), Dual(5.0, -2.0)])
    assert [(d.v, d.d) for d in y] == [(11.0, -3.5), (23.0, -6.5)]


@pytest.mark.parametrize("rows, v, words", [
    ([[1.0, 2.0], [3.0]], [1.0, 1.0], "row 1 has 1 entries, row 0 has 2; rule: every row has the same length"),
    ([[1.0, math.nan]], [1.0, 1.0], "entry [0][1] = nan; rule: every entry is a finite int or float"),
    ([[1.0, math.inf]], [1.0, 1.0], "entry [0][1] = inf; rule"),
    ([[1.0, "2"]], [1.0, 1.0], "entry [0][1] is str '2'; rule"),
    ([[1.0, 2.0]], [1.0], "a vector of 1 entries for a matrix of 2 columns; rule"),
    (3.0, [1.0], "float is not a sequence of rows of numbers"),
])
def test_a_malformed_matrix_or_vector_is_refused_in_one_line(rows, v, words):
    with pytest.raises((TypeError, ValueError)) as err:
        fmath.matvec(rows, v)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_traced_it_is_one_operation_and_one_element_per_row():
    M = fmath.Matrix([[1.0 / (1 + i + j) for j in range(100)] for i in range(100)])
    paths = explore(lambda: fmath.matvec(M, [symbol("u", i) for i in range(100)]), "test")
    ops = [n.op for n in paths[0].nodes]
    assert len(paths) == 1 and sorted(set(ops)) == ["elem", "in", "matvec"]
    assert (ops.count("in"), ops.count("matvec"), ops.count("elem")) == (100, 1, 100)
    # the same product twice is the same operation (hash-consed), a vector with constants is recorded
    # with them, and a vector of numbers only is computed in Python
    paths = explore(lambda: fmath.matvec(M, [symbol("u", 0)] + [0.5] * 99) + fmath.matvec(
        M, [symbol("u", 0)] + [0.5] * 99) + fmath.matvec(M, [0.5] * 100), "test")
    ops = [n.op for n in paths[0].nodes]
    assert ops.count("matvec") == 1 and ops.count("elem") == 100
    assert paths[0].result[1][200:] == M.product([0.5] * 100)


@pytest.mark.parametrize("where", ["rows", "Matrix"])
def test_a_matrix_that_is_not_a_constant_is_refused_in_one_line_naming_the_rule(where):
    def traced():
        g = symbol("p", 0)
        rows = [[1.0, g], [0.0, 1.0]]
        return fmath.matvec(rows if where == "rows" else fmath.Matrix(rows), [symbol("u", 0), symbol("u", 1)])
    with pytest.raises(TraceError) as err:
        explore(traced, "Model: outputs")
    text = str(err.value)
    assert "Model: outputs: fmath.matvec: the matrix entry [0][1] is a computed value; rule: the matrix of " \
           "fmath.matvec is a constant known when the model is built" in text, text
    assert "test_matvec.py:" in text and "\n" not in text and "on the path" not in text


def test_a_dual_entry_in_the_matrix_is_not_a_constant_either():
    with pytest.raises(fmath.NotConstantError, match=r"the matrix entry \[1\]\[0\] is a computed value; rule"):
        fmath.matvec([[1.0], [Dual(2.0, 1.0)]], [1.0])



def model_rows(n):
    return [[1.0 / (1 + i + 2 * j) for j in range(n)] for i in range(n)]


def square(n, unrolled=False):
    """y = M u with an n x n dense matrix, through matvec or as the unrolled sums."""
    rows = model_rows(n)
    M = fmath.Matrix(rows)
    if unrolled:
        def out(t, x, q, u, p):
            return {f"y{k}": sum(rows[k][e] * u[e] for e in range(n)) for k in range(n)}
    else:
        def out(t, x, q, u, p):
            return dict(zip((f"y{k}" for k in range(n)), fmath.matvec(M, u)))
    return HybridModel(name="Square", description="y = M u", states=(), parameters=(),
                       inputs=tuple(Variable(f"u{k}", "1", "input", 0.0) for k in range(n)),
                       outputs=tuple(Variable(f"y{k}", "1", "output") for k in range(n)),
                       flow=lambda t, x, q, u, p: [], events=(), initial=lambda p: ([], {}), output_fn=out,
                       feedthrough={f"y{k}": tuple(f"u{e}" for e in range(n)) for k in range(n)})


def test_the_c_of_a_100_x_100_map_grows_by_rows_not_by_entries():
    """From 50 to 100 rows the file grows by a few lines per row (the table's row, the input, the
    element, the output, and the same in the derivative), where the unrolled sums grow by twice the
    row count per row; the 100 x 100 table is printed once, for the outputs and their derivative."""
    lines = {n: len(generate(square(n)).splitlines()) for n in (50, 100)}
    assert lines[100] - lines[50] <= 10 * 50, lines
    c = generate(square(100))
    assert c.count("static const double pg_matrix_") == 1 and c.count("pg_matrix_0[r][c]") == 2
    unrolled = {n: len(generate(square(n, unrolled=True)).splitlines()) for n in (10, 20)}
    assert unrolled[20] - unrolled[10] > 10 * 10, unrolled  # what the bound above would catch


def mixed():
    """A nonlinear vector through two constant maps, in the outputs and in the flow."""
    A = fmath.Matrix([[1.0, 2.0, -0.5, 0.25], [0.1, 0.0, 3.0, -1.0], [-7.0, 1e-3, 0.3, 2.0]])

    def out(t, x, q, u, p):
        y = fmath.matvec(A, [fmath.sin(u[0]), u[1] * u[2], x[0], p.c])
        return {"y0": y[0], "y1": y[1], "y2": y[2] * y[0]}

    return A, HybridModel(
        name="Mixed", description="matvec in the outputs and the flow", states=(Variable("z", "1", "state", 0.5),),
        parameters=(Parameter("c", 2.0, "", "a constant of the vector"),),
        inputs=tuple(Variable(f"u{k}", "1", "input", 0.0) for k in range(3)),
        outputs=tuple(Variable(f"y{k}", "1", "output") for k in range(3)),
        flow=lambda t, x, q, u, p: fmath.matvec([[-1.0, 0.5]], [x[0], u[0] * u[0]]),
        events=(), initial=lambda p: ([0.5], {}), output_fn=out,
        feedthrough={f"y{k}": ("u0", "u1", "u2") for k in range(3)})


@pytest.fixture(scope="module")
def native_mixed(tmp_path_factory):
    A, model = mixed()
    return A, model, NativeModel(model_library(model, tmp_path_factory.mktemp("matvec")))


def _jvp(lib, which, t, x, u, p, sx, su, n_out):
    fn = JVP(getattr(lib.m, which))
    msg, out = PgMsg(), (C.c_double * n_out)()
    assert fn(t, arr(x, 1), arr([], 1), arr(u), arr(p), arr(sx, 1), arr(su), out, C.byref(msg)) == 0
    return list(out)


@needs_cc
def test_the_generated_c_gives_the_python_bits_and_the_exact_derivative(native_mixed):
    A, model, lib = native_mixed
    rng = random.Random(7)
    cases = [([1.0, 1e100, -1e100], 1e-300, 1e100)] + [
        ([rng.uniform(-3, 3) for _ in range(3)], rng.uniform(-3, 3), rng.uniform(-3, 3)) for _ in range(200)]
    for u, z, c in cases:
        py = model.output_fn(0.0, [z], {}, tuple(u), Params({"c": c}))
        assert lib.outputs(0.0, [z], [], u, [c]) == ("ok", [py["y0"], py["y1"], py["y2"]])
        assert lib.flow(0.0, [z], [], u, [c]) == ("ok", model.flow(0.0, [z], {}, tuple(u), Params({"c": c})))
    rows = A.rows
    for u, z, c in cases[1:40]:
        su, sz = [rng.uniform(-1, 1) for _ in range(3)], rng.uniform(-1, 1)
        dy = _jvp(lib, "outputs_jvp", 0.0, [z], u, [c], [sz], su, 3)
        # closed form: y = A v, v = (sin u0, u1 u2, z, c), dv = (cos u0 su0, u2 su1 + u1 su2, sz, 0)
        v = [math.sin(u[0]), u[1] * u[2], z, c]
        dv = [math.cos(u[0]) * su[0], u[2] * su[1] + u[1] * su[2], sz, 0.0]
        y = [sum(a * b for a, b in zip(row, v)) for row in rows]
        dyy = [sum(a * b for a, b in zip(row, dv)) for row in rows]
        want = [dyy[0], dyy[1], dyy[2] * y[0] + y[2] * dyy[0]]
        assert dy == pytest.approx(want, rel=1e-13, abs=1e-13)
        # and central differences of the generated outputs along the seed
        h = 1e-6

        def at(s):
            return lib.outputs(0.0, [z + s * sz], [], [a + s * b for a, b in zip(u, su)], [c])[1]
        fd = [(a - b) / (2 * h) for a, b in zip(at(h), at(-h))]
        assert dy == pytest.approx(fd, rel=1e-6, abs=1e-8)
        df = _jvp(lib, "flow_jvp", 0.0, [z], u, [c], [sz], su, 1)
        assert df == pytest.approx([-sz + 0.5 * 2 * u[0] * su[0]], rel=1e-14, abs=1e-15)


@needs_cc
def test_a_wide_map_compiles_and_gives_the_python_bits(tmp_path):
    model = square(100)
    lib = NativeModel(model_library(model, tmp_path))
    rng = random.Random(11)
    for _ in range(20):
        u = [rng.uniform(-1, 1) * 10.0 ** rng.randint(-5, 5) for _ in range(100)]
        py = model.output_fn(0.0, [], {}, tuple(u), Params({}))
        assert lib.outputs(0.0, [], [], u, []) == ("ok", [py[f"y{k}"] for k in range(100)])
        assert [py[f"y{k}"] for k in range(100)] == left_to_right(model_rows(100), u)
        su = [0.0] * 100
        su[37] = 1.0  # the derivative along u37 is column 37
        assert _jvp(lib, "outputs_jvp", 0.0, [], u, [], [], su, 100) == [row[37] for row in model_rows(100)]

