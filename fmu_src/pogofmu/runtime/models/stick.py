"""The pogo-stick family (docs/models.md, the stick family): a mass on a massless leg of parallel elements.

Continuous states ``[xbar, xdot, y, ydot, z, <element states...>, W_leg, W_ext]``:
leg length, leg length rate, mass height, mass velocity, foot height, the elements' own states
(e.g. absement ``a``), and two work quadratures (``W_leg = int r xdot dt`` over contact,
``W_ext = int F_ext ydot dt``) that make the energy balance ``E + W_leg = E(0) + W_ext`` checkable.
Discrete state ``q``: the mode ``s`` (0 flight, 1 contact) and the elements' memories.

Flow (paper Eq. 43/45 with the input ``F_ext`` added)::

    xbar' = xdot
    xdot' = s (-r/m - g + F_ext/m)
    y'    = ydot
    ydot' = (1-s)(-g + F_ext/m) + s(-r/m - g + F_ext/m)
    z'    = (1-s)(ydot - xdot)

Events, in priority order: touchdown (``z`` falling, in flight), liftoff (``xbar - x_i`` rising, in
contact, when every element allows it), then the elements' own events in leg order.
"""
from __future__ import annotations

from typing import Sequence

from ..elements import Element
from ..plant import F_EXT, FREE_LENGTH, GRAVITY, MASS
from ..model import (FALLING, RISING, Event, HybridModel, Parameter, ParameterError, Variable, require,
                     require_finite, require_positive)

N_BASE = 5  # xbar, xdot, y, ydot, z

BASE_STATES = (
    Variable("xbar", "m", "leg length"),
    Variable("xdot", "m/s", "leg length rate"),
    Variable("y", "m", "height of the mass above the ground"),
    Variable("ydot", "m/s", "vertical velocity of the mass"),
    Variable("z", "m", "height of the foot above the ground (z = y - xbar)"),
)

BASE_OUTPUTS = BASE_STATES + (
    Variable("x", "m", "leg deflection x = xbar - x_i (<= 0: the spring never extends)"),
    Variable("r", "N", "restoring force of the leg (0 in flight)"),
    Variable("s", "", "mode: 0 flight (no contact), 1 contact"),
    Variable("E", "J", "mechanical energy of the mass, E = m ydot^2/2 + m g y"),
    Variable("W_leg", "J", "work absorbed by the leg, integral of r*xdot over contact"),
    Variable("W_ext", "J", "work done by F_ext on the mass, integral of F_ext*ydot"),
)

INTEGER_OUTPUTS = frozenset({"s"})

INPUTS = (F_EXT,)


def _head_parameters(leg):
    return (MASS,) + tuple(
        par for el in leg for par in el.parameters if not par.name.endswith("_0"))


def _tail_parameters(leg):
    return (
        FREE_LENGTH,
        GRAVITY,
        Parameter("xbar_0", 1.0, "m", "initial leg length"),
        Parameter("xdot_0", 0.0, "m/s", "initial leg length rate"),
        Parameter("y_0", 1.5, "m", "initial height of the mass"),
        Parameter("ydot_0", 0.0, "m/s", "initial velocity of the mass"),
        Parameter("z_0", 0.5, "m", "initial height of the foot; must equal y_0 - xbar_0"),
    ) + tuple(par for el in leg for par in el.parameters if par.name.endswith("_0"))


DEFAULT_PLOTS = (
    (("y", "z", "xbar"), ("s",)),  # time histories, like the paper's Fig. 23
    (("E", "W_leg"),),  # energy book-keeping
)


def make_stick_model(name: str, description: str, leg: Sequence[Element], plots=DEFAULT_PLOTS) -> HybridModel:
    """Build the hybrid model of a pogo stick whose leg is the parallel composition ``leg``."""
    leg = tuple(leg)
    slices = []
    n = N_BASE
    for el in leg:
        slices.append(slice(n, n + len(el.states)))
        n += len(el.states)
    I_WLEG, I_WEXT = n, n + 1
    states = BASE_STATES + tuple(v for el in leg for v in el.states) + (
        Variable("W_leg", "J", "work absorbed by the leg"), Variable("W_ext", "J", "work done by F_ext"))
    parameters = _head_parameters(leg) + _tail_parameters(leg)
    names = [par.name for par in parameters]
    if len(set(names)) != len(names):
        raise ValueError(f"duplicate parameter names in leg of {name}: {names}")
    outputs = BASE_OUTPUTS + tuple(v for el in leg for v in el.outputs)
    parts = tuple(zip(leg, slices))

    # built once: each element's force (with the slice of its own states, None if it has none)
    # and, for elements with states, their rates
    forces = tuple((el.force, sl if sl.start != sl.stop else None) for el, sl in parts)
    rates = tuple((el.rates, sl) for el, sl in parts if sl.start != sl.stop)

    def leg_force(x, xdot, X, q, p):
        r = 0.0
        for force, sl in forces:
            r += force(x, xdot, () if sl is None else X[sl], q, p)
        return r

    def flow(t, X, q, u, p):
        return bind(q, u, p)(t, X)

    def bind(q, u, p):
        """The flow for fixed (q, u, p) as a closure over local constants: the engine calls it
        7-13 times per step, so attribute and dict lookups are hoisted out of it."""
        F, m, g, x_i = u[0], p.m, p.g, p.x_i
        fa = F / m - g
        if not q["s"]:
            def flight(t, X):
                xdot, ydot = X[1], X[3]
                dX = [xdot, 0.0, ydot, fa, ydot - xdot]
                for rate, sl in rates:
                    dX.extend(rate(X[0] - x_i, xdot, X[sl], q, p))
                dX.append(0.0)
                dX.append(F * ydot)
                return dX
            return flight
        inv_m = 1.0 / m

        def contact(t, X):
            xdot, ydot = X[1], X[3]
            x = X[0] - x_i
            r = 0.0
            for force, sl in forces:  # leg_force inlined: this is the hot loop
                r += force(x, xdot, () if sl is None else X[sl], q, p)
            acc = fa - r * inv_m
            dX = [xdot, acc, ydot, acc, 0.0]
            for rate, sl in rates:
                dX.extend(rate(x, xdot, X[sl], q, p))
            dX.append(r * xdot)
            dX.append(F * ydot)
            return dX
        return contact

    # ---- events ----
    def touchdown_jump(X, q, u, p):
        X = list(X)
        X[1] = X[3]  # xdot <- ydot
        X[4] = 0.0  # z <- 0
        q = dict(q, s=1)
        return X, q

    def liftoff_jump(X, q, u, p):
        X = list(X)
        X[0] = p.x_i  # xbar <- x_i
        X[1] = 0.0  # xdot <- 0
        X[4] = 0.0  # z <- 0
        return X, dict(q, s=0)

    def liftoff_active(q):
        return q["s"] == 1 and all(el.liftoff_allowed(q) for el in leg)

    events = [
        Event("touchdown", FALLING, lambda X, q, u, p: X[4], touchdown_jump, lambda q: q["s"] == 0),
        Event("liftoff", RISING, lambda X, q, u, p: X[0] - p.x_i, liftoff_jump, liftoff_active),
    ]
    for el, sl in parts:
        for lev in el.events:
            events.append(_wrap_leg_event(lev, sl))

    # ---- initial state, checks, domain ----
    def check(p):
        require_finite(p)
        require_positive(p, "m", "x_i", "xbar_0", "y_0")
        require(p.g >= 0, "g", p.g, "g >= 0")
        for el in leg:
            el.check(p)
        tol = 1e-12 * max(1.0, abs(p.y_0), abs(p.xbar_0))
        if abs(p.z_0 - (p.y_0 - p.xbar_0)) > tol:
            raise ParameterError(
                f"parameter z_0 = {p.z_0!r} violates the rule: z_0 = y_0 - xbar_0 "
                f"(= {p.y_0 - p.xbar_0!r} with y_0 = {p.y_0!r}, xbar_0 = {p.xbar_0!r})")
        require(p.z_0 >= 0, "z_0", p.z_0, "z_0 >= 0 (the foot cannot start below the ground)")
        require(p.xbar_0 <= p.x_i, "xbar_0", p.xbar_0, f"xbar_0 <= x_i = {p.x_i!r} (the spring never extends)")
        if p.z_0 > 0:
            require(p.xbar_0 == p.x_i, "xbar_0", p.xbar_0,
                    f"in flight (z_0 > 0) the massless leg is at its free length: xbar_0 = x_i = {p.x_i!r}")
            require(p.xdot_0 == 0, "xdot_0", p.xdot_0, "in flight (z_0 > 0) the leg does not move: xdot_0 = 0")
        else:
            require(p.xdot_0 == p.ydot_0, "xdot_0", p.xdot_0,
                    f"in contact (z_0 = 0) the foot rests on the ground: xdot_0 = ydot_0 = {p.ydot_0!r}")

    def initial(p):
        check(p)
        X = [p.xbar_0, p.xdot_0, p.y_0, p.ydot_0, p.z_0]
        q = {"s": 0 if p.z_0 > 0 else 1}
        for el in leg:
            X.extend(el.initial_states(p))
            q.update(el.discrete)
        X += [0.0, 0.0]  # W_leg, W_ext
        return X, q

    def domain(t, X, q, u, p, slack):
        xbar, y, z = X[0], X[2], X[4]
        if xbar <= 0:
            return f"leg length xbar = {xbar:.6g} m must stay > 0 (the leg bottomed out)"
        if y <= 0:
            return f"mass height y = {y:.6g} m must stay > 0"
        if y <= z:
            return f"y = {y:.6g} m must stay above the foot z = {z:.6g} m"
        if xbar - p.x_i > slack(p.x_i):
            return f"leg deflection x = {xbar - p.x_i:.6g} m must stay <= 0 (the spring never extends)"
        return None

    def time_scales(p):
        out = []
        if p.g > 0:
            out.append(("sqrt(x_i/g) (fall over the leg length)", ("x_i", "g"), (p.x_i / p.g) ** 0.5))
        if p.ydot_0 != 0:
            out.append(("x_i/|ydot_0| (leg length at the initial speed)", ("x_i", "ydot_0"), p.x_i / abs(p.ydot_0)))
        for el in leg:
            out.extend(el.time_scales(p))
        return tuple(out)

    def error_scales(p):
        out = [("x_i (free leg length)", ("x_i",), p.x_i)]
        for el in leg:
            out.extend(el.error_scales(p))
        return tuple(out)

    reporting = tuple((el, sl, tuple(v.name for v in el.outputs)) for el, sl in parts if el.outputs)

    def output_fn(t, X, q, u, p):
        xbar, xdot, y, ydot, z = X[0], X[1], X[2], X[3], X[4]
        x = xbar - p.x_i
        r = leg_force(x, xdot, X, q, p) if q["s"] else 0.0
        out = {
            "xbar": xbar, "xdot": xdot, "y": y, "ydot": ydot, "z": z, "x": x, "r": r, "s": q["s"],
            "E": 0.5 * p.m * ydot * ydot + p.m * p.g * y, "W_leg": X[I_WLEG], "W_ext": X[I_WEXT],
        }
        for el, sl, names in reporting:
            out.update(zip(names, el.output_values(x, xdot, X[sl], q, p)))
        return out

    return HybridModel(
        name=name, description=description, states=states, parameters=parameters, inputs=INPUTS,
        outputs=outputs, flow=flow, events=tuple(events), initial=initial, output_fn=output_fn,
        check=check, domain=domain, bind=bind, plots=plots, time_scales=time_scales, error_scales=error_scales,
        integer_outputs=INTEGER_OUTPUTS | frozenset(
            v.name for el in leg for v in el.outputs if getattr(el, "integer_outputs", None)
            and v.name in el.integer_outputs))


def _wrap_leg_event(lev, sl):
    def guard(X, q, u, p):
        return lev.guard(X[0] - p.x_i, X[1], X[sl], q, p)

    def jump(X, q, u, p):
        xi, q_new = lev.jump(X[0] - p.x_i, X[1], X[sl], q, p)
        X = list(X)
        X[sl] = xi
        return X, q_new

    return Event(lev.name, lev.direction, guard, jump, lambda q: q["s"] == 1 and lev.active(q))
