"""The tests' independent references: models of the FMUs' equations written here with scipy,
not calling the project's code (closed forms are in pogofmu.references.closed_form and in the tests that
use them). One module, so that no test imports another test for its reference.

* :func:`scipy_mem` — the mem-stick (PogoStickMem) from the default drop;
* :func:`reference_stick` — any stick (linear, mem, SMA) of given parameters, one mode per branch
  of the SMA flag, guards written in x instead of the FMUs' force differences; :func:`scipy_sma`
  the SMA stick from the default drop;
* :func:`penetrator_reference` — the Penetrator (Eq. 50), :func:`hunt_crossley` its soil force;
* :func:`mirror_closed_loop` — a whole segmented mirror (docs/segmented-mirror.md): every
  actuator with its stops, every PID loop and the edge-sensor reconstruction in one ODE, the
  stops' contacts and releases as events.

Checked-in outputs of these (``tests/data/references/<Model>_ref.csv``, event name and time) let
a test compare an FMU without running scipy and show when a reference itself changes
(``python tests/references.py --write`` rewrites them; ``test_references`` checks them).
"""
import functools
import math

from scipy.integrate import solve_ivp

# the default drop of the sticks: m, k, c, x_i, g
M, K, C, X_I, G = 1.0, 100.0, 0.5, 1.0, 9.81
K1, K2, X1, X3 = 100.0, 40.0, -0.2, -0.1  # the SMA flag's defaults
PENETRATOR_DEFAULTS = dict(m=1.0, k=100.0, c=0.5, x_i=1.0, g=9.81, K=1e4, n=1.5, c_r=0.5, d0dot=3.1321,
                d0dot_from_impact=0, y_0=1.5, ydot_0=0.0)


def scipy_mem(law, beta, gamma, t_end, c=C, a0=0.0):
    """Events [(name, t, state)] of the mem-stick from the default drop; 'bottom' if xbar hits 0."""

    def k_of(a):
        return K if law == 0 else (K / (1 + beta * abs(a)) if law == 1 else K * (1 + beta * abs(a)))

    def flight(t, X):
        xbar, xdot, y, ydot, z, a = X
        return [0.0, 0.0, ydot, -G, ydot, 0.0]

    def contact(t, X):
        xbar, xdot, y, ydot, z, a = X
        x = xbar - X_I
        r = k_of(a) * x + c * (1 + gamma * x * x) * xdot
        acc = -r / M - G
        return [xdot, acc, ydot, acc, 0.0, x]

    def touchdown(t, X):
        return X[4]

    def liftoff(t, X):
        return X[0] - X_I

    def bottom(t, X):
        return X[0]

    for f, d in ((touchdown, -1), (liftoff, 1), (bottom, -1)):
        f.terminal, f.direction = True, d
    X, s, t, out = [X_I, 0.0, 1.5, 0.0, 0.5, a0], 0, 0.0, []
    while t < t_end:
        rhs, evs = (flight, [touchdown]) if s == 0 else (contact, [liftoff, bottom])
        sol = solve_ivp(rhs, (t, t_end), X, method="DOP853", events=evs, rtol=1e-13, atol=1e-15, max_step=0.01)
        assert sol.status >= 0, sol.message
        if sol.status == 0:
            break
        j = next(i for i, te in enumerate(sol.t_events) if len(te))
        t, X = sol.t_events[j][0], list(sol.y_events[j][0])
        name = evs[j].__name__
        out.append((name, t, list(X)))
        if name == "bottom":
            break
        if name == "touchdown":
            X[1], X[4], s = X[3], 0.0, 1
        else:
            X[0], X[1], X[4], s = X_I, 0.0, 0.0, 0
    return out


def _ev(fun, direction, name, on_xbar=False):
    fun.terminal, fun.direction, fun.__name__, fun.on_xbar = True, direction, name, on_xbar
    return fun


def _turn(t, X):  # the leg's length turns (xdot = 0): where a guard on xbar has its extrema
    return X[1]


_turn.terminal, _turn.direction = False, 0


def _excursion(sol, evs, t0):
    """The earliest crossing of a guard on xbar that scipy's sign check at step ends cannot see:
    xbar goes over the level and back inside one step (a liftoff of a few ms inside a 10 ms
    step). Between two turns of xbar (xdot = 0, located as the last, non-terminal event) xbar is
    monotone, so a guard found on its after side at a turn crossed exactly once since the turn
    before; the root is found on the dense output. (t, j, X), or None; (t0, -1, None) when the
    crossing is at the segment's own start (cannot judge)."""
    from scipy.optimize import brentq

    before = t0
    for tt in sol.t_events[-1]:
        if tt <= t0:
            continue
        Xt = sol.sol(tt)
        found = []
        for j, ev in enumerate(evs):
            if ev.on_xbar and ev.direction * ev(tt, Xt) > 0:
                g = lambda s, ev=ev: ev(s, sol.sol(s))  # noqa: E731
                if g(before) == 0.0:
                    return (t0, -1, None)
                r = brentq(g, before, tt, xtol=1e-16, rtol=1e-15, maxiter=200)
                found.append((r, j, list(sol.sol(r))))
        if found:
            return min(found)
        before = tt
    return None


def _ballistic_touchdown(z0, v0, g):
    """Time to touchdown of a flight from height z0 >= 0 over the ground with upward speed v0: the
    root tau > 0 of z0 + v0 tau - g tau^2 / 2 (0 when z0 = 0 and v0 <= 0), in the form without
    cancellation for either sign of v0."""
    s = math.sqrt(v0 * v0 + 2.0 * g * z0)
    return (v0 + s) / g if v0 >= 0 else 2.0 * z0 / (s - v0)


def reference_stick(name, p, t_end):
    """[(event name, time)] of a free (unforced) run of the stick with parameters ``p``; None where
    it cannot judge (chattering, a reload, or a contact shorter than its first step).

    The flight is ballistic (the leg at rest, z' = ydot, ydot' = -g), so its touchdown is the closed
    form: an integrator's event search cannot see a flight that lifts off and lands inside its first
    step (z = 0 at both ends of the bracket: scipy returns the flight's own start). The contact is
    integrated by scipy's DOP853 with terminal events."""
    from scipy.integrate import solve_ivp

    m, g, x_i, c = p["m"], p["g"], p["x_i"], p["c"]
    law, beta, gamma = p.get("spring_law", 0), p.get("beta", 0.0), p.get("gamma", 0.0)
    k1, k2, x1, x3 = p.get("k1"), p.get("k2"), p.get("x1"), p.get("x3")

    def k_of(a):  # the mem-spring's stiffness: linear, softening, hardening in the absement
        k = p["k"]
        return k if law == 0 else (k / (1 + beta * abs(a)) if law == 1 else k * (1 + beta * abs(a)))

    def contact(force):
        def f(t, X):
            xbar, xdot, y, ydot, z, a = X
            x = xbar - x_i
            acc = -force(x, xdot, a) / m - g
            return [xdot, acc, ydot, acc, 0.0, x]
        return f

    liftoff = _ev(lambda t, X: X[0] - x_i, 1, "liftoff", on_xbar=True)
    r_upper = lambda x: k1 * x1 + k2 * (x - x1)  # noqa: E731  (the SMA's plateaus)
    r_lower = lambda x: k1 * x3 + k2 * (x - x3)  # noqa: E731
    X = [p["xbar_0"], p["xdot_0"], p["y_0"], p["ydot_0"], p["z_0"], p.get("a_0", 0.0)]
    mode = "flight" if p["z_0"] > 0 else "contact"
    H = None
    t, out = 0.0, []
    while t < t_end:
        if len(out) > 400:
            return None  # chattering (a model for the engine's storm rules, not for this reference)
        if mode == "flight":
            tau = _ballistic_touchdown(X[4], X[3], g)
            if t + tau >= t_end:
                break
            t = t + tau
            X[2], X[3], X[4] = X[2] + X[3] * tau - 0.5 * g * tau * tau, X[3] - g * tau, 0.0
            out.append(("touchdown", t))
            X[1], mode = X[3], "contact"
            continue
        if name != "PogoStickSMA":
            f, evs = contact(lambda x, xdot, a: k_of(a) * x + c * (1 + gamma * x * x) * xdot), [liftoff]
        elif mode == "contact":  # the SMA's virgin (elastic) line
            f = contact(lambda x, xdot, a: k1 * x + c * xdot)
            evs = [liftoff, _ev(lambda t, X: X[0] - x_i - x1, -1, "upper_plateau", on_xbar=True)]
        elif mode == "upper":
            f, evs = contact(lambda x, xdot, a: r_upper(x) + c * xdot), [_ev(lambda t, X: X[1], 1, "reversal")]
        elif mode == "unload":  # elastic from the reversal at H; meets the lower plateau at H + x3 - x1
            f = contact(lambda x, xdot, a, H=H: r_upper(H) + k1 * (x - H) + c * xdot)
            evs = [_ev(lambda t, X, H=H: X[0] - x_i - (H + x3 - x1), 1, "lower_plateau", on_xbar=True),
                   _ev(lambda t, X, H=H: X[0] - x_i - H, -1, "upper_plateau", on_xbar=True)]
        else:  # the lower plateau
            f = contact(lambda x, xdot, a: r_lower(x) + c * xdot)
            evs = [_ev(lambda t, X: X[0] - x_i - x3, 1, "virgin_line", on_xbar=True),
                   _ev(lambda t, X: X[1], -1, "reload")]
        sol = solve_ivp(f, (t, t_end), X, method="DOP853", events=evs + [_turn], rtol=1e-12,
                        atol=1e-14 * max(1.0, x_i), max_step=0.01, dense_output=True)
        assert sol.status >= 0, sol.message
        hits = [(sol.t_events[i][0], i, list(sol.y_events[i][0])) for i in range(len(evs)) if len(sol.t_events[i])]
        missed = _excursion(sol, evs, t)
        hits += [missed] if missed else []
        if not hits:
            break
        te, j, Xe = min(hits, key=lambda h: h[0])
        if te == t:
            return None  # at the segment's own start: a contact over inside the first step, or none
        t, X, event = te, Xe, evs[j].__name__
        out.append((event, t))
        if event == "touchdown":
            X[1], X[4], mode = X[3], 0.0, "contact"
        elif event == "liftoff":
            X[0], X[1], X[4], mode = x_i, 0.0, 0.0, "flight"
        elif event == "upper_plateau":
            mode = "upper"
        elif event == "reversal":
            H, mode = X[0] - x_i, "unload"
        elif event == "lower_plateau":
            mode = "lower"
        elif event == "virgin_line":
            mode = "contact"
        else:  # a reload from the lower plateau: not in this reference (an unforced drop seldom has one)
            return None
    return out


def scipy_sma(t_end, c=C):
    """Events [(name, t)] of the SMA stick's free drop from y = 1.5 m (no forcing)."""
    p = dict(m=M, g=G, x_i=X_I, c=c, k1=K1, k2=K2, x1=X1, x3=X3,
             xbar_0=X_I, xdot_0=0.0, y_0=1.5, ydot_0=0.0, z_0=0.5)
    out = reference_stick("PogoStickSMA", p, t_end)
    assert out is not None, "the reference met a reload, which a free drop has not"
    return out


def _rhs(t, x, s, lam, P):
    y, v, d = x
    if not s:
        return [v, -P["g"], 0.0]
    m, k, c, x_i, K, n = P["m"], P["k"], P["c"], P["x_i"], P["K"], P["n"]
    pw = max(0.0, d) ** n
    dd = (-k * y - c * v - K * pw - k * d + k * x_i) / (lam * pw + c)  # Eq. 50
    return [v, -P["g"] - k / m * (y + d) + k / m * x_i - c / m * (v + dd), dd]


def _event(fun, direction, terminal):
    fun.direction, fun.terminal = direction, terminal
    return fun


@functools.lru_cache(maxsize=None)
def _reference_cached(t_end, items, method="DOP853", rtol=1e-13, atol=1e-15):
    P = dict(items)
    t, x = 0.0, [P["y_0"], P["ydot_0"], 0.0]
    s, d0, record = 0, P["d0dot"], 0.0
    t_lift, x_lift = 0.0, 0.0  # latest liftoff: time and leg deflection
    rk = P["k"] / P["c"]
    assert P["y_0"] > P["x_i"], "the reference starts in flight"
    out = []

    def foot(t, x, s, lam, P):  # foot height in flight: the free massless leg relaxes, k x + c x' = 0
        return x[0] - P["x_i"] - x_lift * math.exp(-rk * (t - t_lift))

    while t < t_end:
        lam = 1.5 * (1.0 - P["c_r"]) * P["K"] / d0
        if s == 0:
            events = [_event(foot, -1, True)]
        else:
            events = [_event(lambda t, x, s, lam, P: x[2], -1, True),
                      _event(lambda t, x, s, lam, P: _rhs(t, x, 1, lam, P)[2], -1, False)]
        sol = solve_ivp(_rhs, (t, t_end), x, method=method, rtol=rtol, atol=atol, events=events,
                        args=(s, lam, P))
        assert sol.status >= 0, sol.message
        if s == 1:
            for te, xe in zip(sol.t_events[1], sol.y_events[1]):
                if xe[2] > record:
                    record = xe[2]
                    out.append(("max_penetration", float(te), xe.copy()))
        if sol.status != 1:
            break
        te, xe = float(sol.t_events[0][0]), sol.y_events[0][0].copy()
        out.append(("touchdown" if s == 0 else "liftoff", te, xe))
        x = [xe[0], xe[1], 0.0]
        if s == 0:
            impact = -xe[1] - rk * x_lift * math.exp(-rk * (te - t_lift))  # foot speed
            d0 = impact if P["d0dot_from_impact"] and impact > 0 else P["d0dot"]
        else:
            t_lift, x_lift = te, xe[0] - P["x_i"]
        t, s = te, 1 - s
    return out, record


def penetrator_reference(t_end=10.0, method="DOP853", rtol=1e-13, **par):
    """[(name, time, state before jump)], largest penetration; for the parameters ``par``, solved
    by scipy's ``method`` (DOP853 or, for stiff soils, Radau) at ``rtol``."""
    return _reference_cached(t_end, tuple(sorted(dict(PENETRATOR_DEFAULTS, **par).items())), method, rtol)


def penetrator_contacts(t_end, method, rtol, **par):
    """[(touchdown or liftoff, time)] of the Penetrator (the contact times, without the peaks)."""
    return [(n, t) for n, t, _ in penetrator_reference(t_end, method, rtol, **par)[0] if n != "max_penetration"]


def hard_stop_reference(t_end, F=30.0, method="Radau", rtol=1e-12, m=1.0, k=100.0, c=0.5, z_s=0.1, K=1e7, n=1.0,
                        c_r=0.8, d0dot=1.0):
    """[(contact or release, time)] of a mass on a spring and a dashpot pushed by a constant force
    ``F`` against a Hunt-Crossley stop at z = z_s (examples/hard_stop/), from rest at z = 0."""
    lam = 1.5 * (1 - c_r) * K / d0dot

    def free(t, x):
        return [x[1], (F - k * x[0] - c * x[1]) / m]

    def stop(t, x):
        d = max(x[0] - z_s, 0.0)
        return [x[1], (F - k * x[0] - c * x[1] - (K + lam * x[1]) * d ** n) / m]

    contact = _ev(lambda t, x: x[0] - z_s, 1, "contact")
    release = _ev(lambda t, x: x[0] - z_s, -1, "release")
    t, x, on, out = 0.0, [0.0, 0.0], False, []
    while t < t_end:
        sol = solve_ivp(stop if on else free, (t, t_end), x, method=method, rtol=rtol, atol=1e-15,
                        events=[release if on else contact], max_step=0.01)
        assert sol.status >= 0, sol.message
        if sol.status == 0:
            break
        t, x = float(sol.t_events[0][0]), list(sol.y_events[0][0])
        out.append(("release" if on else "contact", t))
        on = not on
    return out


def hunt_crossley(state, d0, **par):
    """Soil force of a contact state [y, ydot, delta] (independent of the package)."""
    P = dict(PENETRATOR_DEFAULTS, **par)
    lam = 1.5 * (1 - P["c_r"]) * P["K"] / d0
    dd = _rhs(0.0, state[:3], 1, lam, P)[2]
    return P["K"] * max(0.0, state[2]) ** P["n"] * (1 + lam / P["K"] * dd)


def mirror_closed_loop(actuators, controllers, reconstructor, edges, t_eval, method="DOP853", rtol=1e-12,
                       atol=1e-16, locate_kinks=True):
    """The closed loop of a segmented mirror as one ODE (scipy), the pistons ``z[i]`` at
    ``t_eval`` and the stops' events ``[(segment, name, time)]``.

    ``actuators[i]``, ``controllers[i]``: dicts of segment i's parameters (the names of the
    .ssv files; a name missing is the model's default: n = 1, a_0 = I_0 = 0, spring_law 1);
    ``reconstructor``: ``z_target``, ``G``; ``edges``: the neighbour pairs (i, j) of the edge
    sensors, s = z_j - z_i.  Per segment the states are z, z', the absement a, the controller's
    integral I and filtered piston w:

        m z'' = F + F_w(t) - k z - c z' - k_m/(1 + beta |a|) z + F_stop,   a' = z
        F_stop = -(K + lam z') max(0, z - z_s)^n on the upper stop, (K - lam z') max(0, -z_s - z)^n
                 on the lower, lam = 1.5 (1 - c_r) K / d0dot (not clipped at 0: the Hunt-Crossley law)
        r = z_target - G z_rel,  z_rel the minimum-norm least squares of D z_rel = D z (numpy pinv)
        F_u = K_p (r - z) + K_i I - K_d (z - w)/T_f,  F = clip(F_u, +-F_max)
        I' = (r - z) + (F - F_u)/(K_i T_t),  w' = (z - w)/T_f

    Contact where z crosses +-z_s towards the stop, release where it crosses back (the modes
    switch there, as in the FMU: a stop holds its mode until z crosses back).  The integration
    restarts at every event, at the gust's start and end (its second derivative jumps there) and,
    with ``locate_kinks``, where a clip's F_u crosses +-F_max (the right-hand side has a kink
    there), so that no step of the integrator straddles a loss of smoothness."""
    import numpy as np

    n = len(actuators)
    col = lambda d, key, default=None: np.array([float(x.get(key, default)) for x in d])  # noqa: E731
    assert all(int(x.get("spring_law", 1)) == 1 for x in actuators), "the softening mem-spring only"
    m, k, c, km, beta = (col(actuators, q) for q in ("m", "k", "c", "k_m", "beta"))
    zs, Ks, nexp, cr, d0 = col(actuators, "z_s"), col(actuators, "K"), col(actuators, "n", 1.0), \
        col(actuators, "c_r"), col(actuators, "d0dot")
    Aw, tg, Tg = (col(actuators, q) for q in ("A_w", "t_g", "T_g"))
    lam = 1.5 * (1 - cr) * Ks / d0
    Kp, Ki, Kd, Tf, Tt, Fm = (col(controllers, q) for q in ("K_p", "K_i", "K_d", "T_f", "T_t", "F_max"))
    D = np.zeros((len(edges), n))
    for e, (i, j) in enumerate(edges):
        D[e, i], D[e, j] = -1.0, 1.0
    P = np.linalg.pinv(D) @ D  # z_rel = pinv(D) s = P z
    zt, G = float(reconstructor["z_target"]), float(reconstructor["G"])

    def unsaturated(z, I, w):
        return Kp * ((zt - G * (P @ z)) - z) + Ki * I - Kd * (z - w) / Tf

    def rhs(t, X, mode):
        z, zd, a, I, w = X.reshape(5, n)
        r = zt - G * (P @ z)
        Fu = Kp * (r - z) + Ki * I - Kd * (z - w) / Tf
        F = np.clip(Fu, -Fm, Fm)
        on = (t > tg) & (t < tg + Tg)
        Fw = np.where(on, 0.5 * Aw * (1 - np.cos(2 * np.pi * (t - tg) / Tg)), 0.0)
        up = -(Ks + lam * zd) * np.maximum(z - zs, 0.0) ** nexp
        low = (Ks - lam * zd) * np.maximum(-zs - z, 0.0) ** nexp
        Fs = np.where(mode == 1, up, np.where(mode == -1, low, 0.0))
        zdd = (F + Fw - k * z - c * zd - km / (1 + beta * np.abs(a)) * z + Fs) / m
        return np.concatenate([zd, zdd, z, (r - z) + (F - Fu) / (Ki * Tt), (z - w) / Tf])

    X = np.concatenate([col(actuators, "z_0"), np.zeros(n), col(actuators, "a_0", 0.0), col(controllers, "I_0", 0.0),
                        col(controllers, "z_0")])
    assert np.all(np.abs(X[:n]) < zs), "the actuators start off their stops"
    mode = np.zeros(n, dtype=int)
    t_eval = np.asarray(t_eval, dtype=float)
    t, t_end = float(t_eval[0]), float(t_eval[-1])
    breaks = sorted({float(b) for b in np.r_[tg, tg + Tg] if t < b < t_end} | {t_end})
    out = np.full((n, len(t_eval)), np.nan)
    events = []
    F_u0 = unsaturated(X[:n], X[3 * n:4 * n], X[4 * n:])
    side = {(i, sign): 1.0 if F_u0[i] > sign * Fm[i] else -1.0 for i in range(n) for sign in (1.0, -1.0)}
    while t < t_end:
        t_next = next(b for b in breaks if b > t)
        fns, what = [], []
        for i in range(n):  # the events the current modes arm
            if mode[i] == 0:
                cand = ((lambda tt, X, *_, i=i: X[i] - zs[i], 1, 1, "upper_contact"),
                        (lambda tt, X, *_, i=i: X[i] + zs[i], -1, -1, "lower_contact"))
            else:
                s = mode[i]
                cand = ((lambda tt, X, *_, i=i, s=s: X[i] - s * zs[i], -s, 0,
                         "upper_release" if s == 1 else "lower_release"),)
            for fun, direction, to, name in cand:
                fun.terminal, fun.direction = True, direction
                fns.append(fun)
                what.append((i, to, name))
            if locate_kinks:
                for sign in (1.0, -1.0):  # F_u = +-F_max: a kink, no mode (a restart only)
                    fun = (lambda tt, X, *_, i=i, sign=sign:
                           unsaturated(X[:n], X[3 * n:4 * n], X[4 * n:])[i] - sign * Fm[i])
                    # armed for the crossing away from the side F_u is on, which the restart right
                    # after a crossing (its guard ~0, of either sign) knows from the crossing
                    fun.terminal, fun.direction = True, -side[i, sign]
                    fns.append(fun)
                    what.append((i, sign, "kink"))
        sol = solve_ivp(rhs, (t, t_next), X, method=method, rtol=rtol, atol=atol, events=fns,
                        args=(mode.copy(),), dense_output=True)
        assert sol.status >= 0, sol.message
        hits = [(sol.t_events[q][0], q) for q in range(len(fns)) if len(sol.t_events[q])]
        t_stop = min(hits)[0] if hits else t_next
        take = (t_eval >= t) & (t_eval <= t_stop)
        if take.any():
            out[:, take] = sol.sol(t_eval[take])[:n]
        if hits:
            te, q = min(hits)
            i, to, name = what[q]
            X = sol.y_events[q][0]
            if name == "kink":
                side[i, to] = -side[i, to]
            else:
                events.append((i, name, te))
                mode = mode.copy()
                mode[i] = to
        else:
            te, X = t_next, sol.y[:, -1]
        t = te
    return out, events


REFERENCE_OUTPUTS = {  # model: (its reference's events [(name, time)], the stop time)
    "PogoStickMem": (lambda: [(n, t) for n, t, _ in scipy_mem(1, 1.0, 0.0, 10.0)], 10.0),
    "PogoStickSMA": (lambda: scipy_sma(10.0), 10.0),
    "Penetrator": (lambda: [(n, t) for n, t, _ in penetrator_reference(10.0)[0]], 10.0),
}


def reference_csv(model):
    from pathlib import Path

    return Path(__file__).resolve().parent / "data" / "references" / f"{model}_ref.csv"


def read_reference(model):
    """The checked-in events [(name, time)] of ``model``'s reference."""
    rows = reference_csv(model).read_text().splitlines()[1:]
    return [(r.split(",")[0], float(r.split(",")[1])) for r in rows]


def write_references():
    for model, (events, _) in REFERENCE_OUTPUTS.items():
        path = reference_csv(model)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("event,time_s\n" + "".join(f"{n},{t!r}\n" for n, t in ((n, float(t)) for n, t in events())))


if __name__ == "__main__":
    import sys

    if sys.argv[1:] == ["--write"]:
        write_references()
