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
"""
import math

__all__ = ["sqrt", "exp", "log", "cos", "sin", "atan2", "hypot", "trunc", "isfinite", "is_number"]

# the functions a traced value's table must provide (``trunc`` is Python's own protocol,
# ``__trunc__``, and needs no table)
HOOKED = ("sqrt", "exp", "log", "cos", "sin", "atan2", "hypot", "isfinite", "is_number")


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
