"""Benchmark case Penetrator (docs/models.md "Penetrator"): the stick driven into a Hunt-Crossley soil, defaults.

The scipy peer integrates the same 7 states as ``pogofmu.runtime.models.penetrator.MODEL`` --
``[y, ydot, delta, tau, W_leg, W_soil, W_ext]`` -- with one right-hand side per mode (Eq. 50 in
contact), the guards as terminal events with a direction (touchdown: the foot height
``y - x_i - x_lift exp(-(k/c) tau)`` falling; liftoff: ``delta`` falling; max_penetration: a new
record of the penetration, ``max(delta', delta_max - delta)`` falling), and a restart loop that
applies the jumps.  No closed form: the reference is the independent scipy model of
tests/test_penetrator.py (DOP853, rtol 1e-13; 19 touchdown/liftoff events and one penetration
record in 10 s), not this peer.
"""
from __future__ import annotations

import math

from scipy.integrate import solve_ivp

from . import Case, tests_reference


def scipy_loop(p, stop_time, method, rtol, atol, max_step):
    """Events ``[(time, name), ...]`` of the penetrator up to ``stop_time`` with ``solve_ivp``."""
    m, k, c, x_i, g = p["m"], p["k"], p["c"], p["x_i"], p["g"]
    K, n, c_r = p["K"], p["n"], p["c_r"]
    rk = k / c

    def flight(t, X):
        return [X[1], -g, 0.0, 1.0, 0.0, 0.0, 0.0]

    def contact_rhs(lam):
        def rate(X):
            y, ydot, d = X[0], X[1], X[2]
            P = max(0.0, d) ** n
            return (-k * (y + d - x_i) - c * ydot - K * P) / (lam * P + c)

        def rhs(t, X):
            y, ydot, d = X[0], X[1], X[2]
            dd = rate(X)
            v = ydot + dd
            r = k * (y + d - x_i) + c * v
            return [ydot, -g - r / m, dd, 0.0, r * v, -r * dd, 0.0]
        return rhs, rate

    def event(fun, name):
        fun.terminal, fun.direction, fun.__name__ = True, -1, name
        return fun

    y0 = p["y_0"]
    if y0 <= x_i:
        raise ValueError("the scipy peer starts in flight (y_0 > x_i)")
    X = [y0, p["ydot_0"], 0.0, 0.0, 0.0, 0.0, 0.0]
    s, d0, d_max, x_lift = 0, p["d0dot"], 0.0, 0.0
    t = 0.0
    events = []
    while t < stop_time:
        if s == 0:
            rhs = flight
            guards = [event(lambda t, X, xl=x_lift: X[0] - x_i - xl * math.exp(-rk * X[3]), "touchdown")]
        else:
            rhs, rate = contact_rhs(1.5 * (1.0 - c_r) * K / d0)
            guards = [event(lambda t, X: X[2], "liftoff"),
                      event(lambda t, X, rate=rate, M=d_max: max(rate(X), M - X[2]), "max_penetration")]
        sol = solve_ivp(rhs, (t, stop_time), X, method=method, events=guards,
                        rtol=rtol, atol=atol, max_step=max_step)
        if sol.status != 1:
            if sol.status < 0:
                raise RuntimeError(f"solve_ivp failed at t = {sol.t[-1]}: {sol.message}")
            break
        j = min((te[0], i) for i, te in enumerate(sol.t_events) if len(te))[1]
        t, X, name = float(sol.t_events[j][0]), list(sol.y_events[j][0]), guards[j].__name__
        if name == "touchdown":
            impact = -X[1] - rk * x_lift * math.exp(-rk * X[3])  # the foot's speed
            d0 = impact if p["d0dot_from_impact"] and impact > 0 else p["d0dot"]
            X[2], s = 0.0, 1
        elif name == "liftoff":
            x_lift = X[0] - x_i
            X[2], X[3], s = 0.0, 0.0, 0
        else:
            d_max = max(d_max, X[2])
        events.append((t, name))
    return events


CASE = Case(
    name="Penetrator",
    fmu="Penetrator",
    model="pogofmu.runtime.models.penetrator:MODEL",
    params={},  # default drop into K = 1e4 N/m^1.5, n = 1.5 soil: 19 contact events + 1 record
    scipy_loop=scipy_loop,
    reference=tests_reference("penetrator"),
    reference_label="the independent scipy model of tests/test_penetrator.py (DOP853, rtol 1e-13)",
)
