"""The mathematical functions a model may call (``fmath.sqrt(x)``).

On numbers they are the standard library's (the Python-hosted FMUs compute with them
unchanged). A value that the standard library cannot take (a traced value of the code
generator, :mod:`pogofmu.codegen.trace`, or a dual number, :mod:`pogofmu.runtime.dual`, over
numbers or traced values) carries its own versions: its class's ``__fmath__`` table, which
these functions call instead. So the generator follows a model's calls without replacing anything
of this module for the time it traces (another thread of the same process running a model on
numbers meanwhile is not affected). A model calls ``fmath.<name>``, never ``math.<name>``: the
standard library's own function would not know a traced value.

When several arguments carry a table, the class with the highest ``__fmath_rank__`` wins (a dual
number holds traced values, so its table is the outer one).

``matvec(M, v)`` is a constant linear map: ``M`` (a :class:`Matrix`, or rows of numbers) is known
when the model is built, ``v`` may be computed. On numbers it is the plain Python loop below; the
generator records it as one operation, printed as a C table and a loop doing the same
multiplications and additions in the same order, and its derivative is the same map on the tangent.
"""
import math

__all__ = ["sqrt", "exp", "log", "cos", "sin", "atan2", "hypot", "tan", "asin", "acos", "atan", "sinh", "cosh",
           "tanh", "log10", "pow", "copysign", "trunc", "isfinite", "is_number", "matvec", "interp", "interp2", "Table", "Table2",
           "Matrix", "NotConstantError"]

# the functions a model may call on a state (named by the generator's refusals)
FUNCTIONS = ("sqrt", "exp", "log", "log10", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh",
             "tanh", "hypot", "pow", "copysign", "isfinite", "trunc", "interp", "interp2")

# the functions a traced value's table must provide (``trunc`` is Python's own protocol,
# ``__trunc__``, and needs no table)
HOOKED = ("sqrt", "exp", "log", "cos", "sin", "atan2", "hypot", "tan", "asin", "acos", "atan", "sinh", "cosh",
          "tanh", "log10", "copysign", "isfinite", "is_number", "matvec", "interp", "interp_slope", "interp2", "interp2_d")


def _table(args):
    """The ``__fmath__`` table of the highest-ranked argument that has one, or None."""
    best, rank = None, None
    for a in args:
        cls = type(a)
        table = getattr(cls, "__fmath__", None)
        if table is not None and (rank is None or cls.__fmath_rank__ > rank):
            best, rank = table, cls.__fmath_rank__
    return best


def _numeric(name, real):
    def fn(*args):
        try:
            return real(*args)
        except Exception:  # not a number for math (or a domain error): a value's own function, if any
            table = _table(args)
            if table is None:
                raise
        return table[name](*args)  # (outside the handler: its errors are not chained to math's)
    fn.__name__ = fn.__qualname__ = name
    fn.__doc__ = f"math.{name} on numbers; the argument's own ``{name}`` on a value that carries one."
    return fn


sqrt = _numeric("sqrt", math.sqrt)
exp = _numeric("exp", math.exp)
log = _numeric("log", math.log)
cos = _numeric("cos", math.cos)
sin = _numeric("sin", math.sin)
atan2 = _numeric("atan2", math.atan2)
hypot = _numeric("hypot", math.hypot)
tan = _numeric("tan", math.tan)
asin = _numeric("asin", math.asin)
acos = _numeric("acos", math.acos)
atan = _numeric("atan", math.atan)
sinh = _numeric("sinh", math.sinh)
cosh = _numeric("cosh", math.cosh)
tanh = _numeric("tanh", math.tanh)
log10 = _numeric("log10", math.log10)
copysign = _numeric("copysign", math.copysign)


def pow(a, b):  # noqa: A001 (the name users know from math)
    """``a ** b`` as Python's float power computes it, one operation of the generated C: 0.0 to a
    negative power raises ZeroDivisionError; a negative base to a non-integer power, which Python
    answers with a complex number, raises ValueError (math domain error); an overflow raises
    OverflowError. (``math.pow`` differs only in the first: ValueError.)"""
    r = a ** b  # (Python's float power raises the OverflowError itself)
    if isinstance(r, complex):
        raise ValueError("math domain error")
    return r


trunc = math.trunc  # (an int: the generated C truncates toward zero the same way; a traced value's __trunc__)


def isfinite(v) -> bool:
    """``v`` is an int or a float and finite (False for anything else: a string, None, NaN)."""
    if isinstance(v, (int, float)):
        return math.isfinite(v)
    table = _table((v,))
    return table["isfinite"](v) if table is not None else False


def is_number(v) -> bool:
    """``v`` is an int or a float and not NaN (infinities are numbers)."""
    if isinstance(v, (int, float)):
        return not math.isnan(v)
    table = _table((v,))
    return table["is_number"](v) if table is not None else False


class NotConstantError(TypeError):
    """A matrix entry of :func:`matvec` that is a computed value (a traced or dual number), not a
    constant known when the model is built."""


CONSTANT_RULE = ("rule: the matrix of fmath.matvec is a constant known when the model is built (numbers computed "
                 "at import or from constants, not from a state, an input, a parameter or the time); build it "
                 "once with fmath.Matrix(rows) at module level")


class Matrix:
    """A constant matrix for :func:`matvec`: ``rows`` of finite ints or floats, all of one length,
    checked once and kept as tuples of floats. Build it once (at module level): a model that
    passes rows of numbers to :func:`matvec` has them checked at every call."""

    __slots__ = ("rows", "n_rows", "n_cols", "_hash")

    def __init__(self, rows):
        if isinstance(rows, Matrix):
            rows = rows.rows
        try:
            rows = [tuple(row) for row in rows]
        except TypeError:
            raise TypeError(f"fmath.Matrix: {type(rows).__name__} is not a sequence of rows of numbers") from None
        n_cols = len(rows[0]) if rows else 0
        out = []
        for i, row in enumerate(rows):
            if len(row) != n_cols:
                raise ValueError(f"fmath.Matrix: row {i} has {len(row)} entries, row 0 has {n_cols}; "
                                 f"rule: every row has the same length")
            for j, a in enumerate(row):
                if not isinstance(a, (int, float)):
                    if _table((a,)) is not None:
                        raise NotConstantError(f"fmath.matvec: the matrix entry [{i}][{j}] is a computed value; "
                                               f"{CONSTANT_RULE}")
                    raise TypeError(f"fmath.Matrix: entry [{i}][{j}] is {type(a).__name__} {a!r}; rule: every "
                                    f"entry is a finite int or float")
                if not math.isfinite(a):
                    raise ValueError(f"fmath.Matrix: entry [{i}][{j}] = {a!r}; rule: every entry is a finite int "
                                     f"or float")
            out.append(tuple(float(a) for a in row))
        self.rows, self.n_rows, self.n_cols, self._hash = tuple(out), len(out), n_cols, None

    def __hash__(self):  # (the generator keys its operations and its C tables by the matrix)
        if self._hash is None:
            self._hash = hash(self.rows)
        return self._hash

    def __eq__(self, other):
        return self is other or (isinstance(other, Matrix) and hash(self) == hash(other) and self.rows == other.rows)

    def __repr__(self):
        return f"fmath.Matrix({self.n_rows} x {self.n_cols})"

    def product(self, v):
        """``M v`` on numbers: row ``k`` is ``((0.0 + M[k][0] v[0]) + M[k][1] v[1]) + ...``, left to
        right (the generated C's loop does the same operations: the same bits)."""
        out = []
        for row in self.rows:
            acc = 0.0
            for a, x in zip(row, v):
                acc += a * x
            out.append(acc)
        return out


def matvec(M, v) -> list:
    """The product ``M v`` of a constant matrix ``M`` (a :class:`Matrix`, or rows of numbers) and a
    vector ``v`` (a sequence of ``M``'s column count), as a list of ``M``'s row count of floats.

    Each row is summed left to right from 0.0 (as ``sum(M[k][e] * v[e] for e in ...)``, on Python
    before 3.12, whose ``sum`` of floats is not compensated). The native generator records it as one
    operation: a constant table in the C and a loop, not one line per entry, and its derivative
    along a tangent ``dv`` is ``M dv``. ``M`` must be a constant (:data:`CONSTANT_RULE`)."""
    if not isinstance(M, Matrix):
        M = Matrix(M)
    v = tuple(v)
    if len(v) != M.n_cols:
        raise ValueError(f"fmath.matvec: a vector of {len(v)} entries for a matrix of {M.n_cols} columns; rule: "
                         f"len(v) is the matrix's column count")
    table = _table(v)
    if table is not None:
        return table["matvec"](M, v)
    return M.product(v)


def _bisect(bs, n, v):
    """(lo, hi): the segment of the increasing breakpoints bs[:n] holding v, by bisection (the
    generated C's loop; v outside or NaN ends in the first or last segment)."""
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if bs[mid] <= v:
            lo = mid
        else:
            hi = mid
    return lo, hi


class Table(Matrix):
    """A 1-D lookup table for :func:`interp`: breakpoints ``xs`` (strictly increasing, at least two)
    and values ``ys`` of the same length, finite numbers, checked once. Build it once, at module
    level (``THRUST = fmath.Table(T_S, F_N)``): the native generator prints it as a ``static const``
    array, and a model that passes lists to :func:`interp` has them checked at every call."""

    __slots__ = ()

    def __init__(self, xs, ys=None):
        if isinstance(xs, Matrix) and ys is None:
            super().__init__(xs.rows)
            return
        try:
            xs, ys = list(xs), list(ys)
        except TypeError:
            raise TypeError("fmath.Table(xs, ys): xs and ys are sequences of numbers") from None
        if len(xs) != len(ys):
            raise ValueError(f"fmath.Table: {len(xs)} breakpoints and {len(ys)} values; rule: len(xs) == len(ys)")
        if len(xs) < 2:
            raise ValueError(f"fmath.Table: {len(xs)} breakpoint(s); rule: at least two")
        try:
            super().__init__([xs, ys])
        except NotConstantError:
            raise NotConstantError("fmath.interp: a table entry is a computed value; rule: the table of "
                                   "fmath.interp is a constant known when the model is built; build it once with "
                                   "fmath.Table(xs, ys) at module level") from None
        except (TypeError, ValueError) as exc:
            raise type(exc)(str(exc).replace("fmath.Matrix: entry [0]", "fmath.Table: xs").replace(
                "fmath.Matrix: entry [1]", "fmath.Table: ys")) from None
        xs = self.rows[0]
        for k in range(1, len(xs)):
            if not xs[k] > xs[k - 1]:
                raise ValueError(f"fmath.Table: xs[{k}] = {xs[k]!r} after xs[{k - 1}] = {xs[k - 1]!r}; rule: the "
                                 f"breakpoints are strictly increasing")

    def __repr__(self):
        return f"fmath.Table({self.n_cols} points)"

    def _segment(self, x):
        """(lo, hi) of the segment holding x, by bisection (the generated C does the same)."""
        return _bisect(self.rows[0], len(self.rows[0]), x)

    def at(self, x):
        """The table at ``x``: linear between breakpoints, held at the ends."""
        xs, ys = self.rows
        if x <= xs[0]:
            return ys[0]
        if x >= xs[-1]:
            return ys[-1]
        lo, hi = self._segment(x)
        return ys[lo] + (ys[hi] - ys[lo]) / (xs[hi] - xs[lo]) * (x - xs[lo])

    def slope_at(self, x):
        """The derivative of :meth:`at`: the segment's slope (the right segment's at a breakpoint),
        0.0 where the table is held."""
        xs, ys = self.rows
        if x <= xs[0] or x >= xs[-1]:
            return 0.0
        lo, hi = self._segment(x)
        return (ys[hi] - ys[lo]) / (xs[hi] - xs[lo])


def interp(x, xs, ys=None):
    """The 1-D table (``xs``, ``ys``) at ``x``, as ``numpy.interp``: linear between the breakpoints,
    held at the ends. ``xs`` may be a :class:`Table` (then ``ys`` is omitted). One operation of the
    generated C: a ``static const`` table searched by bisection, the same arithmetic as here (the
    same bits); its derivative is the segment's slope, exact."""
    T = xs if isinstance(xs, Table) and ys is None else Table(xs, ys)
    table = _table((x,))
    if table is not None:
        return table["interp"](x, T)
    return T.at(x)


def interp_slope(x, T):
    """The slope of :func:`interp` at ``x`` (for the derivatives)."""
    table = _table((x,))
    if table is not None:
        return table["interp_slope"](x, T)
    return T.slope_at(x)


class Table2(Matrix):
    """A 2-D lookup table for :func:`interp2`: breakpoints ``xs`` (``n``) and ``ys`` (``m``), each
    strictly increasing with at least two, and ``table`` of ``n`` rows of ``m`` values
    (``table[i][j]`` at ``(xs[i], ys[j])``), finite numbers, checked once. Kept as one matrix of
    ``n + 2`` rows: ``xs`` and ``ys`` padded with zeros to a common length, then the table."""

    __slots__ = ("nx", "ny")

    def __init__(self, xs, ys, table):
        xs, ys = Table(xs, [0.0] * len(list(xs))).rows[0], Table(ys, [0.0] * len(list(ys))).rows[0]
        rows = [list(r) for r in table]
        if len(rows) != len(xs) or any(len(r) != len(ys) for r in rows):
            raise ValueError(f"fmath.Table2: a table of {len(rows)} rows of "
                             f"{sorted({len(r) for r in rows})} values for {len(xs)} xs and {len(ys)} ys; rule: "
                             f"len(table) == len(xs) and every row has len(ys) values")
        width = max(len(xs), len(ys))
        pad = lambda v: list(v) + [0.0] * (width - len(v))  # noqa: E731
        try:
            super().__init__([pad(xs), pad(ys)] + [pad(r) for r in rows])
        except NotConstantError:
            raise NotConstantError("fmath.interp2: a table entry is a computed value; rule: the table is a constant "
                                   "known when the model is built; build it once with fmath.Table2 at module "
                                   "level") from None
        except (TypeError, ValueError) as exc:
            raise type(exc)(str(exc).replace("fmath.Matrix", "fmath.Table2")) from None
        self.nx, self.ny = len(xs), len(ys)

    def __repr__(self):
        return f"fmath.Table2({self.nx} x {self.ny})"

    @staticmethod
    def _cell(bs, n, v):
        """(lo, hi, w): the segment of breakpoints bs[:n] holding v and v's weight in it, held at the
        ends (bisection, as the generated C)."""
        if v <= bs[0]:
            return 0, 1, 0.0
        if v >= bs[n - 1]:
            return n - 2, n - 1, 1.0
        lo, hi = _bisect(bs, n, v)
        return lo, hi, (v - bs[lo]) / (bs[hi] - bs[lo])

    def _corners(self, x, y):
        """The cell of (x, y) and the table along y on its two x edges: (i0, i1, wx, j0, j1, a, b)."""
        r = self.rows
        i0, i1, wx = self._cell(r[0], self.nx, x)
        j0, j1, wy = self._cell(r[1], self.ny, y)
        a = r[2 + i0][j0] + (r[2 + i0][j1] - r[2 + i0][j0]) * wy
        b = r[2 + i1][j0] + (r[2 + i1][j1] - r[2 + i1][j0]) * wy
        return i0, i1, wx, j0, j1, a, b

    def at(self, x, y):
        """Bilinear between the four corners of the cell holding (x, y), held at the edges."""
        _, _, wx, _, _, a, b = self._corners(x, y)
        return a + (b - a) * wx

    def d_at(self, x, y, which):
        """The partial derivative of :meth:`at` in x (``which`` 0) or y (1): the cell's, 0.0 where held."""
        r = self.rows
        i0, i1, wx, j0, j1, a, b = self._corners(x, y)
        if which == 0:
            if x <= r[0][0] or x >= r[0][self.nx - 1]:
                return 0.0
            return (b - a) / (r[0][i1] - r[0][i0])
        if y <= r[1][0] or y >= r[1][self.ny - 1]:
            return 0.0
        da = r[2 + i0][j1] - r[2 + i0][j0]
        db = r[2 + i1][j1] - r[2 + i1][j0]
        return (da + (db - da) * wx) / (r[1][j1] - r[1][j0])


def interp2(x, y, xs, ys=None, table=None):
    """The 2-D table at ``(x, y)``: bilinear in the cell holding it, held at the edges. ``xs`` may be a
    :class:`Table2` (then ``ys`` and ``table`` are omitted). One operation of the generated C, with the
    same arithmetic (the same bits); its partial derivatives are the cell's, exact."""
    T = xs if isinstance(xs, Table2) and ys is None else Table2(xs, ys, table)
    tb = _table((x, y))
    if tb is not None:
        return tb["interp2"](x, y, T)
    return T.at(x, y)


def interp2_d(x, y, T, which):
    """A partial derivative of :func:`interp2` (``which`` 0: in x, 1: in y), for the derivatives."""
    tb = _table((x, y))
    if tb is not None:
        return tb["interp2_d"](x, y, T, which)
    return T.d_at(x, y, which)
