"""Forward-mode derivatives of a model's own functions: dual numbers.

A :class:`Dual` is a value and its tangent (the derivative along a seed direction). Calling a
model function with duals in place of its states gives its value and its Jacobian-vector product
from the model's own code, with no second copy of any equation. Branches of the model (modes,
``max``, ``abs``) are decisions on the *values*, so the derivative is that of the branch taken.

The parts are numbers or values that carry their own math (a class with an ``__fmath__`` table,
:mod:`.fmath`):

* on floats, inside a Python-hosted FMU and the host tools, a column of the flow's exact Jacobian
  for the engine's Rosenbrock method (``flow_jvp`` of the Python binding, :mod:`.solver.cengine`);
* on traced values (``pogofmu.codegen.trace.Sym``), inside the code generator's trace: the
  function's operations *and* those of the chain rule, printed as C, are the native FMUs'
  ``flow_jvp`` and ``outputs_jvp``.

Both run the same operations in the same order, so the two give the same bits. A tangent that is
known to be zero is a plain number ``0`` and costs no operation. A function a dual number cannot
follow (``float(v)``, ``math.sqrt(v)`` instead of ``fmath.sqrt(v)``) raises
:class:`NotDifferentiable`.
"""
from __future__ import annotations

from . import fmath


class NotDifferentiable(TypeError):
    """A model function did something a dual number cannot follow (its derivative is not taken)."""


_NUMBER = (int, float)


def _zero(d) -> bool:
    return isinstance(d, _NUMBER) and d == 0


# (_zero written out in the three below: they run at every operation of a Jacobian's columns)
def _add(a, b):
    if isinstance(a, _NUMBER) and a == 0:
        return b
    if isinstance(b, _NUMBER) and b == 0:
        return a
    return a + b


def _sub(a, b):
    if isinstance(b, _NUMBER) and b == 0:
        return a
    if isinstance(a, _NUMBER) and a == 0:
        return -b
    return a - b


def _mul(a, b):
    """A product where ``b`` is a tangent (zero skips the operation)."""
    if (isinstance(b, _NUMBER) and b == 0) or (isinstance(a, _NUMBER) and a == 0):
        return 0.0
    return a * b


def _parts(v):
    """(value, tangent) of an operand: a number or a value with its own math has a zero tangent."""
    if isinstance(v, Dual):
        return v.v, v.d
    if isinstance(v, _NUMBER) or hasattr(type(v), "__fmath__"):
        return v, 0.0
    raise NotDifferentiable(f"a derivative of an operation on {type(v).__name__} {v!r}")


class Dual:
    """``v + d ε`` with ``ε² = 0``: the value ``v`` and the tangent ``d``."""

    __slots__ = ("v", "d")
    __hash__ = None

    def __init__(self, v, d=0.0):
        self.v, self.d = v, d

    # ---- arithmetic ----
    def __add__(self, o):
        ov, od = _parts(o)
        return Dual(self.v + ov, _add(self.d, od))

    def __radd__(self, o):
        ov, od = _parts(o)
        return Dual(ov + self.v, _add(od, self.d))

    def __sub__(self, o):
        ov, od = _parts(o)
        return Dual(self.v - ov, _sub(self.d, od))

    def __rsub__(self, o):
        ov, od = _parts(o)
        return Dual(ov - self.v, _sub(od, self.d))

    def __mul__(self, o):
        ov, od = _parts(o)
        return Dual(self.v * ov, _add(_mul(ov, self.d), _mul(self.v, od)))

    def __rmul__(self, o):
        ov, od = _parts(o)
        return Dual(ov * self.v, _add(_mul(ov, self.d), _mul(self.v, od)))

    def __truediv__(self, o):
        ov, od = _parts(o)
        q = self.v / ov
        return Dual(q, _tangent_div(self.d, q, od, ov))

    def __rtruediv__(self, o):
        ov, od = _parts(o)
        q = ov / self.v
        return Dual(q, _tangent_div(od, q, self.d, self.v))

    def __pow__(self, o):
        return _pow(self, o)

    def __rpow__(self, o):
        return _pow(o, self)

    def __neg__(self):
        return Dual(-self.v, 0.0 if _zero(self.d) else -self.d)

    def __pos__(self):
        return self

    def __abs__(self):
        if self.v >= 0:  # a decision on the value: the derivative of the branch taken
            return Dual(abs(self.v), self.d)
        return Dual(abs(self.v), 0.0 if _zero(self.d) else -self.d)

    def __trunc__(self):
        return fmath.trunc(self.v)

    # ---- comparisons and truth: the value's ----
    def __lt__(self, o): return self.v < _parts(o)[0]
    def __le__(self, o): return self.v <= _parts(o)[0]
    def __gt__(self, o): return self.v > _parts(o)[0]
    def __ge__(self, o): return self.v >= _parts(o)[0]
    def __eq__(self, o): return self.v == _parts(o)[0]
    def __ne__(self, o): return self.v != _parts(o)[0]

    def __bool__(self):
        return bool(self.v)

    def __float__(self):
        raise NotDifferentiable("float() of a dual number, or a call into math that converts it (math.sqrt(v)): "
                                "a derivative follows pogofmu.fmath only. Rewrite: fmath.<name>(v) for math.<name>(v) "
                                f"({', '.join(fmath.FUNCTIONS)}), and v (or v * 1.0 for an int) for float(v)")

    def __format__(self, spec):
        return format(self.v, spec)

    def __repr__(self):
        return repr(self.v)

    __str__ = __repr__


def _tangent_div(da, q, db, b):
    """The tangent of a / b = q: (da - q db) / b."""
    num = _sub(da, _mul(q, db))
    return 0.0 if _zero(num) else num / b


def _pow(a, b):
    av, ad = _parts(a)
    bv, bd = _parts(b)
    value = av ** bv
    d = 0.0
    if not _zero(ad):  # b a^(b-1) da
        d = _mul(bv * av ** (bv - 1), ad)
    if not _zero(bd):  # a^b log(a) db
        d = _add(d, _mul(value * fmath.log(av), bd))
    return Dual(value, d)


def _unary(name, derivative):
    of_value = getattr(fmath, name)

    def fn(x):
        if not isinstance(x, Dual):
            return of_value(x)
        value = of_value(x.v)
        return Dual(value, 0.0 if _zero(x.d) else _mul(derivative(x.v, value), x.d))
    return fn


def _atan2(y, x):
    (yv, yd), (xv, xd) = _parts(y), _parts(x)
    value = fmath.atan2(yv, xv)
    if _zero(yd) and _zero(xd):
        return value
    r2 = xv * xv + yv * yv
    return Dual(value, _tangent_div(_sub(_mul(xv, yd), _mul(yv, xd)), 0.0, 0.0, r2))


def _hypot(a, b):
    (av, ad), (bv, bd) = _parts(a), _parts(b)
    value = fmath.hypot(av, bv)
    if _zero(ad) and _zero(bd):
        return value
    return Dual(value, _tangent_div(_add(_mul(av, ad), _mul(bv, bd)), 0.0, 0.0, value))


LN10 = 2.302585092994046  # log(10)


def _copysign(a, b):
    """|a| with the sign of b: the tangent of a times the signs of a and of the result (b's
    tangent does not move it)."""
    (av, ad), (bv, _) = _parts(a), _parts(b)
    value = fmath.copysign(av, bv)
    if _zero(ad):
        return value
    same = (av < 0) == (value < 0)  # (a value of a traced a: a decision, as abs() takes one)
    return Dual(value, ad if same else _mul(-1.0, ad))


def _interp(x, T):
    """A table at x: the value, and the tangent times the segment's slope."""
    xv, xd = _parts(x)
    value = fmath.interp(xv, T)
    if _zero(xd):
        return value
    return Dual(value, _mul(fmath.interp_slope(xv, T), xd))


def _interp2(x, y, T):
    """A 2-D table at (x, y): the value, and the tangents times the cell's partial derivatives."""
    (xv, xd), (yv, yd) = _parts(x), _parts(y)
    value = fmath.interp2(xv, yv, T)
    if _zero(xd) and _zero(yd):
        return value
    d = 0.0
    if not _zero(xd):
        d = _mul(fmath.interp2_d(xv, yv, T, 0), xd)
    if not _zero(yd):
        d = _add(d, _mul(fmath.interp2_d(xv, yv, T, 1), yd))
    return Dual(value, d)


def _matvec(M, v):
    """``M v`` for a constant ``M``: the values' product and, the map being linear, the same map on
    the tangents (none where every tangent is zero)."""
    parts = [_parts(a) for a in v]
    value = fmath.matvec(M, [a for a, _ in parts])
    if all(_zero(d) for _, d in parts):
        return value
    return [Dual(a, d) for a, d in zip(value, fmath.matvec(M, [d for _, d in parts]))]


DUAL_MATH = {
    "sqrt": _unary("sqrt", lambda v, r: 0.5 / r),
    "exp": _unary("exp", lambda v, r: r),
    "log": _unary("log", lambda v, r: 1.0 / v),
    "cos": _unary("cos", lambda v, r: -fmath.sin(v)),
    "sin": _unary("sin", lambda v, r: fmath.cos(v)),
    "atan2": _atan2,
    "hypot": _hypot,
    "tan": _unary("tan", lambda v, r: 1.0 + r * r),
    "asin": _unary("asin", lambda v, r: 1.0 / fmath.sqrt(1.0 - v * v)),
    "acos": _unary("acos", lambda v, r: -1.0 / fmath.sqrt(1.0 - v * v)),
    "atan": _unary("atan", lambda v, r: 1.0 / (1.0 + v * v)),
    "sinh": _unary("sinh", lambda v, r: fmath.cosh(v)),
    "cosh": _unary("cosh", lambda v, r: fmath.sinh(v)),
    "tanh": _unary("tanh", lambda v, r: 1.0 - r * r),
    "log10": _unary("log10", lambda v, r: 1.0 / (v * LN10)),
    "copysign": _copysign,
    "interp": _interp,
    "interp2": _interp2,
    "interp2_d": lambda x, y, T, which: fmath.interp2_d(_parts(x)[0], _parts(y)[0], T, which),
    "interp_slope": lambda x, T: fmath.interp_slope(_parts(x)[0], T),
    "isfinite": lambda x: fmath.isfinite(_parts(x)[0]),
    "is_number": lambda x: fmath.is_number(_parts(x)[0]),
    "matvec": _matvec,
}


# a dual number's own math functions, which pogofmu.runtime.fmath calls on it (ranked above a
# traced value's: a dual holds traced values)
Dual.__fmath__ = DUAL_MATH
Dual.__fmath_rank__ = 2


def value_and_tangent(v):
    """(value, tangent) of a result: a dual's parts; anything else has a zero tangent."""
    return _parts(v)


__all__ = ["Dual", "NotDifferentiable", "value_and_tangent"]
