"""The mathematical functions a model may call, looked up here at every call (``fmath.sqrt(x)``).

They are the standard library's own (the Python FMUs compute with them unchanged); the code
generator of the native FMUs (:mod:`pogofmu.codegen.trace`) replaces them for the time it
traces a model, so that a call on a traced value becomes an operation of the generated C code.
A model therefore calls ``fmath.<name>``, never ``math.<name>`` nor a name imported from here.
"""
import math

__all__ = ["sqrt", "exp", "log", "cos", "sin", "atan2", "hypot", "trunc", "isfinite", "is_number"]

sqrt = math.sqrt
exp = math.exp
log = math.log
cos = math.cos
sin = math.sin
atan2 = math.atan2
hypot = math.hypot
trunc = math.trunc  # (an int: the generated C truncates toward zero the same way)


def isfinite(v) -> bool:
    """``v`` is an int or a float and finite (False for anything else: a string, None, NaN)."""
    return isinstance(v, (int, float)) and math.isfinite(v)


def is_number(v) -> bool:
    """``v`` is an int or a float and not NaN (infinities are numbers)."""
    return isinstance(v, (int, float)) and not math.isnan(v)
