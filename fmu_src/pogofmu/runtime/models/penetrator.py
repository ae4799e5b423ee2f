"""Penetrator: the pogo stick driven into a Hunt–Crossley soil (docs/models.md "Penetrator"; paper Sect. 5,
Appendix A.3, Eqs. 49-50).

A mass ``m`` on a massless leg (linear spring ``k`` parallel to a linear dashpot ``c``, free length
``x_i``) whose massless foot penetrates a compliant soil (:class:`~pogofmu.runtime.soil.HuntCrossley`).
The foot's penetration ``delta`` (positive into the soil) is a state: the leg and the soil are in
series, and the force balance on the massless foot gives its rate.

Continuous states ``[y, ydot, delta, W_leg, W_soil, W_ext]``; discrete state
``q = {s, d0dot, delta_max}``: the mode (0 flight, 1 contact), the reference velocity of the
current contact's restitution law, and the largest penetration recorded so far.

Flow, with ``x = y + delta - x_i`` the leg deflection and ``P = max(0, delta)^n``::

    delta' = s (-k x - c ydot - K P) / (lambda P + c)          (force balance on the foot)
    y'     = ydot
    ydot'  = -g + F_ext/m - s r/m,     r = k x + c (ydot + delta')   (leg force; r = -F_soil)
    W_leg'  = s r (ydot + delta')      (power the leg absorbs: r times its length rate)
    W_soil' = -s r delta' = s F_soil delta'   (power the soil absorbs)
    W_ext'  = F_ext ydot

so ``E + W_leg + W_soil = E(0) + W_ext`` holds exactly (``E = m ydot^2/2 + m g y``).

Events, in priority order:

1. touchdown (flight): ``y - x_i`` falling; ``s <- 1``, ``delta <- 0``, ``d0dot`` of the contact
   from the impact speed ``-ydot`` when ``d0dot_from_impact = 1``;
2. liftoff (contact): ``delta`` falling; ``s <- 0``, ``delta <- 0``;
3. max_penetration (contact): ``max(delta', delta_max - delta)`` falling, i.e. ``delta`` turns
   back (``delta'`` falls through 0) while above every earlier penetration: ``delta_max <- delta``.
   It fires only when the record is broken (once in the default run, at the first impact); the
   output ``delta_max = max(q.delta_max, delta)`` is the exact running maximum at any time, because
   between records either ``delta`` is below the record or rising above it.
"""
from __future__ import annotations

from .. import fmath
from ..model import (FALLING, Event, HybridModel, Parameter, Variable, require,
                     require_finite, require_nonnegative, require_positive)
from ..plant import DAMPING, F_EXT, FREE_LENGTH, GRAVITY, MASS, STIFFNESS
from ..soil import HuntCrossley

SOIL = HuntCrossley()

I_Y, I_YDOT, I_DELTA, I_TAU, I_WLEG, I_WSOIL, I_WEXT = range(7)

STATES = (
    Variable("y", "m", "height of the mass above the soil surface"),
    Variable("ydot", "m/s", "vertical velocity of the mass"),
    Variable("delta", "m", "penetration of the foot into the soil (positive down; 0 in flight)"),
    Variable("tau", "s", "time since the latest liftoff (flight only; drives the leg's relaxation)"),
    Variable("W_leg", "J", "work absorbed by the leg"),
    Variable("W_soil", "J", "work absorbed by the soil"),
    Variable("W_ext", "J", "work done by F_ext"),
)

OUTPUTS = (
    Variable("y", "m", "height of the mass above the soil surface"),
    Variable("ydot", "m/s", "vertical velocity of the mass"),
    Variable("delta", "m", "penetration of the foot into the soil (positive down; 0 in flight)"),
    Variable("delta_dot", "m/s", "penetration rate of the foot (0 in flight)"),
    Variable("F_soil", "N", "Hunt-Crossley soil force on the foot, positive up (0 in flight); "
             "equals minus the leg force r"),
    Variable("z", "m", "height of the foot: above the surface in flight (y - x_i - leg deflection), "
             "-delta in contact"),
    Variable("s", "", "mode: 0 flight (no contact), 1 contact"),
    Variable("delta_max", "m", "largest penetration so far (exact running maximum)"),
    Variable("d0dot_used", "m/s", "reference velocity of the restitution law in the current (or latest) "
             "contact: d0dot, or the impact speed with d0dot_from_impact = 1"),
    Variable("E", "J", "mechanical energy of the mass, E = m ydot^2/2 + m g y"),
    Variable("W_leg", "J", "work absorbed by the leg, integral of r*(ydot + delta_dot) over contact"),
    Variable("W_soil", "J", "work absorbed by the soil, integral of F_soil*delta_dot over contact"),
    Variable("W_ext", "J", "work done by F_ext on the mass, integral of F_ext*ydot; "
             "E + W_leg + W_soil = E(0) + W_ext"),
)

INPUTS = (F_EXT,)

PARAMETERS = (
    MASS, STIFFNESS, DAMPING, FREE_LENGTH, GRAVITY,
) + SOIL.parameters + (
    Parameter("y_0", 1.5, "m", "initial height of the mass (flight if y_0 > x_i, else contact)"),
    Parameter("ydot_0", 0.0, "m/s", "initial velocity of the mass"),
)

PLOTS = (
    (("y",), ("delta", "delta_max"), ("F_soil",), ("s",)),  # penetration and soil force vs time
    # the Hunt-Crossley hysteresis loop: loading (penetrating) above unloading
    (("vs", "delta", "F_soil", "delta_dot", "loading (delta_dot > 0)", "unloading (delta_dot < 0)"),),
    (("E", "W_leg", "W_soil"),),  # energy book-keeping
)


def _initial_mode(p):
    """``(s, x_lift)`` at t = 0: flight with the leg at its free length when y_0 > x_i; else the
    foot stands on the surface with the leg compressed by x_i - y_0, in contact if the foot is
    pushed into the soil (delta'(0) > 0, or = 0 with delta''(0) >= 0 for F_ext = 0), otherwise in
    flight with that compression relaxing."""
    if p.y_0 > p.x_i:
        return 0, 0.0
    x0 = p.y_0 - p.x_i
    rate = -(p.k / p.c) * x0 - p.ydot_0  # delta'(0) with P = 0
    if rate > 0 or (rate == 0 and p.g - (p.k / p.c) * p.ydot_0 >= 0):
        return 1, 0.0
    return 0, x0


def check(p):
    require_finite(p)
    require_positive(p, "m", "x_i", "y_0")
    require_nonnegative(p, "k")
    require(p.c > 0, "c", p.c, "c > 0 (the leg dashpot sets the rate of the massless foot: "
            "delta' = (...)/(lambda P + c))")
    require(p.g >= 0, "g", p.g, "g >= 0")
    SOIL.check(p)


def time_scales(p):
    """Physical time scales ``(label, parameter names, s)``: the engine refuses one below its
    resolution and names the fastest when a run turns out stiff."""
    out = []
    if p.g > 0:
        out.append(("sqrt(x_i/g) (fall over the leg length)", ("x_i", "g"), fmath.sqrt(p.x_i / p.g)))
    if p.ydot_0 != 0:
        out.append(("x_i/|ydot_0| (leg length at the initial speed)", ("x_i", "ydot_0"), p.x_i / abs(p.ydot_0)))
    if p.k > 0:
        out.append(("sqrt(m/k) (leg spring)", ("m", "k"), fmath.sqrt(p.m / p.k)))
        out.append(("c/k (relaxation of the leg)", ("c", "k"), p.c / p.k))
    # the soil's stiffness at the resting depth delta_s = (m g/K)^(1/n): K_s = n K delta_s^(n-1)
    # (= K for a linear soil); under the leg dashpot the foot relaxes in c/K_s
    if p.K > 0 and (p.n == 1 or p.g > 0):
        K_s = p.K if p.n == 1 else p.n * p.K * (p.m * p.g / p.K) ** ((p.n - 1) / p.n)
        if K_s > 0:
            names = ("c", "K") if p.n == 1 else ("c", "K", "n", "m", "g")
            out.append(("c/K_s (foot in the soil, K_s = n K delta_s^(n-1) at the resting depth "
                        "delta_s = (m g/K)^(1/n))", names, p.c / K_s))
    return tuple(out)


def error_scales(p):
    """Smallest magnitudes of the motion the error control must resolve: the free leg length, the
    leg's static deflection m g/k and the resting depth in the soil (m g/K)^(1/n)."""
    out = [("x_i (free leg length)", ("x_i",), p.x_i)]
    if p.g > 0 and p.k > 0:
        out.append(("m g/k (static leg deflection)", ("m", "g", "k"), p.m * p.g / p.k))
    if p.g > 0 and p.K > 0:
        out.append(("(m g/K)^(1/n) (resting depth in the soil)", ("m", "g", "K", "n"),
                    (p.m * p.g / p.K) ** (1.0 / p.n)))
    return tuple(out)


def initial(p):
    check(p)
    s, x_lift = _initial_mode(p)
    X = [p.y_0, p.ydot_0, 0.0, 0.0, 0.0, 0.0, 0.0]
    q = {"s": s, "d0dot": p.d0dot, "delta_max": 0.0, "x_lift": x_lift}
    return X, q


def bind(q, u, p):
    """The flow for fixed (q, u, p), constants hoisted out of the 7-13 calls per step."""
    F = u[0]
    fa = F / p.m - p.g
    if not q["s"]:
        def flight(t, X):
            ydot = X[1]
            return [ydot, fa, 0.0, 1.0, 0.0, 0.0, F * ydot]
        return flight
    k, c, x_i, inv_m = p.k, p.c, p.x_i, 1.0 / p.m
    rate = SOIL.bind(p, q["d0dot"])[1]

    def contact(t, X):
        y, ydot, d = X[0], X[1], X[2]
        x = y + d - x_i
        dd = rate(-k * x - c * ydot, c, d)
        v = ydot + dd  # leg length rate
        r = k * x + c * v  # leg force (compression < 0) = -F_soil
        return [ydot, fa - r * inv_m, dd, 0.0, r * v, -r * dd, F * ydot]

    return contact


def flow(t, X, q, u, p):
    return bind(q, u, p)(t, X)


def _delta_dot(X, q, p):
    """Penetration rate from the force balance on the massless foot (contact)."""
    x = X[I_Y] + X[I_DELTA] - p.x_i
    return SOIL.rate_of(p, q["d0dot"], -p.k * x - p.c * X[I_YDOT], p.c, X[I_DELTA])


def _flight_leg(X, q, p):
    """Leg deflection in flight: the massless free-ended leg relaxes, k x + c x' = 0, from its
    deflection at liftoff: x = x_lift exp(-(k/c) tau)."""
    x_lift = q["x_lift"]
    return x_lift * fmath.exp(-(p.k / p.c) * X[I_TAU]) if x_lift else 0.0


def _foot_height_flight(X, q, p):
    return X[I_Y] - p.x_i - _flight_leg(X, q, p)


# ---- events ----
def touchdown_jump(X, q, u, p):
    X = list(X)
    X[I_DELTA] = 0.0
    # the soil's impact speed is the foot's: -z' = -(ydot - x') = -ydot - (k/c) x
    impact = -X[I_YDOT] - (p.k / p.c) * _flight_leg(X, q, p)
    return X, dict(q, s=1, d0dot=SOIL.reference_velocity(p, impact))


def liftoff_jump(X, q, u, p):
    X = list(X)
    X[I_DELTA] = 0.0
    X[I_TAU] = 0.0
    return X, dict(q, s=0, x_lift=X[I_Y] - p.x_i)


def peak_guard(X, q, u, p):
    return max(_delta_dot(X, q, p), q["delta_max"] - X[I_DELTA])


def peak_jump(X, q, u, p):
    return list(X), dict(q, delta_max=max(q["delta_max"], X[I_DELTA]))


def _in_contact(q):
    return q["s"] == 1


EVENTS = (
    Event("touchdown", FALLING, lambda X, q, u, p: _foot_height_flight(X, q, p), touchdown_jump,
          lambda q: q["s"] == 0),
    Event("liftoff", FALLING, lambda X, q, u, p: X[I_DELTA], liftoff_jump, _in_contact),
    Event("max_penetration", FALLING, peak_guard, peak_jump, _in_contact),
)


def domain(t, X, q, u, p, slack):
    y, d = X[I_Y], X[I_DELTA]
    if y <= 0:
        return f"mass height y = {y:.6g} m must stay > 0 (the body reached the soil surface)"
    if q["s"]:
        if y + d <= 0:
            return f"leg length y + delta = {y + d:.6g} m must stay > 0 (the leg bottomed out)"
        if d < -1e-6 * p.x_i:
            return (f"penetration delta = {d:.6g} m < 0 in contact: the foot left the soil without a "
                    f"liftoff event")
    return None


def output_fn(t, X, q, u, p):
    y, ydot, d = X[I_Y], X[I_YDOT], X[I_DELTA]
    if q["s"]:
        dd = _delta_dot(X, q, p)
        F_soil = SOIL.force_of(p, q["d0dot"], d, dd)
        d_max = max(q["delta_max"], d)
        z = -d if d > 0.0 else 0.0
    else:
        dd = F_soil = 0.0
        d_max = q["delta_max"]
        z = _foot_height_flight(X, q, p)
    return {
        # the state itself: the engine lands the liftoff on delta = 0 (to ~1e-16 m), so it does
        # not dip below 0 before a liftoff; tests check this on the raw value
        "y": y, "ydot": ydot, "delta": d, "delta_dot": dd, "F_soil": F_soil, "s": q["s"],
        "delta_max": d_max, "d0dot_used": q["d0dot"], "z": z,
        "E": 0.5 * p.m * ydot * ydot + p.m * p.g * y,
        "W_leg": X[I_WLEG], "W_soil": X[I_WSOIL], "W_ext": X[I_WEXT],
    }


MODEL = HybridModel(
    name="Penetrator",
    description="Pogo stick driven into a Hunt-Crossley soil (Pei, Quadrelli & Wright 2020, Sect. 5): "
                "mass on a massless spring-dashpot leg whose massless foot penetrates a compliant soil; "
                "state events located by the internal solver",
    states=STATES, parameters=PARAMETERS, inputs=INPUTS, outputs=OUTPUTS, flow=flow, events=EVENTS,
    initial=initial, output_fn=output_fn, check=check, domain=domain, bind=bind,
    integer_outputs=frozenset({"s"}), plots=PLOTS, time_scales=time_scales, error_scales=error_scales,
)
