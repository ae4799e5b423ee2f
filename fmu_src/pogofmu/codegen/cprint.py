"""Printing traced paths (:mod:`.trace`) as the body of one C function.

The paths of a function share their first decisions; the body is their decision tree: the
operations every path below a decision needs are printed once before its ``if``, in the order
Python made them, each as ``const double v<k> = ...;`` (C evaluates them in that order with the
same IEEE operations: the same bits). An operation that raises in Python (a division by zero,
``sqrt`` of a negative number, an overflow in ``**`` or ``exp``) is checked where it happens and
ends the function with the error Python would raise (``pg_*`` helpers of ``pg_support.h``),
even when its value is not used afterwards — as in Python. Leaves (what a path returns or
raises) are printed by a callback of the caller, which knows what the function returns.

A constant linear map (``fmath.matvec``: a ``matvec`` node and an ``elem`` node per row) is printed
as its operands in an array and a loop over a ``static const double`` table that the caller names
and prints once per file (``matrix_name``), the products added left to right from 0.0 as Python
adds them.
"""
from __future__ import annotations

import math
from typing import Callable, Dict, List, Optional, Sequence, Set

from .trace import BOOL, INT, Node, Path, Sym, split_message  # noqa: F401

FALLIBLE = {"truediv", "pow", "sqrt", "exp", "log", "cos", "sin", "trunc", "tan", "asin", "acos", "sinh", "cosh",
            "log10"}
INFIX = {"add": "+", "sub": "-", "mul": "*", "lt": "<", "le": "<=", "gt": ">", "ge": ">=", "eq": "==", "ne": "!="}


def literal(v) -> str:
    """A Python number as a C double literal that parses to the same double."""
    if isinstance(v, bool):
        return "1.0" if v else "0.0"
    if isinstance(v, int):
        return f"{v}.0"
    if math.isnan(v):
        return "NAN"
    if math.isinf(v):
        return "INFINITY" if v > 0 else "(-INFINITY)"
    text = repr(float(v))
    if "." not in text and "e" not in text:
        text += ".0"
    return f"({text})" if text.startswith("-") else text


def c_string(text: str) -> str:
    out = []
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ch == "\n":
            out.append("\\n")
        elif ord(ch) < 32 or ord(ch) == 127:
            out.append(f"\\{ord(ch):03o}")
        elif ord(ch) > 127:
            out.extend(f"\\{b:03o}" for b in ch.encode("utf-8"))
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _bisect_c(tb: str, axis: int, v: str, lo: str, hi: str) -> str:
    """The C of fmath._bisect: the segment [lo, hi] of the breakpoints tb[axis] holding v."""
    return (f"while ({hi} - {lo} > 1) {{ const int mid = ({lo} + {hi}) / 2; "
            f"if ({tb}[{axis}][mid] <= {v}) {lo} = mid; else {hi} = mid; }}")


class Printer:
    """Prints one traced function. ``inputs`` maps an input group (``t``, ``x``, ``q`` ...) to the
    C expression of its element ``{i}``; ``leaf(path, ref) -> lines`` prints what a path does at
    its end, ``ref(value)`` giving the C expression of a traced value or a number."""

    def __init__(self, paths: Sequence[Path], inputs: Dict[str, str], leaf: Callable, roots: Callable,
                 matrix_name: Optional[Callable] = None):
        self.paths = list(paths)
        self.inputs = inputs
        self.leaf = leaf
        self.roots = roots  # (path) -> the node indices its result uses
        self.matrix_name = matrix_name  # (fmath.Matrix) -> the C name of its table
        self._live = [self._live_set(p) for p in self.paths]

    # ---- liveness: what a path needs (its result, its decisions, every operation that may raise)
    def _live_set(self, path: Path) -> Set[int]:
        nodes = path.nodes
        todo = [c for c, _, _ in path.decisions] + list(self.roots(path))
        todo += [n.index for n in nodes if n.op in FALLIBLE]
        live: Set[int] = set()
        while todo:
            i = todo.pop()
            if i in live:
                continue
            live.add(i)
            if nodes[i].op == "in":
                continue
            for a in nodes[i].args:
                if isinstance(a, int):
                    todo.append(a)
        return live

    def ref_of(self, path: Path):
        def ref(v):
            if isinstance(v, Sym):
                return f"v{v.i}"
            if isinstance(v, (bool, int, float)):
                return literal(v)
            raise TypeError(f"not a number: {v!r}")
        return ref

    def body(self) -> List[str]:
        return self._tree(list(range(len(self.paths))), 0, 0, "    ")

    def _tree(self, group: List[int], depth: int, start: int, ind: str) -> List[str]:
        first = self.paths[group[0]]
        live = set().union(*(self._live[k] for k in group))
        if depth < len(first.decisions):
            cond, _, n_before = first.decisions[depth]
            lines = self._nodes(first.nodes, start, n_before, live, ind)
            yes = [k for k in group if self.paths[k].decisions[depth][1]]
            no = [k for k in group if not self.paths[k].decisions[depth][1]]
            assert yes and no, "a decision explored one way only"
            lines.append(f"{ind}if (v{cond}) {{")
            lines += self._tree(yes, depth + 1, n_before, ind + "    ")
            lines.append(f"{ind}}} else {{")
            lines += self._tree(no, depth + 1, n_before, ind + "    ")
            lines.append(f"{ind}}}")
            return lines
        assert len(group) == 1, "paths that agree on every decision"
        lines = self._nodes(first.nodes, start, len(first.nodes), live, ind)
        return lines + [ind + line for line in self.leaf(first, self.ref_of(first))]

    def _nodes(self, nodes: List[Node], start: int, stop: int, live: Set[int], ind: str) -> List[str]:
        out = []
        for n in nodes[start:stop]:
            if n.index in live:
                out += [ind + line for line in self._node(n, nodes)]
                if n.op in FALLIBLE:  # kept for its error even where its value is not used
                    out.append(f"{ind}(void)v{n.index};")
        return out

    def _node(self, n: Node, nodes: List[Node]) -> List[str]:
        def a(k):
            v = n.args[k]
            return f"v{v}" if isinstance(v, int) else literal(v[1])

        def num(k):  # an operand as a number (a truth value is 0 or 1 in arithmetic)
            return a(k)
        name = f"v{n.index}"
        ctype = "int" if n.kind == BOOL else "double"
        op = n.op
        if op == "in":
            group, i = n.args
            return [f"const {ctype} {name} = {self.inputs[group].format(i=i)};"]
        if op in INFIX:
            return [f"const {ctype} {name} = {num(0)} {INFIX[op]} {num(1)};"]
        if op == "truediv":
            return [f"if ({num(1)} == 0.0) return pg_arith(m, PG_ZERO_DIVISION);",
                    f"const double {name} = {num(0)} / {num(1)};"]
        if op in ("pow", "atan2", "hypot", "copysign"):
            fn = {"pow": "pg_pow", "atan2": "pg_atan2", "hypot": "pg_hypot", "copysign": "pg_copysign"}[op]
            return [f"double {name};", f"if ({fn}({num(0)}, {num(1)}, &{name}, m)) return PG_ARITH;"]
        if op in ("sqrt", "exp", "log", "cos", "sin", "trunc", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh",
                  "log10"):
            return [f"double {name};", f"if (pg_{op}({num(0)}, &{name}, m)) return PG_ARITH;"]
        if op == "neg":
            return [f"const double {name} = -{num(0)};"]
        if op == "abs":
            return [f"const double {name} = fabs({num(0)});"]
        if op == "not":
            return [f"const int {name} = !{a(0)};"]
        if op == "isfinite":
            return [f"const int {name} = isfinite({num(0)}) ? 1 : 0;"]
        if op == "isnumber":
            return [f"const int {name} = isnan({num(0)}) ? 0 : 1;"]
        if op in ("interp2", "interp2_d0", "interp2_d1"):
            T = n.args[0]
            tb, nx, ny = self.matrix_name(T), T.nx, T.ny

            def cell(axis, nb, v, lo, hi, w):
                return [f"    int {lo} = 0, {hi} = 1; double {w} = 0.0;",
                        f"    if ({v} <= {tb}[{axis}][0]) {{ {lo} = 0; {hi} = 1; {w} = 0.0; }}",
                        f"    else if ({v} >= {tb}[{axis}][{nb - 1}]) {{ {lo} = {nb - 2}; {hi} = {nb - 1}; {w} = 1.0; }}",
                        "    else {",
                        f"        {lo} = 0; {hi} = {nb - 1};",
                        f"        {_bisect_c(tb, axis, v, lo, hi)}",
                        f"        {w} = ({v} - {tb}[{axis}][{lo}]) / ({tb}[{axis}][{hi}] - {tb}[{axis}][{lo}]);",
                        "    }"]
            out = [f"double {name};", "{", f"    const double xq = {num(1)}, yq = {num(2)};",
                   *cell(0, nx, "xq", "i0", "i1", "wx"), *cell(1, ny, "yq", "j0", "j1", "wy"),
                   f"    const double *r0 = {tb}[2 + i0], *r1 = {tb}[2 + i1];"]
            # the table along y on the cell's two x edges (fmath.Table2._corners)
            edges = ["    const double a = r0[j0] + (r0[j1] - r0[j0]) * wy;",
                     "    const double b = r1[j0] + (r1[j1] - r1[j0]) * wy;"]
            if op == "interp2":
                out += [*edges, f"    {name} = a + (b - a) * wx;"]
            elif op == "interp2_d0":
                out += [*edges,
                        f"    if (xq <= {tb}[0][0] || xq >= {tb}[0][{nx - 1}]) {name} = 0.0;",
                        f"    else {name} = (b - a) / ({tb}[0][i1] - {tb}[0][i0]);"]
            else:
                out += [f"    if (yq <= {tb}[1][0] || yq >= {tb}[1][{ny - 1}]) {name} = 0.0;",
                        "    else {",
                        "        const double da = r0[j1] - r0[j0];",
                        "        const double db = r1[j1] - r1[j0];",
                        f"        {name} = (da + (db - da) * wx) / ({tb}[1][j1] - {tb}[1][j0]);",
                        "    }"]
            return out + ["}"]
        if op in ("interp", "interp_slope"):
            T = n.args[0]
            if self.matrix_name is None:
                raise ValueError("a table (fmath.interp) with no C table to print it from")
            tb, last = self.matrix_name(T), T.n_cols - 1
            inside = (f"{name} = {tb}[1][lo] + ({tb}[1][hi] - {tb}[1][lo]) / ({tb}[0][hi] - {tb}[0][lo]) * "
                      f"(xq - {tb}[0][lo]);" if op == "interp" else
                      f"{name} = ({tb}[1][hi] - {tb}[1][lo]) / ({tb}[0][hi] - {tb}[0][lo]);")
            end = (f"{tb}[1][0]", f"{tb}[1][{last}]") if op == "interp" else ("0.0", "0.0")
            return [f"double {name};", "{",
                    f"    const double xq = {num(1)};",
                    f"    if (xq <= {tb}[0][0]) {name} = {end[0]};",
                    f"    else if (xq >= {tb}[0][{last}]) {name} = {end[1]};",
                    "    else {",
                    f"        int lo = 0, hi = {last};",
                    f"        {_bisect_c(tb, 0, 'xq', 'lo', 'hi')}",
                    f"        {inside}",
                    "    }", "}"]
        if op == "matvec":
            M = n.args[0]
            if self.matrix_name is None:
                raise ValueError("a constant linear map (fmath.matvec) with no table to print it from")
            table = self.matrix_name(M)
            return [f"const double {name}_v[{M.n_cols}] = {{{', '.join(num(k) for k in range(1, len(n.args)))}}};",
                    f"double {name}[{M.n_rows}];",
                    f"for (int r = 0; r < {M.n_rows}; r++) {{",
                    "    double acc = 0.0;",
                    f"    for (int c = 0; c < {M.n_cols}; c++) acc += {table}[r][c] * {name}_v[c];",
                    f"    {name}[r] = acc;",
                    "}"]
        if op == "elem":
            return [f"const double {name} = v{n.args[0]}[{n.args[1][1]}];"]
        raise ValueError(f"no C for the operation {op}")


def matrix_table(name: str, M) -> List[str]:
    """The C definition of a constant matrix (``fmath.Matrix``): one line per row, each entry a
    literal that parses to the same double."""
    rows = [f"    {{{', '.join(literal(a) for a in row)}}}," for row in M.rows]
    return [f"static const double {name}[{M.n_rows}][{M.n_cols}] = {{", *rows, "};"]


def message_lines(text: str, ref, kind_of=None) -> List[str]:
    """C statements appending ``text`` (with its placeholders) to the message ``m``."""
    out = []
    for part in split_message(text):
        if isinstance(part, str):
            out.append(f"pg_msg_str(m, {c_string(part)});")
        else:
            i, kind, spec = part
            out.append(f"pg_msg_value(m, v{i}, '{kind}', {c_string(spec)});")
    return out


def result_nodes(value) -> List[int]:
    """Every traced node a returned structure refers to (and the placeholders in its strings)."""
    out: List[int] = []

    def walk(v):
        if isinstance(v, Sym):
            out.append(v.i)
        elif isinstance(v, str):
            out.extend(p[0] for p in split_message(v) if not isinstance(p, str))
        elif isinstance(v, dict):
            for w in v.values():
                walk(w)
        elif isinstance(v, (list, tuple)):
            for w in v:
                walk(w)
    walk(value)
    return out


__all__ = ["Printer", "literal", "c_string", "matrix_table", "message_lines", "result_nodes", "INT", "BOOL"]
