"""HopController: a hop-height regulator for the pogo stick (README "HopController.fmu").

A feedback law with no state of its own (zero continuous states): it reads the stick's ``y``,
``ydot`` and mode ``s`` and returns the thrust ``F_ext`` on the mass.

Its one discontinuity in time, the thrust switching on where the leg starts to extend (``ydot``
rising through 0 in contact: from 0 to the law's value, saturated at ``F_max``), is an event
(``extension``) whose guard reads the inputs: an importer that integrates the plant itself (FMI
3.0 model exchange, or a strongly coupled master) stops there as at the plant's own contacts. In
co-simulation the inputs are held over a communication step, so the switch is seen at the
communication points and the event never fires inside a step.

Energy of the hopper as the controller sees it (the leg length is ``y`` in contact, the foot
being on the ground)::

    E_est = m ydot^2/2 + m g y + s * k (y - x_i)^2/2          (mass + spring energy)
    E_T   = m g h_target                                       (energy of an apex at h_target)
    e     = E_T - E_est                                        (energy deficit)

Thrust, only while the leg extends in contact (``s = 1`` and ``ydot > 0``), zero otherwise::

    F_ext = clip( K_D c ydot + e / (tau_E ydot), 0, F_max )

With ``K_D = 1`` the first term cancels the dashpot's loss (``dE_est/dt = (F_ext - c ydot) ydot``
in contact), and the second makes the deficit decay as ``de/dt = -e/tau_E``: the energy at
liftoff, hence the next apex ``E/(m g)`` (flight is conservative), tends to ``E_T``.  The
per-hop return map and the effect of the communication step are analysed in the README.

Sampled (``sample_period > 0``): the law becomes a zero-order hold, evaluated at the instants
``T_s, 2 T_s, ...`` by a periodic time event (``tick``) from the inputs of that instant and held
in between (zero before the first sample), as a digital controller at ``1/T_s`` Hz; ``sample_period = 0`` (the default) is
the continuous law above.

``m``, ``g``, ``k``, ``c``, ``x_i`` are the controller's knowledge of the plant: they carry the
plant's names so that one SSP parameter set (.ssv) sets both components consistently.
"""
from __future__ import annotations

import math

from .. import fmath
from ..plant import DAMPING, FREE_LENGTH, GRAVITY, MASS, STIFFNESS, known_to_controller
from ..model import RISING, Event, HybridModel, Parameter, TimeEvent, Variable, require, require_finite, \
    require_nonnegative, require_positive

PARAMETERS = (
    Parameter("h_target", 1.5, "m", "apex height to regulate (> x_i: the stick must leave the ground)"),
    Parameter("tau_E", 0.02, "s", "time constant of the energy-deficit decay during leg extension (> 0)"),
    Parameter("K_D", 1.0, "", "fraction of the dashpot loss c*ydot fed forward (1: full compensation, 0: none)"),
    Parameter("F_max", 20.0, "N", "largest thrust (the thrust is clipped to [0, F_max])"),
    Parameter("sample_period", 0.0, "s", "period of the law's zero-order hold (a digital controller at "
              "1/sample_period Hz); 0: the continuous law"),
    known_to_controller(MASS), GRAVITY, known_to_controller(STIFFNESS), known_to_controller(DAMPING),
    known_to_controller(FREE_LENGTH),
)

INPUTS = (
    Variable("y", "m", "height of the hopper's mass (from the stick)", 1.5),
    Variable("ydot", "m/s", "vertical velocity of the hopper's mass (from the stick)", 0.0),
    Variable("s", "", "mode of the stick: 1 contact, anything else flight (no thrust)", 0),
)

OUTPUTS = (
    Variable("F_ext", "N", "thrust on the mass, positive up (to the stick's input F_ext)"),
    Variable("E_est", "J", "energy seen by the controller: m ydot^2/2 + m g y + s k (y - x_i)^2/2"),
    Variable("E_err", "J", "energy deficit m g h_target - E_est"),
    Variable("phase", "", "0 flight, 1 compression (no thrust), 2 extension (thrust law active)"),
)


def phase(y, ydot, s):
    if s != 1:
        return 0
    return 2 if ydot > 0.0 else 1


def thrust(y, ydot, s, p):
    """The control law (module docstring): thrust [N] for the stick's outputs (y, ydot, s)."""
    if s != 1 or not ydot > 0.0:
        return 0.0, energy(y, ydot, s, p)
    E = energy(y, ydot, s, p)
    e = p.m * p.g * p.h_target - E
    F = p.K_D * p.c * ydot + e / (p.tau_E * ydot)  # +-inf for a tiny ydot: clipped below
    return min(max(F, 0.0), p.F_max), E


def energy(y, ydot, s, p):
    E = 0.5 * p.m * ydot * ydot + p.m * p.g * y
    if s == 1:
        x = y - p.x_i
        E += 0.5 * p.k * x * x
    return E


def _check(p):
    require_finite(p)
    require_positive(p, "m", "x_i", "tau_E", "F_max")
    require_nonnegative(p, "g", "k", "c", "K_D", "sample_period")
    require(p.h_target > p.x_i, "h_target", p.h_target,
            f"h_target > x_i = {p.x_i!r} (an apex below the free leg length never leaves the ground)")


def _initial(p):
    _check(p)
    return [], {"F_held": 0.0}  # the sampled law's held thrust (sample_period > 0)


def _flow(t, x, q, u, p):
    return []


def _outputs(t, x, q, u, p):
    y, ydot, s = u[0], u[1], fmath.trunc(u[2])
    F, E = thrust(y, ydot, s, p)
    if p.sample_period > 0:
        F = q["F_held"]
    return {"F_ext": F, "E_est": E, "E_err": p.m * p.g * p.h_target - E, "phase": phase(y, ydot, s)}


def _first_tick(p):
    """The sampled law's first instant (one period in; the thrust is zero before it), or never for
    the continuous law."""
    return p.sample_period if p.sample_period > 0 else math.inf


def _tick(x, q, u, p):
    """The zero-order hold: the law at this instant's inputs, held until the next tick."""
    return x, {"F_held": thrust(u[0], u[1], fmath.trunc(u[2]), p)[0]}


def _extension_guard(x, q, u, p):
    """``ydot`` in contact (the thrust law switches on where it rises through 0), 1 in flight (no
    switch: the thrust is 0 whatever ``ydot`` does)."""
    return u[1] if u[2] == 1 else 1.0


def _no_jump(x, q, u, p):
    return x, q  # the law itself switches with its inputs: nothing to reset


EVENTS = (Event("extension", RISING, _extension_guard, _no_jump),
          TimeEvent("tick", at=_first_tick, every=lambda p: p.sample_period, jump=_tick))


def demo_hop(t, p):
    """Inputs of the default experiment: the stick's (y, ydot, s) over repeated hops of the
    controller's own plant model without dashpot and without thrust (an open loop: the thrust
    does not act back), from an apex 10 % of ``h_target - x_i`` below the target, so the law is
    swept over flight, compression and extension with an energy deficit to make up (the thrust
    saturates at ``F_max`` where ``ydot`` is small and falls off as the leg extends faster).

    Flight: the parabola from the apex; contact: the spring-mass oscillation about
    ``x_i - m g/k`` entered at ``y = x_i`` with the touchdown speed, left at ``y = x_i`` with the
    opposite speed (closed form; each hop the same, period ``2 t_fall + T_contact``).
    """
    apex = p.h_target - 0.1 * (p.h_target - p.x_i)
    if not (p.k > 0 and p.g > 0 and apex > p.x_i):
        return {"y": apex, "ydot": 0.0, "s": 0}  # no hop without a spring and gravity: rest at the apex
    t_fall = math.sqrt(2.0 * (apex - p.x_i) / p.g)
    v_td = p.g * t_fall
    w = math.sqrt(p.k / p.m)
    sag = p.m * p.g / p.k  # static deflection
    phi = math.atan2(v_td / w, sag)
    amp = math.hypot(sag, v_td / w)
    t_contact = (2.0 * math.pi - 2.0 * phi) / w
    tau = math.fmod(t, 2.0 * t_fall + t_contact)
    if tau < t_fall:  # falling from the apex
        return {"y": apex - 0.5 * p.g * tau * tau, "ydot": -p.g * tau, "s": 0}
    tau -= t_fall
    if tau < t_contact:  # leg on the ground
        return {"y": p.x_i - sag + amp * math.cos(w * tau + phi), "ydot": -amp * w * math.sin(w * tau + phi), "s": 1}
    tau -= t_contact  # rising to the next apex
    return {"y": p.x_i + v_td * tau - 0.5 * p.g * tau * tau, "ydot": v_td - p.g * tau, "s": 0}


MODEL = HybridModel(
    name="HopController",
    description="Hop-height regulator for the pogo stick: thrust during leg extension that drives the "
                "hopper's energy to m g h_target (dashpot feed-forward + energy-deficit feedback)",
    states=(),
    parameters=PARAMETERS,
    inputs=INPUTS,
    outputs=OUTPUTS,
    flow=_flow,
    events=EVENTS,
    initial=_initial,
    output_fn=_outputs,
    check=_check,
    integer_inputs=frozenset({"s"}),
    integer_outputs=frozenset({"phase"}),
    # the law swept over the hops of demo_hop: the inputs it sees, the thrust and energies it returns
    plots=((("y",), ("ydot",), ("s", "phase"), ("F_ext",)),),  # (E_est is constant: a lossless hop)
    default_input=demo_hop,
    # a feedback law: every output is a function of the inputs at the same instant
    feedthrough={"F_ext": ("y", "ydot", "s"), "E_est": ("y", "ydot", "s"), "E_err": ("y", "ydot", "s"),
                 "phase": ("ydot", "s")},
    default_stop_time=2.0,
    default_step=1e-3,
)
