"""Benchmark case PogoStickSMA (docs/models.md "PogoStickSMA"): superelastic SMA flag + linear dashpot, defaults.

The scipy peer integrates the same 7 states as ``pogofmu.runtime.models.pogo_stick_sma.MODEL`` --
``[xbar, xdot, y, ydot, z, W_leg, W_ext]`` -- with one right-hand side per (mode, SMA branch),
the contact and branch guards as terminal events with a direction, and a restart loop that applies
the jump (branch, anchor).  No closed form for the event times: the reference is the independent
scipy model of tests/test_sma.py (DOP853, rtol 1e-13; 23 events in 10 s), not this peer.
"""
from __future__ import annotations

from scipy.integrate import solve_ivp

from . import Case, tests_reference


def scipy_loop(p, stop_time, method, rtol, atol, max_step):
    """Events ``[(time, name), ...]`` of the SMA stick up to ``stop_time`` with ``solve_ivp``."""
    m, c, x_i, g = p["m"], p["c"], p["x_i"], p["g"]
    k1, k2, x1, x3 = p["k1"], p["k2"], p["x1"], p["x3"]

    def r_up(x):
        return k1 * x1 + k2 * (x - x1)

    def r_low(x):
        return k1 * x3 + k2 * (x - x3)

    def flight(t, X):
        return [X[1], 0.0, X[3], -g, X[3] - X[1], 0.0, 0.0]

    def contact_rhs(r_sma):
        def rhs(t, X):
            xbar, xdot, y, ydot, z, W_leg, W_ext = X
            r = r_sma(xbar - x_i) + c * xdot
            acc = -r / m - g
            return [xdot, acc, ydot, acc, 0.0, r * xdot, 0.0]
        return rhs

    def event(fun, direction, name):
        fun.terminal, fun.direction, fun.__name__ = True, direction, name
        return fun

    touchdown = event(lambda t, X: X[4], -1, "touchdown")
    liftoff = event(lambda t, X: X[0] - x_i, 1, "liftoff")
    reversal = event(lambda t, X: X[1], 1, "reversal")
    reload = event(lambda t, X: X[1], -1, "reload")
    virgin = event(lambda t, X: X[0] - x_i - x3, 1, "virgin_line")
    upper_rhs, lower_rhs = contact_rhs(r_up), contact_rhs(r_low)

    X = [p["xbar_0"], p["xdot_0"], p["y_0"], p["ydot_0"], p["z_0"], 0.0, 0.0]
    s, branch, xa, ra = (0 if p["z_0"] > 0 else 1), 0, 0.0, 0.0
    t = 0.0
    events = []
    while t < stop_time:
        if s == 0:
            rhs, guards = flight, [touchdown]
        elif branch == 0:
            rhs = contact_rhs(lambda x, xa=xa, ra=ra: ra + k1 * (x - xa))
            to_up = event(lambda t, X, xa=xa, ra=ra: ra + k1 * (X[0] - x_i - xa) - r_up(X[0] - x_i), -1,
                          "upper_plateau")
            if xa == 0.0:  # virgin line: the foot may leave the ground
                guards = [liftoff, to_up]
            else:
                to_low = event(lambda t, X, xa=xa, ra=ra: ra + k1 * (X[0] - x_i - xa) - r_low(X[0] - x_i), 1,
                               "lower_plateau")
                guards = [to_up, to_low]
        elif branch == 1:
            rhs, guards = upper_rhs, [reversal]
        else:
            rhs, guards = lower_rhs, [virgin, reload]
        sol = solve_ivp(rhs, (t, stop_time), X, method=method, events=guards,
                        rtol=rtol, atol=atol, max_step=max_step)
        if sol.status != 1:
            if sol.status < 0:
                raise RuntimeError(f"solve_ivp failed at t = {sol.t[-1]}: {sol.message}")
            break
        j = min((te[0], i) for i, te in enumerate(sol.t_events) if len(te))[1]
        t, X, name = sol.t_events[j][0], list(sol.y_events[j][0]), guards[j].__name__
        x = X[0] - x_i
        if name == "touchdown":
            X[1], X[4], s = X[3], 0.0, 1
        elif name == "liftoff":
            X[0], X[1], X[4], s = x_i, 0.0, 0.0, 0
        elif name == "upper_plateau":
            branch = 1
        elif name == "reversal":
            branch, xa, ra = 0, x, r_up(x)
        elif name == "lower_plateau":
            branch = 2
        elif name == "virgin_line":
            branch, xa, ra = 0, 0.0, 0.0
        else:  # reload
            branch, xa, ra = 0, x, r_low(x)
        events.append((t, name))
    return events


CASE = Case(
    name="PogoStickSMA",
    fmu="PogoStickSMA",
    model="pogofmu.runtime.models.pogo_stick_sma:MODEL",
    params={},  # default drop: 3 full flags and a small one, 23 events, settles in contact
    scipy_loop=scipy_loop,
    reference=tests_reference("sma"),
    reference_label="the independent scipy model of tests/test_sma.py (DOP853, rtol 1e-13)",
)
