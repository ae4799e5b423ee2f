"""The SpaceHopper's continuous-time closed loop: the reference of the coupling study and tests.

The stick's contact equations with the controller's thrust law inside the ODE — no coupling
delay, no sampling — integrated by scipy's DOP853 at rtol 1e-12, the flight in closed form. The
law is written here from its formula (docs/models.md, "HopController"), independently of the FMU
code: the reference of every master algorithm, the strongly coupled one included.

Host-side code (scipy); never imported inside an FMU.
"""
from __future__ import annotations

import math


def thrust_law(y, ydot, s, p):
    """``F = clip(K_D c ydot + (m g h_target - E_est)/(tau_E ydot), 0, F_max)`` while ``s = 1``
    and ``ydot > 0``, else 0; ``E_est = m ydot^2/2 + m g y + k (y - x_i)^2/2`` in contact."""
    if s != 1 or ydot <= 0:
        return 0.0
    E = 0.5 * p["m"] * ydot ** 2 + p["m"] * p["g"] * y + 0.5 * p["k"] * (y - p["x_i"]) ** 2
    e = p["m"] * p["g"] * p["h_target"] - E
    return min(max(p["K_D"] * p["c"] * ydot + e / (p["tau_E"] * ydot), 0.0), p["F_max"])


def first_apex(p) -> float:
    """First apex height [m] after a drop at rest from ``y_0`` (``p``: the parameter set's values
    ``m, g, k, c, x_i, y_0, h_target, tau_E, K_D, F_max``)."""
    return first_hop(p)["apex"]


def first_hop(p) -> dict:
    """The first hop after a drop at rest from ``y_0``: the instants of the touchdown, the bottom
    of the stroke (where the thrust switches on) and the liftoff [s], and the apex [m]."""
    from scipy.integrate import solve_ivp

    m, g, k, c, xi = p["m"], p["g"], p["k"], p["c"], p["x_i"]
    v_td = -math.sqrt(2 * g * (p["y_0"] - xi))

    def compression(t, X):
        return [X[1], (-k * (X[0] - xi) - c * X[1]) / m - g]

    bottom = lambda t, X: X[1]  # noqa: E731
    bottom.terminal, bottom.direction = True, 1
    s1 = solve_ivp(compression, (0, 10), [xi, v_td], method="DOP853", rtol=1e-12, atol=1e-14, events=bottom)
    y_b, t_b = s1.y_events[0][0][0], s1.t_events[0][0]

    def extension(t, X):
        F = p["F_max"] if X[1] <= 0 else thrust_law(X[0], X[1], 1, p)  # ydot -> 0+: the law saturates
        return [X[1], (F - k * (X[0] - xi) - c * X[1]) / m - g]

    liftoff = lambda t, X: X[0] - xi  # noqa: E731
    liftoff.terminal, liftoff.direction = True, 1
    s2 = solve_ivp(extension, (0, 10), [y_b, 0.0], method="DOP853", rtol=1e-12, atol=1e-14, events=liftoff,
                   max_step=1e-3)
    v_lo = s2.y_events[0][0][1]
    t_td = math.sqrt(2 * (p["y_0"] - xi) / g)
    return {"touchdown": t_td, "bottom": t_td + float(t_b), "liftoff": t_td + float(t_b + s2.t_events[0][0]),
            "apex": float(xi + v_lo ** 2 / (2 * g))}


def apex_of_run(res, g, component="PogoStick"):
    """The first apex of a master's run, from its rows: on the first flight row after the first
    contact whose held thrust is zero (then the flight is a parabola), ``y + ydot^2/(2 g)``; None
    if the run has no such row."""
    y, yd, s = res[f"{component}.y"], res[f"{component}.ydot"], res[f"{component}.s"]
    F = res[f"{component}.F_ext"]
    contact = False
    for k in range(len(y)):
        if s[k] == 1:
            contact = True
        elif contact and F[k] == 0.0:
            return float(y[k] + yd[k] ** 2 / (2 * g))
    return None


def first_apex_sampled(p, period: float) -> float:
    """First apex height [m] of the sampled-data closed loop: the stick's equations with the thrust
    law evaluated at the instants ``period, 2 period, ...`` from the stick's state there and held
    in between (zero before the first) (a digital controller at ``1/period`` Hz, ``HopController.sample_period``). scipy's
    DOP853 at rtol 1e-12, restarted at every tick and every contact; the apex is taken at the first
    tick after the liftoff (the held thrust is zero from there: a parabola)."""
    from scipy.integrate import solve_ivp

    m, g, k, c, xi = p["m"], p["g"], p["k"], p["c"], p["x_i"]
    t, y, v, s, F = 0.0, p["y_0"], 0.0, 0, 0.0
    lifted, n = False, 0
    while True:
        F = thrust_law(y, v, s, p) if n else 0.0  # the tick at t = n period: the law there, held
        if lifted and s == 0:
            return float(y + v * v / (2 * g))
        n += 1
        t_tick = n * period
        while t < t_tick:
            if s == 0:
                rhs = (lambda tt, X, F=F: [X[1], F / m - g])
                guard = (lambda tt, X: X[0] - xi)
                guard.direction = -1
            else:
                rhs = (lambda tt, X, F=F: [X[1], (F - k * (X[0] - xi) - c * X[1]) / m - g])
                guard = (lambda tt, X: X[0] - xi)
                guard.direction = 1
            guard.terminal = True
            sol = solve_ivp(rhs, (t, t_tick), [y, v], method="DOP853", rtol=1e-12, atol=1e-14, events=guard)
            if sol.t_events[0].size and sol.t_events[0][0] > t:
                t = float(sol.t_events[0][0])
                y, v = (float(a) for a in sol.y_events[0][0])
                y = xi  # on the leg's free length, exactly
                lifted |= s == 1
                s = 1 - s
            else:
                t, y, v = t_tick, float(sol.y[0][-1]), float(sol.y[1][-1])
