"""The functions of ``pogofmu.fmath`` that aerospace models use (tan, asin, acos, atan, sinh, cosh,
tanh, log10, pow, copysign), on every path a model's code takes:

* numbers: the standard library's value and errors (ValueError for a domain error, OverflowError
  for a finite argument with an infinite result), ``pow`` as Python's float power;
* dual numbers (the exact Jacobian-vector products of the Python-hosted Rosenbrock method and of
  the native FMUs' generated flow_jvp): the derivative against a central difference;
* the native generator: a user's model file using all of them, exported by ``pogofmu export``, gives
  the Python-hosted FMU's outputs to the bit; ``math.copysign`` on a state is refused naming the
  call and its fmath replacement.
"""
from __future__ import annotations

import math
import re
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pogofmu.runtime import fmath
from pogofmu.runtime.dual import Dual
from support import run_pogofmu

pytestmark = pytest.mark.own_fmus  # (exports its own FMUs)

NEW = ("tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "log10")
DOMAIN = {"asin": (-0.95, 0.95), "acos": (-0.95, 0.95), "log10": (0.05, 50.0), "tan": (-1.4, 1.4)}


@pytest.mark.parametrize("name", NEW)
@settings(max_examples=50, deadline=None, derandomize=True)
@given(u=st.floats(0.0, 1.0))
def test_on_numbers_the_standard_librarys_value_and_on_duals_its_derivative(name, u):
    lo, hi = DOMAIN.get(name, (-5.0, 5.0))
    v = lo + (hi - lo) * u
    f = getattr(fmath, name)
    assert f(v) == getattr(math, name)(v)
    d = f(Dual(v, 1.0))
    h = 1e-6 * max(1.0, abs(v))
    fd = (getattr(math, name)(v + h) - getattr(math, name)(v - h)) / (2 * h)
    assert d.d == pytest.approx(fd, rel=1e-6, abs=1e-8), (name, v)


def test_the_errors_are_the_standard_librarys():
    for f, arg, exc in ((fmath.asin, 1.5, ValueError), (fmath.acos, -2.0, ValueError), (fmath.log10, 0.0, ValueError),
                        (fmath.log10, -1.0, ValueError), (fmath.tan, math.inf, ValueError),
                        (fmath.sinh, 1e3, OverflowError), (fmath.cosh, -1e3, OverflowError)):
        with pytest.raises(exc):
            f(arg)
    with pytest.raises(ValueError, match="math domain error"):
        fmath.pow(-8.0, 1.0 / 3.0)  # (Python's ** answers with a complex number)
    with pytest.raises(ZeroDivisionError):
        fmath.pow(0.0, -1.0)
    with pytest.raises(OverflowError):
        fmath.pow(10.0, 400.0)
    assert fmath.pow(-2.0, 3.0) == -8.0 and fmath.pow(2.0, 0.5) == math.sqrt(2.0)


@settings(max_examples=50, deadline=None, derandomize=True)
@given(a=st.floats(-10, 10), b=st.floats(-10, 10), e=st.floats(-2, 2))
def test_pow_and_copysign_derivatives(a, b, e):
    assert fmath.copysign(a, b) == math.copysign(a, b)
    d = fmath.copysign(Dual(a, 1.0), b)
    if a != 0.0:  # d|a| sign(b) / da = sign(a) sign(b)
        assert d.d == math.copysign(1.0, a) * math.copysign(1.0, b)
    base = abs(a) + 0.5
    p = fmath.pow(Dual(base, 1.0), e)
    assert p.d == pytest.approx(e * base ** (e - 1), rel=1e-12)


FUNCS = '''
import math
from pogofmu import HybridModel, Parameter, Variable, fmath


def flow(t, x, q, u, p):
    s = fmath.tanh(x[0]) + fmath.atan(x[1]) + {copysign}(0.5, x[1])
    r = fmath.log10(1.0 + x[0] * x[0]) + fmath.pow(1.0 + x[0] * x[0], 0.25)
    w = fmath.sinh(0.1 * x[1]) - fmath.cosh(0.1 * x[0]) + fmath.tan(0.2 * x[0])
    a = fmath.asin(0.5 * fmath.sin(x[0])) + fmath.acos(0.5 * fmath.cos(x[1]))
    return [x[1], -p.k * x[0] - 0.1 * s + 0.01 * (r + w + a)]


MODEL = HybridModel(
    name="{name}", description="an oscillator whose force uses the functions of fmath",
    states=(Variable("x", "m", "position"), Variable("v", "m/s", "velocity")),
    parameters=(Parameter("k", 4.0, "1/s2", "stiffness"),),
    inputs=(),
    outputs=(Variable("x", "m", "position"), Variable("v", "m/s", "velocity"), Variable("f", "", "a function")),
    flow=flow, events=(),
    initial=lambda p: ([1.0, 0.0], {{}}),
    output_fn=lambda t, x, q, u, p: {{"x": x[0], "v": x[1], "f": fmath.tanh(x[0]) * fmath.pow(2.0, x[1])}},
    default_stop_time=5.0,
)
'''


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fmath")
    (folder / "funcs.py").write_text(FUNCS.format(name="Funcs", copysign="fmath.copysign"))
    (folder / "bad.py").write_text(FUNCS.format(name="Bad", copysign="math.copysign"))
    proc = run_pogofmu("export", "funcs.py", "bad.py", "--out", "out", "--platforms", "x86_64-linux", cwd=folder,
                       timeout=600)
    return folder, proc


def test_a_model_using_the_functions_gives_the_same_bits_in_both_backends(exported):
    from fmpy import simulate_fmu

    folder, proc = exported
    out = folder / "out"
    runs = {}
    for kind in ("Funcs.fmu", "native/Funcs.fmu", "fmi3/Funcs.fmu", "native/fmi3/Funcs.fmu"):
        kw = {} if "fmi3" not in kind else dict(fmi_type="CoSimulation")
        runs[kind] = simulate_fmu(str(out / kind), stop_time=5.0, output_interval=1e-2, **kw)
    first = runs["Funcs.fmu"]
    for kind, res in runs.items():
        for col in ("x", "v", "f"):
            assert np.array_equal(res[col], first[col]), (kind, col)
    # and the functions are the ones named: the output f against numpy on the states served
    assert np.allclose(first["f"], np.tanh(first["x"]) * 2.0 ** first["v"], rtol=1e-15, atol=0)


def test_math_copysign_on_a_state_is_refused_naming_the_call_and_its_replacement(exported):
    folder, proc = exported
    assert proc.returncode == 1, proc.stdout + proc.stderr  # the Python-hosted FMUs are written
    text = proc.stderr
    assert "bad.py:7:" in text and "math.copysign(...) of a traced value" in text, text
    assert "Rewrite: fmath.copysign(...)" in text and "math.sqrt" not in text, text
    assert (folder / "out" / "Bad.fmu").exists() and not (folder / "out" / "native" / "Bad.fmu").exists()


# ---- fmath.interp: a 1-D table ---------------------------------------------------------------------
ROCKET = '''
from pogofmu import HybridModel, Parameter, Variable, fmath

T_S = {t_s}
F_N = (0.0, 900.0, 800.0, 760.0, 600.0, 100.0, 0.0)
THRUST = fmath.Table(T_S, F_N)
DRAG = fmath.Table((0.0, 50.0, 150.0, 300.0), (0.0, 1.0, 12.0, 60.0))


def flow(t, x, q, u, p):
    return [x[1], (fmath.interp(t, THRUST) - fmath.interp(x[1], DRAG)) / p.m - p.g]


MODEL = HybridModel(
    name="{name}", description="a vertical rocket with a tabulated thrust curve and drag",
    states=(Variable("h", "m", "altitude"), Variable("v", "m/s", "vertical speed")),
    parameters=(Parameter("m", 20.0, "kg", "mass"), Parameter("g", 9.81, "m/s2", "gravity")),
    inputs=(),
    outputs=(Variable("h", "m", "altitude"), Variable("v", "m/s", "vertical speed"), Variable("F", "N", "thrust")),
    flow=flow, events=(),
    initial=lambda p: ([0.0, 0.0], {{}}),
    output_fn=lambda t, x, q, u, p: {{"h": x[0], "v": x[1], "F": fmath.interp(t, THRUST)}},
    default_stop_time=4.0, default_step=1e-2,
)
'''
T_S = (0.0, 0.1, 0.5, 1.5, 2.5, 2.8, 3.0)
F_N = (0.0, 900.0, 800.0, 760.0, 600.0, 100.0, 0.0)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(x=st.floats(-1.0, 4.0))
def test_interp_is_numpys_and_its_derivative_the_segments_slope(x):
    T = fmath.Table(T_S, F_N)
    assert fmath.interp(x, T) == pytest.approx(float(np.interp(x, T_S, F_N)), rel=1e-15, abs=1e-12)
    assert fmath.interp(x, list(T_S), list(F_N)) == fmath.interp(x, T)
    d = fmath.interp(Dual(x, 1.0), T)
    k = int(np.searchsorted(T_S, x, side="right"))  # the segment [k-1, k] holding x (the right one at a breakpoint)
    slope = 0.0 if x <= T_S[0] or x >= T_S[-1] else (F_N[k] - F_N[k - 1]) / (T_S[k] - T_S[k - 1])
    assert (d.d if isinstance(d, Dual) else 0.0) == slope


@pytest.mark.parametrize("xs, ys, rule", [
    ((0.0, 1.0, 1.0), (1.0, 2.0, 3.0), "strictly increasing"),
    ((0.0, 1.0), (1.0, 2.0, 3.0), "len(xs) == len(ys)"),
    ((0.0,), (1.0,), "at least two"),
    ((0.0, 1.0), (1.0, math.nan), "finite"),
])
def test_a_table_that_breaks_a_rule_is_refused_naming_it(xs, ys, rule):
    with pytest.raises(ValueError, match=re.escape(rule)):
        fmath.Table(xs, ys)


@pytest.fixture(scope="module")
def rockets(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rocket")
    (folder / "rocket.py").write_text(ROCKET.format(name="Rocket", t_s=repr(T_S)))
    (folder / "bad_rocket.py").write_text(ROCKET.format(name="BadRocket", t_s="(0.0, 0.1, 0.5, 0.4, 2.5, 2.8, 3.0)"))
    good = run_pogofmu("export", "rocket.py", "--out", "out", "--platforms", "x86_64-linux", cwd=folder, timeout=600)
    bad = run_pogofmu("export", "bad_rocket.py", "--out", "out", "--platforms", "x86_64-linux", cwd=folder, timeout=600)
    return folder, good, bad


def test_a_thrust_curve_gives_the_same_bits_in_every_kind_and_numpys_interp(rockets):
    from fmpy import simulate_fmu

    folder, good, _ = rockets
    assert good.returncode == 0, good.stdout + good.stderr
    runs = {}
    for kind in ("Rocket.fmu", "native/Rocket.fmu", "fmi3/Rocket.fmu", "native/fmi3/Rocket.fmu"):
        kw = {} if "fmi3" not in kind else dict(fmi_type="CoSimulation")
        runs[kind] = simulate_fmu(str(folder / "out" / kind), stop_time=4.0, output_interval=1e-2, **kw)
    first = runs["Rocket.fmu"]
    for kind, res in runs.items():
        assert all(np.array_equal(res[c], first[c]) for c in ("h", "v", "F")), kind
    assert np.allclose(first["F"], np.interp(first["time"], T_S, F_N), rtol=1e-14, atol=1e-12)
    # burnout at 3 s: from then on a ballistic arc with drag, so the speed falls faster than g alone
    late = first["time"] > 3.0 + 1e-9
    assert np.all(np.diff(first["v"][late]) < -9.81 * 1e-2 * (1 - 1e-9))


def test_a_table_with_decreasing_breakpoints_is_refused_at_export_with_its_line(rockets):
    folder, _, bad = rockets
    assert bad.returncode == 2, bad.stdout + bad.stderr
    assert "bad_rocket.py:6:" in bad.stderr and "xs[3] = 0.4 after xs[2] = 0.5" in bad.stderr, bad.stderr
    assert "strictly increasing" in bad.stderr and not (folder / "out" / "BadRocket.fmu").exists()


# a thrust table in time with the steps ending on its kinks, as docs/writing-models.md says to write it: a
# step across a kink is accepted with an error the embedded pair does not see (DOPRI5 6.4e-5 m/s off at
# rel_tol 1e-6 and 1e-8 alike, a user's audit); ending the steps on the breakpoints makes each segment a cubic
KINKED = '''
from pogofmu import HybridModel, Parameter, TimeEvent, Variable, fmath

T_S = (0.0, 0.1, 0.5, 1.5, 2.5, 2.8, 3.0)
F_N = (0.0, 900.0, 800.0, 760.0, 600.0, 100.0, 0.0)
THRUST = fmath.Table(T_S, F_N)

MODEL = HybridModel(
    name="Kinked", description="a thrust table in time, its steps ending on its breakpoints",
    states=(Variable("h", "m", "altitude"), Variable("v", "m/s", "vertical speed")),
    parameters=(Parameter("m", 20.0, "kg", "mass"), Parameter("g", 9.81, "m/s2", "gravity")),
    inputs=(),
    outputs=(Variable("h", "m", "altitude"), Variable("v", "m/s", "vertical speed")),
    flow=lambda t, x, q, u, p: [x[1], fmath.interp(t, THRUST) / p.m - p.g],
    events=(),
    time_events=tuple(TimeEvent(f"kink{i}", at=lambda p, tk=tk: tk, jump=lambda x, q, u, p: (x, q))
                      for i, tk in enumerate(T_S[1:])),
    initial=lambda p: ([0.0, 0.0], {}),
    output_fn=lambda t, x, q, u, p: {"h": x[0], "v": x[1]},
    default_stop_time=3.0, default_step=1e-2,
)
'''


def _thrust_closed_form(t_end):
    """h and v at t_end of h\' = v, v\' = F(t)/m - g from rest, F piecewise linear: exact rationals."""
    ts = [Fraction(str(t)) for t in T_S]
    fs = [Fraction(str(f)) for f in F_N]
    m, g = Fraction(20), Fraction("9.81")
    h = v = Fraction(0)
    for k in range(len(ts) - 1):
        a, b = ts[k], min(ts[k + 1], Fraction(str(t_end)))
        if b <= a:
            break
        d, s = b - a, (fs[k + 1] - fs[k]) / (ts[k + 1] - ts[k])
        h += v * d + (fs[k] / m - g) * d * d / 2 + s / m * d ** 3 / 6
        v += (fs[k] / m - g) * d + s / m * d * d / 2
    return float(h), float(v)


def test_a_thrust_table_with_its_steps_ending_on_the_kinks_is_its_closed_form(tmp_path):
    from fmpy import simulate_fmu

    (tmp_path / "kinked.py").write_text(KINKED)
    proc = run_pogofmu("export", "kinked.py", "--out", "out", "--platforms", "x86_64-linux", cwd=tmp_path, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for kind in ("Kinked.fmu", "native/Kinked.fmu"):
        for method in (0, 8):
            for rel_tol in (1e-6, 1e-8):
                res = simulate_fmu(str(tmp_path / "out" / kind), stop_time=3.0, output_interval=0.1,
                                   start_values={"method": method, "rel_tol": rel_tol})
                for t_k, h, v in zip(res["time"], res["h"], res["v"]):
                    h_ref, v_ref = _thrust_closed_form(t_k)
                    assert abs(v - v_ref) <= 1e-12 * (1 + abs(v_ref)), (kind, method, rel_tol, t_k, v, v_ref)
                    assert abs(h - h_ref) <= 1e-12 * (1 + abs(h_ref)), (kind, method, rel_tol, t_k, h, h_ref)


# ---- fmath.interp2: a 2-D table --------------------------------------------------------------------
MACH = (0.0, 0.5, 0.9, 1.2, 2.0)
ALPHA = (-0.2, 0.0, 0.1, 0.3)
CL = ((-0.8, 0.0, 0.45, 1.2), (-0.85, 0.0, 0.5, 1.3), (-1.0, 0.0, 0.6, 1.5), (-0.9, 0.0, 0.55, 1.35),
      (-0.6, 0.0, 0.35, 0.9))


@settings(max_examples=100, deadline=None, derandomize=True)
@given(x=st.floats(-0.5, 2.5), y=st.floats(-0.4, 0.5))
def test_interp2_is_bilinear_held_at_the_edges_and_its_partials_are_the_cells(x, y):
    from scipy.interpolate import RegularGridInterpolator

    T = fmath.Table2(MACH, ALPHA, CL)
    ref = RegularGridInterpolator((MACH, ALPHA), np.array(CL), method="linear")
    xc, yc = min(max(x, MACH[0]), MACH[-1]), min(max(y, ALPHA[0]), ALPHA[-1])  # held at the edges
    assert fmath.interp2(x, y, T) == pytest.approx(float(ref([[xc, yc]])[0]), rel=1e-13, abs=1e-14)
    assert fmath.interp2(x, y, MACH, ALPHA, CL) == fmath.interp2(x, y, T)
    # the partials: central differences inside one cell (away from the breakpoints), 0 where held
    h = 1e-7
    near = lambda v, bs: min(abs(v - b) for b in bs) < 2 * h  # noqa: E731
    if not near(x, MACH) and not near(y, ALPHA):
        dx = fmath.interp2(Dual(x, 1.0), y, T)
        dy = fmath.interp2(x, Dual(y, 1.0), T)
        fx = (fmath.interp2(x + h, y, T) - fmath.interp2(x - h, y, T)) / (2 * h)
        fy = (fmath.interp2(x, y + h, T) - fmath.interp2(x, y - h, T)) / (2 * h)
        assert (dx.d if isinstance(dx, Dual) else 0.0) == pytest.approx(fx, abs=1e-6)
        assert (dy.d if isinstance(dy, Dual) else 0.0) == pytest.approx(fy, abs=1e-6)


def test_a_2d_table_that_breaks_a_rule_is_refused_naming_it():
    with pytest.raises(ValueError, match="strictly increasing"):
        fmath.Table2((0.0, 1.0, 0.5), ALPHA, CL[:3])
    with pytest.raises(ValueError, match=r"len\(table\) == len\(xs\)"):
        fmath.Table2(MACH, ALPHA, CL[:4])
    with pytest.raises(ValueError, match="finite"):
        fmath.Table2(MACH, ALPHA, CL[:4] + ((math.inf, 0.0, 0.0, 0.0),))


AERO = '''
from pogofmu import HybridModel, Parameter, Variable, fmath

TABLE = fmath.Table2({mach!r}, {alpha!r}, {cl!r})


def flow(t, x, q, u, p):
    return [x[1], p.c * fmath.interp2(0.3 + 0.2 * x[1], x[0], TABLE) - p.k * x[0]]


MODEL = HybridModel(
    name="Aero", description="a pitch oscillator with a lift table in Mach and angle of attack",
    states=(Variable("a", "rad", "angle of attack"), Variable("w", "rad/s", "pitch rate")),
    parameters=(Parameter("k", 9.0, "1/s2", "stiffness"), Parameter("c", 2.0, "rad/s2", "lift gain")),
    inputs=(),
    outputs=(Variable("a", "rad", "angle"), Variable("L", "", "lift coefficient")),
    flow=flow, events=(),
    initial=lambda p: ([0.25, 0.0], {{}}),
    output_fn=lambda t, x, q, u, p: {{"a": x[0], "L": fmath.interp2(0.3 + 0.2 * x[1], x[0], TABLE)}},
    default_stop_time=5.0, default_step=1e-2,
)
'''


def test_a_2d_table_gives_the_same_bits_in_every_kind(tmp_path):
    from fmpy import simulate_fmu

    (tmp_path / "aero.py").write_text(AERO.format(mach=MACH, alpha=ALPHA, cl=CL))
    proc = run_pogofmu("export", "aero.py", "--out", "out", "--platforms", "x86_64-linux", cwd=tmp_path, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    runs = {}
    for kind in ("Aero.fmu", "native/Aero.fmu", "fmi3/Aero.fmu", "native/fmi3/Aero.fmu"):
        for method in (5, 1):  # Dormand-Prince; Rodas5P, whose Jacobian takes the table's partials
            kw = {} if "fmi3" not in kind else dict(fmi_type="CoSimulation")
            runs[kind, method] = simulate_fmu(str(tmp_path / "out" / kind), stop_time=5.0, output_interval=1e-2,
                                              start_values={"method": method}, **kw)
    for method in (5, 1):
        first = runs["Aero.fmu", method]
        for (kind, m), res in runs.items():
            if m == method:
                assert all(np.array_equal(res[c], first[c]) for c in ("a", "L")), (kind, method)
    # the two methods solve the same problem
    assert np.allclose(runs["Aero.fmu", 5]["a"], runs["Aero.fmu", 1]["a"], atol=1e-4)
