"""Benchmark case PogoStick (docs/models.md "PogoStick"): the TEMPLATE to copy for a new model.

The scipy peer below is the basic pogo stick written as a Python user would write it with
``solve_ivp``: one right-hand side per mode, the guards as terminal events with a direction, and a
restart loop that applies the jump.  It integrates the same 7 states as
``pogofmu.runtime.models.pogo_stick.MODEL`` -- ``[xbar, xdot, y, ydot, z, W_leg, W_ext]`` -- so that both
solvers' error control sees the same vector (``F_ext = 0``, so ``W_ext`` stays 0).
"""
from __future__ import annotations

from scipy.integrate import solve_ivp

from . import Case, closed_form_reference


def scipy_loop(p, stop_time, method, rtol, atol, max_step):
    """Events ``[(time, name), ...]`` of the pogo stick up to ``stop_time`` with ``solve_ivp``."""
    m, k, c, x_i, g = p["m"], p["k"], p["c"], p["x_i"], p["g"]

    def flight(t, X):
        xbar, xdot, y, ydot, z, W_leg, W_ext = X
        return [xdot, 0.0, ydot, -g, ydot - xdot, 0.0, 0.0]

    def contact(t, X):
        xbar, xdot, y, ydot, z, W_leg, W_ext = X
        r = k * (xbar - x_i) + c * xdot
        acc = -r / m - g
        return [xdot, acc, ydot, acc, 0.0, r * xdot, 0.0]

    def touchdown(t, X):  # foot height z falls through 0 (flight)
        return X[4]

    touchdown.terminal, touchdown.direction = True, -1

    def liftoff(t, X):  # leg back at its free length (contact)
        return X[0] - x_i

    liftoff.terminal, liftoff.direction = True, 1

    X = [p["xbar_0"], p["xdot_0"], p["y_0"], p["ydot_0"], p["z_0"], 0.0, 0.0]
    s = 0 if p["z_0"] > 0 else 1
    t = 0.0
    events = []
    while t < stop_time:
        rhs, guard = (flight, touchdown) if s == 0 else (contact, liftoff)
        sol = solve_ivp(rhs, (t, stop_time), X, method=method, events=guard,
                        rtol=rtol, atol=atol, max_step=max_step)
        if sol.status != 1:  # reached stop_time (0) or failed (-1)
            if sol.status < 0:
                raise RuntimeError(f"solve_ivp failed at t = {sol.t[-1]}: {sol.message}")
            break
        t, X = float(sol.t_events[0][0]), list(sol.y_events[0][0])
        if s == 0:  # touchdown: s <- 1, xdot <- ydot, z <- 0
            X[1], X[4], s = X[3], 0.0, 1
            events.append((t, "touchdown"))
        else:  # liftoff: s <- 0, xdot <- 0, xbar <- x_i, z <- 0
            X[0], X[1], X[4], s = x_i, 0.0, 0.0, 0
            events.append((t, "liftoff"))
    return events


CASE = Case(
    name="PogoStick",
    fmu="PogoStick",
    model="pogofmu.runtime.models.pogo_stick:MODEL",
    params={},  # the default experiment: drop from y = 1.5 m, 19 events, settles after t = 7.07 s
    scipy_loop=scipy_loop,
    reference=closed_form_reference,
    reference_label="closed form (pogofmu.references.closed_form, 19 events)",
    targets=True,
)
