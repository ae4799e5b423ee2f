"""The basic pogo stick's event sequence in closed form (docs/models.md, "PogoStick").

With ``F_ext = 0`` the flight is a parabola and the contact a damped linear oscillator, so every
touchdown and liftoff time is the root of an elementary function.  They are computed here with
mpmath at ``digits`` significant digits (40 by default): an independent reference for the engine,
the FMUs and the work-precision study, computed by the project, not read from anywhere.

Flight (``s = 0``): ``y(t) = y_a + v_a t - g t^2/2`` until the foot reaches the ground, ``y = x_i``
falling.  Contact (``s = 1``): with the leg deflection ``x = y - x_i`` and its equilibrium
``x_eq = -m g/k``, ``u = x - x_eq`` obeys ``u'' + (c/m) u' + (k/m) u = 0`` from
``u(0) = m g/k``, ``u'(0) = v_td``; the stick lifts off when ``x`` returns to 0 rising, i.e. at the
first ``t > 0`` with ``u(t) = m g/k``.  If the oscillation never comes back that high, the stick
stays in contact for ever (no further event).

Host-side code (needs mpmath); never imported inside an FMU.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import List, Optional

DEFAULTS = {"m": 1.0, "k": 100.0, "c": 0.5, "x_i": 1.0, "g": 9.81, "y_0": 1.5, "ydot_0": 0.0}


def basic_events(params: Optional[dict] = None, t_end: float = math.inf, digits: int = 40,
                 max_events: int = 10_000) -> List[dict]:
    """Events of the basic pogo stick dropped from flight: ``[{"index", "event", "time", "y",
    "ydot"}]`` (times and velocities as mpmath numbers of ``digits`` digits; ``float()`` them).

    ``params`` may set ``m, k, c, x_i, g, y_0, ydot_0`` (others of the FMU are irrelevant here);
    the stick starts in flight (``y_0 > x_i``), and the contact must be underdamped
    (``c^2 < 4 k m``), as with the defaults."""
    import mpmath

    p = dict(DEFAULTS, **(params or {}))
    with mpmath.workdps(digits + 10):
        mp = mpmath.mpf
        m, k, c, xi, g = (mp(p[n]) for n in ("m", "k", "c", "x_i", "g"))
        y, v = mp(p["y_0"]), mp(p["ydot_0"])
        if not y > xi:
            raise ValueError(f"y_0 = {p['y_0']!r} must exceed x_i = {p['x_i']!r}: the stick starts in flight")
        sigma = c / (2 * m)
        w2 = k / m - sigma ** 2
        if not w2 > 0:
            raise ValueError("the contact must be underdamped (c^2 < 4 k m) for this closed form")
        wd = mpmath.sqrt(w2)
        u0 = m * g / k  # u = x - x_eq at touchdown and at liftoff
        t, out = mp(0), []
        while len(out) < max_events:
            # flight: y + v tau - g tau^2/2 = x_i, the root after the apex (or the only positive one)
            tau = (v + mpmath.sqrt(v * v + 2 * g * (y - xi))) / g if g > 0 else None
            if tau is None or t + tau > t_end:
                break
            t += tau
            v_td = v - g * tau
            out.append({"index": len(out) + 1, "event": "touchdown", "time": t, "y": xi, "ydot": v_td})
            # contact: u(t) = exp(-sigma t) (A cos wd t + B sin wd t), A = u0, B = (v_td + sigma u0)/wd
            A, B = u0, (v_td + sigma * u0) / wd

            def f(s):
                return mpmath.exp(-sigma * s) * (A * mpmath.cos(wd * s) + B * mpmath.sin(wd * s)) - u0

            def fdot(s):
                e = mpmath.exp(-sigma * s)
                return e * ((B * wd - sigma * A) * mpmath.cos(wd * s) - (A * wd + sigma * B) * mpmath.sin(wd * s))

            fa, fs, fw, fb, fu = float(A), float(sigma), float(wd), float(B), float(u0)

            def f_float(s):  # the same function in double precision: only to bracket the root
                return math.exp(-fs * s) * (fa * math.cos(fw * s) + fb * math.sin(fw * s)) - fu

            s_lo = _first_rising_root(f, f_float, 2 * mpmath.pi / wd)
            if s_lo is None or t + s_lo > t_end:
                break  # settles in contact (or the stop time comes first)
            t += s_lo
            v = fdot(s_lo)
            y = xi
            out.append({"index": len(out) + 1, "event": "liftoff", "time": t, "y": xi, "ydot": v})
        return [dict(e, time=+e["time"], ydot=+e["ydot"]) for e in out]


def _first_rising_root(f, f_float, period, samples=4000):
    """The first root of ``f`` in ``(0, period]`` where it crosses from below (f(0) = 0, f < 0 just
    after): bracketed on a grid with ``f_float`` (the same function in double precision), refined
    by mpmath's bisection-secant (anderson) solver on ``f`` at full precision; the bracket is
    widened by a grid cell each side, so a root within rounding of a grid point is kept."""
    import mpmath

    h = float(period) / samples
    grid = [h * j for j in range(1, samples + 1)]
    values = [f_float(s) for s in grid]
    for j in range(len(grid) - 1):
        if values[j] < 0 <= values[j + 1]:
            a, b = grid[max(j - 1, 0)], grid[min(j + 2, len(grid) - 1)]
            if not f(a) < 0 <= f(b):
                a, b = grid[j], grid[j + 1]
            return mpmath.findroot(f, (a, b), solver="anderson")
    return None


def basic_state(t: float, params: Optional[dict] = None, digits: int = 40):
    """``(y, ydot)`` of the basic pogo stick at time ``t`` (mpmath numbers): the segment after the
    latest event before ``t`` — a parabola in flight, the damped oscillator in contact — evaluated
    in closed form. The reference of the study's global error at the stop time."""
    import mpmath

    p = dict(DEFAULTS, **(params or {}))
    events = basic_events(p, t_end=t, digits=digits)
    with mpmath.workdps(digits + 10):
        mp = mpmath.mpf
        m, k, c, xi, g = (mp(p[n]) for n in ("m", "k", "c", "x_i", "g"))
        T = mp(t)
        if not events:
            tau = T
            return mp(p["y_0"]) + mp(p["ydot_0"]) * tau - g * tau ** 2 / 2, mp(p["ydot_0"]) - g * tau
        last = events[-1]
        s = T - last["time"]
        if last["event"] == "liftoff":  # flight from the ground at the liftoff velocity
            v = last["ydot"]
            return xi + v * s - g * s ** 2 / 2, v - g * s
        sigma = c / (2 * m)
        wd = mpmath.sqrt(k / m - sigma ** 2)
        u0 = m * g / k
        A, B = u0, (last["ydot"] + sigma * u0) / wd
        e = mpmath.exp(-sigma * s)
        u = e * (A * mpmath.cos(wd * s) + B * mpmath.sin(wd * s))
        udot = e * ((B * wd - sigma * A) * mpmath.cos(wd * s) - (A * wd + sigma * B) * mpmath.sin(wd * s))
        return xi + (u - u0), udot  # y = x_i + x, x = u + x_eq, x_eq = -u0


@lru_cache(maxsize=32)
def _cached(key, t_end):
    return tuple({"index": e["index"], "name": e["event"], "time": float(e["time"]), "y": float(e["y"]),
                  "ydot": float(e["ydot"])} for e in basic_events(dict(key), t_end))


def events_as_floats(params: Optional[dict] = None, t_end: float = math.inf) -> List[dict]:
    """:func:`basic_events` with plain floats (what the tests and the studies compare against);
    cached per parameter set."""
    key = tuple(sorted(dict(DEFAULTS, **(params or {})).items()))
    return [dict(e) for e in _cached(key, t_end)]
