"""Tracing a model's pure functions on symbolic values: every path, every operation, in order.

The native FMUs run C generated from the same :class:`~pogofmu.runtime.model.HybridModel`
the Python FMUs run. The generator calls each model function (flow, guards, jumps, outputs,
parameter rules, domain conditions, scales) with :class:`Sym` values in place of numbers: each
arithmetic operation on them is recorded as a node, *in the order Python evaluates it* (so the C
code does the same floating-point operations in the same order and gives the same bits), and
each place where Python needs a truth value of a traced condition (``if``, ``and``, ``max``,
``x if c else y``) is a *decision*. :func:`explore` runs the function once per feasible
combination of decisions and returns the paths; :mod:`.cprint` prints them as one C function
with the decisions as ``if``/``else``.

What a traced function may do: arithmetic (``+ - * / ** abs``, unary minus), comparisons, the
math functions of :mod:`pogofmu.runtime.fmath` (which call a traced value's own, ``Sym.__fmath__``), ``math.trunc``,
a constant linear map ``fmath.matvec(M, v)`` (one node, whatever the size of ``M``),
``min``/``max``, lists/tuples/dicts of values, f-strings formatting values (``{v!r}``,
``{v:.6g}``: recorded as placeholders that C formats the same way), raising a model error. What
it may not: ``float(v)``, ``int(v)``, hashing a value (a dict or set keyed by one), ``math.*``
other than the above — each raises :class:`TraceError` naming the operation.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Dict, List, Optional, Tuple

from pogofmu.runtime import fmath
from pogofmu.runtime.model import ModelError

FLOAT, INT, BOOL = "f", "i", "b"
MAX_PATHS = 20000
MAX_DECISIONS = 2000  # on one path: more is a loop whose trip count depends on a traced value
_CODEGEN = __import__("os").path.dirname(__import__("os").path.abspath(__file__))


class TraceError(Exception):
    """A model function does something the generator cannot turn into C (names what and where)."""


def const(v):
    """A constant operand: ``("k", v)`` (a bare int is a node index)."""
    return ("k", v)


def is_const(a) -> bool:
    return isinstance(a, tuple) and len(a) == 2 and a[0] == "k"


def _cons_key(a):
    """Hash-consing key of an operand: constants by type and repr (0.0 and -0.0, 1 and 1.0 differ)."""
    if is_const(a):
        return ("k", type(a[1]).__name__, repr(a[1]))
    return a


class Node:
    """One operation: ``op`` with ``args`` (node indices, constants ``("k", v)``, or for an input
    its group and index)."""

    __slots__ = ("op", "args", "kind", "index")

    def __init__(self, op, args, kind, index):
        self.op, self.args, self.kind, self.index = op, args, kind, index

    def __repr__(self):
        return f"n{self.index}={self.op}{self.args}"


class Recorder:
    """The record of one run: its nodes (hash-consed: the same operation on the same operands is
    one node) and its decisions, forced to ``prefix`` and then True."""

    def __init__(self, prefix: Tuple[bool, ...]):
        self.prefix = prefix
        self.nodes: List[Node] = []
        self._cons: Dict[tuple, int] = {}
        self.decisions: List[Tuple[int, bool, int]] = []  # (condition node, value, nodes made before it)
        self._known: Dict[int, bool] = {}  # condition node -> its value on this path
        self._equal: Dict[int, float] = {}  # node -> the constant it is known to equal on this path
        self._unequal: Dict[int, set] = {}  # node -> constants it is known to differ from

    def node(self, op, args, kind) -> int:
        key = (op, tuple(_cons_key(a) for a in args))
        i = self._cons.get(key)
        if i is None:
            i = len(self.nodes)
            self.nodes.append(Node(op, args, kind, i))
            self._cons[key] = i
        return i

    def decide(self, cond: int) -> bool:
        if cond in self._known:
            return self._known[cond]
        implied = self._implied(cond)
        if implied is not None:
            return implied
        k = len(self.decisions)
        if k >= MAX_DECISIONS:
            raise TraceError(f"more than {MAX_DECISIONS} decisions on one path: a loop whose trip count depends on a "
                             f"state, an input or a parameter (while x > ...: or a break on such a value); the C "
                             f"code has one branch per decision. Rewrite: a loop of a fixed count (for i in "
                             f"range(N), N a constant) with the condition inside it, or a closed form")
        value = self.prefix[k] if k < len(self.prefix) else True
        self.decisions.append((cond, value, len(self.nodes)))
        self._known[cond] = value
        self._learn(cond, value)
        return value

    # a little reasoning on equalities with constants (discrete modes: s == 0 known rules out s == 1)
    def _comparison(self, cond):
        n = self.nodes[cond]
        if n.op in ("eq", "ne") and is_const(n.args[1]) and isinstance(n.args[0], int):
            return n.op, n.args[0], n.args[1][1]
        return None

    def _implied(self, cond):
        c = self._comparison(cond)
        if c is None:
            return None
        op, var, const = c
        if var in self._equal:
            same = self._equal[var] == const
            return same if op == "eq" else not same
        if const in self._unequal.get(var, ()):
            return op == "ne"
        return None

    def _learn(self, cond, value):
        c = self._comparison(cond)
        if c is None:
            return
        op, var, const = c
        if (op == "eq") == value:
            self._equal[var] = const
        else:
            self._unequal.setdefault(var, set()).add(const)


_current: List[Optional[Recorder]] = [None]


def _rec() -> Recorder:
    r = _current[0]
    if r is None:
        raise TraceError("a traced value was used outside of a trace")
    return r


def _arg(v):
    """An operand: a node index for a traced value, the number itself for a constant."""
    if isinstance(v, Sym):
        return v.i
    if isinstance(v, bool):
        return const(int(v))
    if isinstance(v, (int, float)):
        return const(v)
    raise TraceError(f"an operation mixes a traced value with {type(v).__name__} {v!r}: a model's values are ints "
                     f"and floats")


def _kind(v):
    if isinstance(v, Sym):
        return v.kind
    return INT if isinstance(v, (int, bool)) and not isinstance(v, float) else FLOAT


def _binary(op, a, b, kind):
    return Sym(_rec().node(op, (_arg(a), _arg(b)), kind), kind)


def _arith_kind(a, b, op):
    if op == "truediv" or op == "pow":
        return FLOAT
    return INT if _kind(a) == INT and _kind(b) == INT else FLOAT


class Sym:
    """A traced number (``kind``: ``f`` float, ``i`` integer, ``b`` truth value)."""

    __slots__ = ("i", "kind")
    __hash__ = None  # a dict or set keyed by a traced value cannot be turned into C

    def __init__(self, i: int, kind: str = FLOAT):
        self.i, self.kind = i, kind

    # ---- arithmetic ----
    def _op(self, other, op, reverse=False):
        if not isinstance(other, (Sym, int, float)):
            return NotImplemented
        a, b = (other, self) if reverse else (self, other)
        return _binary(op, a, b, _arith_kind(a, b, op))

    def __add__(self, o): return self._op(o, "add")
    def __radd__(self, o): return self._op(o, "add", True)
    def __sub__(self, o): return self._op(o, "sub")
    def __rsub__(self, o): return self._op(o, "sub", True)
    def __mul__(self, o): return self._op(o, "mul")
    def __rmul__(self, o): return self._op(o, "mul", True)
    def __truediv__(self, o): return self._op(o, "truediv")
    def __rtruediv__(self, o): return self._op(o, "truediv", True)
    def __pow__(self, o): return self._op(o, "pow")
    def __rpow__(self, o): return self._op(o, "pow", True)

    def __neg__(self):
        kind = INT if self.kind in (INT, BOOL) else FLOAT
        return Sym(_rec().node("neg", (self.i,), kind), kind)

    def __pos__(self):
        return self

    def __abs__(self):
        kind = INT if self.kind in (INT, BOOL) else FLOAT
        return Sym(_rec().node("abs", (self.i,), kind), kind)

    def __trunc__(self):
        return Sym(_rec().node("trunc", (self.i,), INT), INT)

    # ---- comparisons ----
    def _cmp(self, other, op):
        if not isinstance(other, (Sym, int, float)):
            return NotImplemented
        return Sym(_rec().node(op, (self.i, _arg(other)), BOOL), BOOL)

    def __lt__(self, o): return self._cmp(o, "lt")
    def __le__(self, o): return self._cmp(o, "le")
    def __gt__(self, o): return self._cmp(o, "gt")
    def __ge__(self, o): return self._cmp(o, "ge")
    def __eq__(self, o): return self._cmp(o, "eq")
    def __ne__(self, o): return self._cmp(o, "ne")

    # ---- truth: a decision ----
    def __bool__(self):
        r = _rec()
        if self.kind == BOOL:
            return r.decide(self.i)
        return r.decide(r.node("ne", (self.i, const(0)), BOOL))  # a number's truth: != 0

    # ---- what cannot be traced ----
    def __float__(self):
        called = _call_in_caller()
        fm = called.split(".", 1)[1] if called and called.startswith("math.") else None
        if fm in fmath.FUNCTIONS:
            raise TraceError(f"{called}(...) of a traced value: the generator follows pogofmu.fmath only. "
                             f"Rewrite: fmath.{fm}(...) (from pogofmu import fmath)")
        what = f"{called}(...)" if called else "float() of a traced value, or a call into math or numpy that converts it"
        raise TraceError(f"{what}: the generator follows pogofmu.fmath only. Rewrite: fmath.<name>(v) for "
                         "math.<name>(v) (" + ", ".join(sorted(fmath.FUNCTIONS)) + "), and v (or v * 1.0 for an int) "
                         "for float(v)" + ("; fmath has no such function: write it with these, or keep it out of "
                                           "the native FMU (--backend python)" if called else ""))

    def __int__(self):
        raise TraceError("int() of a traced value. Rewrite: math.trunc(v)")

    def __index__(self):
        raise TraceError("a traced value used as an index or a count (x[i], range(n) with i or n a state, an input "
                         "or a parameter): the C code's loops and indices are fixed. Rewrite: index with constants, "
                         "loop over range(N) with N a constant")

    # ---- formatting: placeholders in messages ----
    def __format__(self, spec):
        return placeholder(self, spec or "r")

    def __repr__(self):
        return placeholder(self, "r")

    __str__ = __repr__


def logical_not(v):
    if isinstance(v, Sym):
        return Sym(_rec().node("not", (_arg(v),), BOOL), BOOL)
    return not v


def _call_in_caller():
    """The ``module.function`` (``math.copysign``, ``np.tanh``) called on the line of the model's code
    that converted a traced value to a float, or None: the first frame outside this module."""
    import linecache
    import re
    import sys

    frame = sys._getframe(2)
    while frame is not None and frame.f_code.co_filename == __file__:
        frame = frame.f_back
    if frame is None:
        return None
    line = linecache.getline(frame.f_code.co_filename, frame.f_lineno)
    m = re.search(r"\b(math|np|numpy|cmath)\.(\w+)\s*\(", line)
    return f"{'math' if m.group(1) in ('math', 'cmath') else m.group(1)}.{m.group(2)}" if m else None


# ---- placeholders: a formatted value inside a message -------------------------------------------
_MARK = "\x00"


def placeholder(v: Sym, spec: str) -> str:
    return f"{_MARK}{v.i}:{v.kind}:{spec}{_MARK}"


def split_message(text: str):
    """A message with placeholders as ``[str | (node, kind, spec)]``."""
    parts = text.split(_MARK)
    out = []
    for k, part in enumerate(parts):
        if k % 2 == 0:
            if part:
                out.append(part)
        else:
            i, kind, spec = part.split(":", 2)
            out.append((int(i), kind, spec))
    return out


# ---- the math functions, traced -------------------------------------------------------------------
def _unary_fn(name, real):
    def fn(x):
        if isinstance(x, Sym):
            return Sym(_rec().node(name, (x.i,), FLOAT), FLOAT)
        return real(x)
    return fn


def _binary_fn(name, real):
    def fn(a, b):
        if isinstance(a, Sym) or isinstance(b, Sym):
            return Sym(_rec().node(name, (_arg(a), _arg(b)), FLOAT), FLOAT)
        return real(a, b)
    return fn


def _table_op(name, T, args, on_numbers):
    """A table (fmath.Table, Table2) at ``args``: one node of the table and the arguments when one is
    traced, else its value on numbers."""
    if any(isinstance(a, Sym) for a in args):
        return Sym(_rec().node(name, (T, *(_arg(a) for a in args)), FLOAT), FLOAT)
    return on_numbers(*args)


def _isfinite(x):
    if isinstance(x, Sym):
        return Sym(_rec().node("isfinite", (x.i,), BOOL), BOOL)
    return isinstance(x, (int, float)) and math.isfinite(x)


def _is_number(x):
    if isinstance(x, Sym):
        return Sym(_rec().node("isnumber", (x.i,), BOOL), BOOL)
    return isinstance(x, (int, float)) and not math.isnan(x)


def _matvec(M, v):
    """``fmath.matvec(M, v)`` with traced entries in ``v`` (``M`` a checked constant
    :class:`~pogofmu.runtime.fmath.Matrix`): one ``matvec`` node of the matrix and the entries of
    ``v``, and one ``elem`` node per row — O(rows + columns) nodes, however many entries."""
    if M.n_rows == 0 or M.n_cols == 0:
        return M.product(v)
    rec = _rec()
    node = rec.node("matvec", (M, *(_arg(a) for a in v)), FLOAT)
    return [Sym(rec.node("elem", (node, const(k)), FLOAT), FLOAT) for k in range(M.n_rows)]


TRACED_MATH = {
    "sqrt": _unary_fn("sqrt", math.sqrt),
    "exp": _unary_fn("exp", math.exp),
    "log": _unary_fn("log", math.log),
    "cos": _unary_fn("cos", math.cos),
    "sin": _unary_fn("sin", math.sin),
    "atan2": _binary_fn("atan2", math.atan2),
    "hypot": _binary_fn("hypot", math.hypot),
    "tan": _unary_fn("tan", math.tan),
    "asin": _unary_fn("asin", math.asin),
    "acos": _unary_fn("acos", math.acos),
    "atan": _unary_fn("atan", math.atan),
    "sinh": _unary_fn("sinh", math.sinh),
    "cosh": _unary_fn("cosh", math.cosh),
    "tanh": _unary_fn("tanh", math.tanh),
    "log10": _unary_fn("log10", math.log10),
    "copysign": _binary_fn("copysign", math.copysign),
    "interp": lambda x, T: _table_op("interp", T, (x,), T.at),
    "interp_slope": lambda x, T: _table_op("interp_slope", T, (x,), T.slope_at),
    "interp2": lambda x, y, T: _table_op("interp2", T, (x, y), T.at),
    "interp2_d": lambda x, y, T, which: _table_op(f"interp2_d{which}", T, (x, y), lambda a, b: T.d_at(a, b, which)),
    "trunc": math.trunc,  # on a traced value: Sym.__trunc__, an operation of the generated C
    "isfinite": _isfinite,
    "is_number": _is_number,
    "matvec": _matvec,
}


# a traced value's own math functions, which pogofmu.runtime.fmath calls on it
Sym.__fmath__ = TRACED_MATH
Sym.__fmath_rank__ = 1
_UNTRACED = set(fmath.HOOKED) - set(TRACED_MATH)
if _UNTRACED:  # a function added to fmath must be added here too, or a model's call on it fails to trace
    raise TraceError(f"pogofmu.runtime.fmath has functions the tracer does not know: {sorted(_UNTRACED)}")


# ---- inputs of a traced function -------------------------------------------------------------------
def symbol(group: str, index: int, kind: str = FLOAT) -> Sym:
    """The traced input ``group[index]`` (``group``: t, x, q, u, p, s ...)."""
    return Sym(_rec().node("in", (group, index), kind), kind)


# ---- exploring every path ----------------------------------------------------------------------
class Path:
    """One path through a traced function: its decisions, its nodes and how it ended —
    ``("return", value)`` or ``("raise", exception class name, message)``."""

    __slots__ = ("decisions", "nodes", "result")

    def __init__(self, decisions, nodes, result):
        self.decisions, self.nodes, self.result = decisions, nodes, result


def explore(fn: Callable[[], Any], what: str) -> List[Path]:
    """Run ``fn`` (which builds its inputs with :func:`symbol`) once per feasible combination of
    its decisions. A model error raised on a path is that path's result; any other exception is
    a :class:`TraceError` naming ``what``."""
    paths: List[Path] = []
    pending: List[Tuple[bool, ...]] = [()]
    while pending:
        prefix = pending.pop()
        rec = Recorder(prefix)
        _current[0] = rec
        try:
            try:
                result = ("return", fn())
            except ModelError as exc:
                result = ("raise", type(exc).__name__, str(exc))
            except (TraceError, fmath.NotConstantError) as exc:
                raise TraceError(f"{_where(exc)}{what}: {exc}") from None
            except Exception as exc:  # noqa: BLE001 - a path that cannot be traced
                raise TraceError(f"{_where(exc)}{what}: {type(exc).__name__}: {exc}{_hint(exc)} (on the path "
                                 f"{[v for _, v, _ in rec.decisions]})") from None
        finally:
            _current[0] = None
        for k in range(len(prefix), len(rec.decisions)):
            pending.append(tuple(v for _, v, _ in rec.decisions[:k]) + (False,))
        paths.append(Path(rec.decisions, rec.nodes, result))
        if len(paths) > MAX_PATHS:
            raise TraceError(f"{what}: more than {MAX_PATHS} paths")
    return paths


def _where(exc) -> str:
    """``file:line: `` of the model's code where a trace failed (the innermost frame outside the
    generator and the interpreter's own files), or nothing."""
    import os
    import traceback

    found = None
    for frame in traceback.extract_tb(exc.__traceback__):
        if not frame.filename.startswith("<") and os.path.dirname(os.path.abspath(frame.filename)) != _CODEGEN \
                and "site-packages" not in frame.filename and "/lib/python" not in frame.filename \
                and os.path.abspath(frame.filename) != os.path.abspath(fmath.__file__):
            found = frame
    return f"{found.filename}:{found.lineno}: " if found else ""


def _hint(exc) -> str:
    """What to write instead, for the usual constructs the generator cannot follow."""
    text = str(exc)
    if "ufunc" in text or "numpy" in text:
        return ": a numpy call on a traced value. Rewrite: fmath.<name>(v), arithmetic, min/max"
    if "unsupported operand" in text or "__round__" in text or "doesn't define" in text:
        return (": an operation the generator does not follow (it follows + - * / ** abs, comparisons, min/max "
                "and fmath). Rewrite: x % y as x - y * math.trunc(x / y), round(v) as math.trunc(v + 0.5) for v >= 0")
    if isinstance(exc, TypeError):
        return ": a builtin or a value the generator cannot follow (a model's values are ints and floats)"
    return ""


def is_sym(v) -> bool:
    return isinstance(v, Sym)


__all__ = ["Sym", "symbol", "explore", "Path", "TraceError", "split_message", "logical_not", "is_sym",
           "FLOAT", "INT", "BOOL"]
