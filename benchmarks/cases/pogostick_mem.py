"""Benchmark case PogoStickMem (docs/models.md "PogoStickMem"): softening mem-spring + linear dashpot (the defaults).

The scipy peer integrates the same 8 states as ``pogofmu.runtime.models.pogo_stick_mem.MODEL`` --
``[xbar, xdot, y, ydot, z, a, W_leg, W_ext]`` (absement ``a' = x``) -- with one right-hand side
per mode, terminal events and a restart loop (``F_ext = 0``, so ``W_ext`` stays 0).
No closed form: the reference is the independent scipy model of tests/test_mem.py (DOP853, rtol 1e-13),
not this peer.
"""
from __future__ import annotations

from scipy.integrate import solve_ivp

from . import Case, tests_reference


def scipy_loop(p, stop_time, method, rtol, atol, max_step):
    """Events ``[(time, name), ...]`` of the mem-stick up to ``stop_time`` with ``solve_ivp``."""
    m, k, c, x_i, g = p["m"], p["k"], p["c"], p["x_i"], p["g"]
    law, beta, gamma = int(p["spring_law"]), p["beta"], p["gamma"]

    def flight(t, X):
        xbar, xdot, y, ydot, z, a, W_leg, W_ext = X
        return [xdot, 0.0, ydot, -g, ydot - xdot, xbar - x_i, 0.0, 0.0]

    def contact(t, X):
        xbar, xdot, y, ydot, z, a, W_leg, W_ext = X
        x = xbar - x_i
        if law == 0:
            ka = k
        elif law == 1:
            ka = k / (1.0 + beta * abs(a))
        else:
            ka = k * (1.0 + beta * abs(a))
        r = ka * x + c * (1.0 + gamma * x * x) * xdot
        acc = -r / m - g
        return [xdot, acc, ydot, acc, 0.0, x, r * xdot, 0.0]

    def touchdown(t, X):  # foot height z falls through 0 (flight)
        return X[4]

    touchdown.terminal, touchdown.direction = True, -1

    def liftoff(t, X):  # leg back at its free length (contact)
        return X[0] - x_i

    liftoff.terminal, liftoff.direction = True, 1

    X = [p["xbar_0"], p["xdot_0"], p["y_0"], p["ydot_0"], p["z_0"], p["a_0"], 0.0, 0.0]
    s = 0 if p["z_0"] > 0 else 1
    t = 0.0
    events = []
    while t < stop_time:
        rhs, guard = (flight, touchdown) if s == 0 else (contact, liftoff)
        sol = solve_ivp(rhs, (t, stop_time), X, method=method, events=guard,
                        rtol=rtol, atol=atol, max_step=max_step)
        if sol.status != 1:
            if sol.status < 0:
                raise RuntimeError(f"solve_ivp failed at t = {sol.t[-1]}: {sol.message}")
            break
        t, X = sol.t_events[0][0], list(sol.y_events[0][0])
        if s == 0:
            X[1], X[4], s = X[3], 0.0, 1
            events.append((t, "touchdown"))
        else:
            X[0], X[1], X[4], s = x_i, 0.0, 0.0, 0
            events.append((t, "liftoff"))
    return events


CASE = Case(
    name="PogoStickMem",
    fmu="PogoStickMem",
    model="pogofmu.runtime.models.pogo_stick_mem:MODEL",
    params={},  # default: softening mem-spring, beta = 1; 11 events, then drifts down in contact
    scipy_loop=scipy_loop,
    reference=tests_reference("mem"),
    reference_label="the independent scipy model of tests/test_mem.py (DOP853, rtol 1e-13)",
)
