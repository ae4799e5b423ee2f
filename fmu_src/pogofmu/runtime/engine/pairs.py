"""Embedded explicit Runge-Kutta pairs with dense output: Dormand-Prince 5(4) and DOP853.

The step, the error norm and the continuous extension of each pair are generated as Python source
from the tableaux (:mod:`.tableaux`) and compiled once, with the state loop unrolled for a given
number of states (:meth:`_Pair.specialized`).  Nothing here knows about models or events.
"""
from __future__ import annotations

import copy
import math

from . import tableaux as tab

# =============================================================================================
# Runge-Kutta pairs
# =============================================================================================
#
# States are plain lists of floats: for the handful of states of these models, Python float
# arithmetic is several times cheaper than numpy's per-call overhead on tiny arrays.  The stage
# sums are generated once per pair from the tableau (zero coefficients skipped) and compiled.

def _lincomb(coefs, names, scale="h"):
    """Source of ``[base + h*(c0*k0_ + ...) ...]`` pieces: (expression, zipped names, vectors)."""
    terms = [(c, k) for c, k in zip(coefs, names) if c != 0.0]
    expr = " + ".join(f"{c!r}*{k}_" for c, k in terms)
    return expr, [k for _, k in terms]


def _gen_stages(A, C, first, last, y="y", t="t"):
    """Source lines computing stages ``k{first}..k{last-1}`` from ``k0..``."""
    lines = []
    for s in range(first, last):
        expr, ks = _lincomb(A[s][:s], [f"k{j}" for j in range(s)])
        it = ", ".join(f"{k}_" for k in ks)
        zs = ", ".join(ks)
        lines.append(f"    k{s} = fun({t} + {C[s]!r}*h, [y_ + h*({expr}) for y_, {it} in zip({y}, {zs})])")
    return lines


def _compile(src, name):
    ns = {"sqrt": math.sqrt}
    exec(compile(src, f"<pogofmu.runtime.engine:{name}>", "exec"), ns)
    return ns[name]


def _gen_step(A, B, C, n_stages):
    lines = ["def step(fun, t, y, f, h):", "    k0 = f"]
    lines += _gen_stages(A, C, 1, n_stages)
    expr, ks = _lincomb(B, [f"k{j}" for j in range(n_stages)])
    lines.append(f"    y_new = [y_ + h*({expr}) for y_, {', '.join(k + '_' for k in ks)} in zip(y, {', '.join(ks)})]")
    lines.append("    f_new = fun(t + h, y_new)")
    lines.append(f"    return y_new, f_new, ({', '.join(f'k{j}' for j in range(n_stages))}, f_new)")
    return _compile("\n".join(lines) + "\n", "step")


def _gen_step_unrolled(A, B, C, n_stages, n):
    """The step of :func:`_gen_step` for exactly ``n`` states, the state loop unrolled: the same
    operations in the same order (the same bits), without a comprehension and a zip per stage
    (about 40 % cheaper for the 5-8 states of these models)."""
    def combination(coefs, i):
        terms = [f"{c!r}*k{j}_{i}" for j, c in enumerate(coefs) if c != 0.0]
        return f"y{i} + h*({' + '.join(terms)})"

    lines = ["def step(fun, t, y, f, h):", "    k0 = f",
             f"    {', '.join(f'y{i}' for i in range(n))}, = y",
             f"    {', '.join(f'k0_{i}' for i in range(n))}, = k0"]
    for s in range(1, n_stages):
        lines.append(f"    k{s} = fun(t + {C[s]!r}*h, [{', '.join(combination(A[s][:s], i) for i in range(n))}])")
        lines.append(f"    {', '.join(f'k{s}_{i}' for i in range(n))}, = k{s}")
    lines.append(f"    y_new = [{', '.join(combination(B, i) for i in range(n))}]")
    lines.append("    f_new = fun(t + h, y_new)")
    lines.append(f"    return y_new, f_new, ({', '.join(f'k{j}' for j in range(n_stages))}, f_new)")
    return _compile("\n".join(lines) + "\n", "step")


def _term_sum(coefs, i):
    """``c0*k0_i + c2*k2_i + ...``: state i's terms of a combination of the stages (zero
    coefficients skipped, the order of _lincomb)."""
    return " + ".join(f"{c!r}*k{j}_{i}" for j, c in enumerate(coefs) if c != 0.0)


def _unpack_lines(combinations, n):
    """Source lines unpacking ``K`` into the stage vectors ``k<j>``, and those that the
    ``combinations`` use into their ``n`` components ``k<j>_<i>``."""
    stages = max(len(c) for c in combinations)
    used = sorted({j for c in combinations for j, v in enumerate(c) if v != 0.0})
    return [f"    {', '.join(f'k{j}' for j in range(stages))}, = K",
            *(f"    {', '.join(f'k{j}_{i}' for i in range(n))}, = k{j}" for j in used)]


def _unpack_state(vector, name, n):
    return f"    {', '.join(f'{name}{i}' for i in range(n))}, = {vector}"


class _Pair:
    """An embedded explicit Runge-Kutta pair with FSAL and dense output (generated code)."""

    name = ""
    order = 0
    error_exponent = 0.0
    MAX_UNROLLED = 32  # state counts up to this get a step with the state loop unrolled

    def _set_step(self, A, B, C, n_stages):
        self.step = _gen_step(A, B, C, n_stages)
        self._tableau = (A, B, C, n_stages)
        self._specialized = {}

    def specialized(self, n: int) -> "_Pair":
        """This pair with its step generated for exactly ``n`` states (cached; the pair itself for
        no states or very many)."""
        if n <= 0 or n > self.MAX_UNROLLED:
            return self
        pair = self._specialized.get(n)
        if pair is None:
            pair = copy.copy(self)
            pair.step = _gen_step_unrolled(*self._tableau, n)
            self._specialize(pair, n)
            pair._specialized = {}
            self._specialized[n] = pair
        return pair

    def _specialize(self, pair, n):
        """Hook: more of the method's code unrolled for ``n`` states (set on ``pair``): the error
        norm, the dense output."""


class DOPRI5(_Pair):
    name = "DOPRI5"
    order = 5
    error_exponent = -1.0 / 5.0

    def __init__(self):
        A, B, C, E, P = tab.DOPRI5_A, tab.DOPRI5_B, tab.DOPRI5_C, tab.DOPRI5_E, tab.DOPRI5_P
        ns = len(B)
        self._set_step(A, B, C, ns)
        self._E, self._P = E, P
        K = [f"k{j}" for j in range(ns + 1)]
        expr, ks = _lincomb(E, K)
        self.error_norm = _compile(
            f"def error_norm(K, h, y, y_new, atol, rtol):\n"
            f"    {', '.join(K)} = K\n"
            f"    acc = 0.0\n"
            f"    for y_, yn_, {', '.join(k + '_' for k in ks)} in zip(y, y_new, {', '.join(ks)}):\n"
            f"        e = h*({expr}) / (atol + rtol*max(abs(y_), abs(yn_)))\n"
            f"        acc += e*e\n"
            f"    return sqrt(acc/len(y)) if y else 0.0\n", "error_norm")
        qs = []
        for r in range(4):
            expr, ks = _lincomb([P[j][r] for j in range(ns + 1)], K)
            qs.append(f"    q{r} = [{expr} for {', '.join(k + '_' for k in ks)}, in zip({', '.join(ks)})]")
        self._coeffs = _compile(f"def coeffs(K):\n    {', '.join(K)} = K\n" + "\n".join(qs)
                                + "\n    return q0, q1, q2, q3\n", "coeffs")

    def _specialize(self, pair, n):
        """The error norm, and the dense output built straight from the stages, unrolled for ``n``
        states: the same operations in the same order as the loops above (the same bits), without
        a zip and a list per coefficient (the dense output of a step costs about a third)."""
        E, P = self._E, self._P
        unpack = _unpack_lines([E, *zip(*P)], n)
        norm = ["def error_norm(K, h, y, y_new, atol, rtol):", *unpack, _unpack_state("y", "y", n),
                _unpack_state("y_new", "yn", n), "    acc = 0.0"]
        for i in range(n):
            norm += [f"    ay, an = abs(y{i}), abs(yn{i})",
                     f"    e = h*({_term_sum(E, i)}) / (atol + rtol*(an if an > ay else ay))",  # = max(ay, an)
                     "    acc += e*e"]
        norm.append(f"    return sqrt(acc/{n})")
        pair.error_norm = _compile("\n".join(norm) + "\n", "error_norm")
        make = ["def dense(fun, t0, Y, y1, h, K):", *unpack, _unpack_state("Y", "y", n)]  # names of _DENSE_UNROLLED[5]
        make += [f"    {'abcd'[r]}{i} = {_term_sum([row[r] for row in P], i)}" for r in range(4) for i in range(n)]
        pair.dense = _compile("\n".join(make + _dense_ev_lines(5, n)) + "\n", "dense")

    def dense(self, fun, t0, y0, y1, h, K):
        return _Dense5(t0, h, y0, self._coeffs(K))


class DOP853(_Pair):
    name = "DOP853"
    order = 8
    error_exponent = -1.0 / 8.0

    def __init__(self):
        A, B, C = tab.DOP853_A, tab.DOP853_B, tab.DOP853_C
        ns, nx = tab.DOP853_N_STAGES, tab.DOP853_N_STAGES_EXTENDED
        self._set_step(A, B, C, ns)
        K = [f"k{j}" for j in range(ns + 1)]
        e5, k5 = _lincomb(tab.DOP853_E5, K)
        e3, k3 = _lincomb(tab.DOP853_E3, K)
        assert k5 == k3
        self.error_norm = _compile(
            f"def error_norm(K, h, y, y_new, atol, rtol):\n"
            f"    {', '.join(K)} = K\n"
            f"    n5 = n3 = 0.0\n"
            f"    for y_, yn_, {', '.join(k + '_' for k in k5)} in zip(y, y_new, {', '.join(k5)}):\n"
            f"        sc = atol + rtol*max(abs(y_), abs(yn_))\n"
            f"        a = ({e5}) / sc\n"
            f"        b = ({e3}) / sc\n"
            f"        n5 += a*a\n"
            f"        n3 += b*b\n"
            f"    if n5 == 0.0:  # (also n3 tiny: 0.01*n3 may underflow to 0)\n"
            f"        return 0.0\n"
            f"    return abs(h) * n5 / sqrt((n5 + 0.01*n3) * len(y))\n", "error_norm")  # y empty: n5 = 0
        # dense output (Hairer's contd8): three more stages, then seven coefficient vectors
        lines = ["def coeffs(fun, t0, y0, y1, h, K):", f"    {', '.join(K)} = K"]
        # stage ns (index 12) of the extended tableau is f_new = K[ns]
        lines += _gen_stages(A, C, ns + 1, nx, y="y0", t="t0")
        KX = [f"k{j}" for j in range(nx)]
        for r in range(4):
            expr, ks = _lincomb(tab.DOP853_D[r], KX)
            lines.append(f"    d{r} = [h*({expr}) for {', '.join(k + '_' for k in ks)}, in zip({', '.join(ks)})]")
        lines += [
            "    f0 = [b - a for a, b in zip(y0, y1)]",
            "    f1 = [h*a - b for a, b in zip(k0, f0)]",
            f"    f2 = [2.0*b - h*(a + c) for a, b, c in zip(k0, f0, k{ns})]",
            "    return f0, f1, f2, d0, d1, d2, d3",
        ]
        self._coeffs = _compile("\n".join(lines) + "\n", "coeffs")

    def _specialize(self, pair, n):
        """The error norm unrolled for ``n`` states (as DOPRI5's: the same operations in the same
        order), and the dense evaluator as a closure (its coefficients need three more stages)."""
        E5, E3 = tab.DOP853_E5, tab.DOP853_E3
        norm = ["def error_norm(K, h, y, y_new, atol, rtol):", *_unpack_lines([E5, E3], n),
                _unpack_state("y", "y", n), _unpack_state("y_new", "yn", n), "    n5 = n3 = 0.0"]
        for i in range(n):
            norm += [f"    ay, an = abs(y{i}), abs(yn{i})",
                     "    sc = atol + rtol*(an if an > ay else ay)",  # = max(ay, an)
                     f"    a = ({_term_sum(E5, i)}) / sc", f"    b = ({_term_sum(E3, i)}) / sc",
                     "    n5 += a*a", "    n3 += b*b"]
        norm += ["    if n5 == 0.0:", "        return 0.0", f"    return abs(h) * n5 / sqrt((n5 + 0.01*n3) * {n})"]
        pair.error_norm = _compile("\n".join(norm) + "\n", "error_norm")
        make, coeffs = _gen_dense_closure(8, n), self._coeffs

        def dense(fun, t0, y0, y1, h, K):
            return make(t0, h, y0, coeffs(fun, t0, y0, y1, h, K))
        pair.dense = dense

    def dense(self, fun, t0, y0, y1, h, K):
        return _Dense8(t0, h, y0, self._coeffs(fun, t0, y0, y1, h, K))


class _Dense5:
    __slots__ = ("t0", "h", "rows")

    def __init__(self, t0, h, y0, Q):
        self.t0, self.h = t0, h
        self.rows = tuple(zip(y0, *Q))  # per state: (y0, q0, q1, q2, q3), zipped once per step

    def __call__(self, t):
        x = (t - self.t0) / self.h
        return _dense5_eval(x, self.h * x, self.rows)


def _dense5_eval(x, hx, rows):
    return [y + hx * (a + x * (b + x * (c + x * d))) for y, a, b, c, d in rows]


class _Dense8:
    __slots__ = ("t0", "h", "rows")

    def __init__(self, t0, h, y0, F):
        self.t0, self.h = t0, h
        self.rows = tuple(zip(y0, *F))  # per state: y0 and its seven coefficients

    def __call__(self, t):
        x = (t - self.t0) / self.h
        return _dense8_eval(x, 1.0 - x, self.rows)


def _dense8_eval(x, w, rows):
    return [y + x * (a + w * (b + x * (c + w * (d + x * (e + w * (f + x * g))))))
            for y, a, b, c, d, e, f, g in rows]


# the dense evaluators unrolled for n states, as closures over one step's coefficients: the same
# operations as above in the same order, t -> state in one call, no unpacking of rows per
# evaluation (the common communication step evaluates once).  Per order: the line after
# x = (t - t0)/h, the names of state i's start value and coefficients, its value.
_DENSE_UNROLLED = {
    5: ("hx = h * x", "y{i}, a{i}, b{i}, c{i}, d{i}", "y{i} + hx * (a{i} + x * (b{i} + x * (c{i} + x * d{i})))"),
    8: ("w = 1.0 - x", "y{i}, a{i}, b{i}, c{i}, d{i}, e{i}, f{i}, g{i}",
        "y{i} + x * (a{i} + w * (b{i} + x * (c{i} + w * (d{i} + x * (e{i} + w * (f{i} + x * g{i}))))))"),
}


def _dense_ev_lines(order, n):
    """Source of the inner ``ev(t)`` (and ``return ev``) of a closure factory over the names of
    ``_DENSE_UNROLLED[order]`` for ``n`` states."""
    preamble, _, value = _DENSE_UNROLLED[order]
    return ["    def ev(t):", "        x = (t - t0) / h", f"        {preamble}",
            f"        return [{', '.join(value.format(i=i) for i in range(n))}]", "    return ev"]


def _gen_dense_closure(order, n):
    """``make(t0, h, y0, Q) -> ev``: Q the coefficient vectors, as the _Dense classes take them."""
    row = _DENSE_UNROLLED[order][1]
    names = [row.format(i=i).split(", ") for i in range(n)]  # per state: y, then its coefficients
    lines = ["def make(t0, h, y0, Q):", f"    {', '.join(r[0] for r in names)}, = y0"]
    for j in range(len(names[0]) - 1):
        lines.append(f"    {', '.join(r[j + 1] for r in names)}, = Q[{j}]")
    return _compile("\n".join(lines + _dense_ev_lines(order, n)) + "\n", "make")


METHODS = {5: DOPRI5(), 8: DOP853()}
