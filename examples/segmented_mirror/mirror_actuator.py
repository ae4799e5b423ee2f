"""One actuator of a segmented mirror: the segment's share of mass on a soft flexure, driven by a
voice coil, with a mem-spring in parallel and hard stops at +-z_s (docs/segmented-mirror.md).

    m z'' = F + F_w(t) - k z - c z' - k_m(a) z + F_stop,      a' = z

* ``F`` the voice-coil force (input), ``F_w`` a deterministic 1 - cos gust of amplitude ``A_w``
  from ``t_g`` lasting ``T_g``;
* the flexure ``k``, ``c`` and, in parallel, a mem-spring (pogofmu.elements.MemSpring, softening:
  k_m(a) = k_m / (1 + beta |a|)) whose absement ``a`` is the memory: its force-piston loop is
  the pinched hysteresis of a mem-element;
* two stops, stiff Hunt-Crossley contacts (pogofmu.elements.HuntCrossley, the Penetrator's soil
  law) at z = +z_s and z = -z_s.  Modes: 0 free, 1 on the upper stop, -1 on the lower stop; each
  contact and each release is a state event.
"""
import math

from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable, fmath, require, \
    require_nonnegative, require_positive
from pogofmu.elements import SPRING_LAWS, HuntCrossley, MemSpring

STOP = HuntCrossley()  # K, n, c_r, d0dot, d0dot_from_impact: both stops' law
MEM = MemSpring()      # its k is this model's k_m (the flexure has the name k): see MemView

FREE, UPPER, LOWER = 0, 1, -1


class MemView:
    """The parameters as the mem-spring reads them: its ``k`` is the actuator's ``k_m``."""

    def __init__(self, p):
        self.k, self.spring_law, self.beta = p.k_m, p.spring_law, p.beta

    def __getitem__(self, name):
        return getattr(self, name)


def gust(t, p):
    """The wind force on the segment's share (N, positive up): A_w (1 - cos(2 pi (t - t_g)/T_g))/2
    for t_g < t < t_g + T_g, 0 otherwise (continuous with its slope at both ends)."""
    if t <= p.t_g or t >= p.t_g + p.T_g:
        return 0.0
    return 0.5 * p.A_w * (1.0 - fmath.cos(2.0 * math.pi * (t - p.t_g) / p.T_g))


def stop_force(x, q, p):
    """The stops' force on the mass (N, positive up); 0 off the stops."""
    if q["mode"] == UPPER:
        return -STOP.force_of(p, p.d0dot, x[0] - p.z_s, x[1])
    if q["mode"] == LOWER:
        return STOP.force_of(p, p.d0dot, -p.z_s - x[0], -x[1])
    return 0.0


def flow(t, x, q, u, p):
    z, zdot, a = x
    r_mem = MEM.force(z, zdot, (a,), q, MemView(p))
    zddot = (u[0] + gust(t, p) - p.k * z - p.c * zdot - r_mem + stop_force(x, q, p)) / p.m
    return [zdot, zddot, z]


def check(p):
    require_positive(p, "m", "k", "z_s", "T_g")
    require_nonnegative(p, "c", "k_m", "beta", "t_g")
    require(p.spring_law in tuple(SPRING_LAWS), "spring_law", p.spring_law,
            "spring_law is 0 (linear), 1 (softening) or 2 (hardening)")
    STOP.check(p)
    require(p.d0dot_from_impact == 0, "d0dot_from_impact", p.d0dot_from_impact,
            "d0dot_from_impact = 0 (the stops use the reference velocity d0dot)")


def initial(p):
    require(-p.z_s < p.z_0 < p.z_s, "z_0", p.z_0, "-z_s < z_0 < z_s (the actuator starts off its stops)")
    return [p.z_0, 0.0, p.a_0], {"mode": FREE}


def to(mode):
    return lambda x, q, u, p: (x, {"mode": mode})


MODEL = HybridModel(
    name="MirrorActuator",
    description="segment actuator: mass on a soft flexure with a mem-spring in parallel, voice coil force F, "
                "a deterministic gust, and stiff Hunt-Crossley stops at +-z_s",
    states=(Variable("z", "m", "piston of the segment at this actuator"),
            Variable("zdot", "m/s", "piston rate"),
            Variable("a", "m.s", "absement of the mem-spring, a' = z (its memory)")),
    parameters=(
        Parameter("m", 83.0, "kg", "the segment's share of mass (250 kg on 3 actuators)"),
        Parameter("k", 1.2e4, "N/m", "stiffness of the flexure"),
        Parameter("c", 50.0, "N.s/m", "damping of the flexure"),
        Parameter("k_m", 2.0e3, "N/m", "stiffness of the mem-spring at zero absement"),
        Parameter("spring_law", 1, "", "mem-spring law: 0 linear k_m, 1 softening k_m/(1+beta|a|), "
                  "2 hardening k_m(1+beta|a|)", integer=True),
        Parameter("beta", 200.0, "1/(m.s)", "memory coefficient of the mem-spring (0: a linear spring)"),
        Parameter("a_0", 0.0, "m.s", "initial absement"),
        Parameter("z_s", 2.0e-3, "m", "position of the hard stops, at +z_s and -z_s"),
        Parameter("K", 1.0e8, "N/m^n", "stiffness of the stops (Hunt-Crossley)"),
        Parameter("n", 1.0, "", "Hunt-Crossley exponent of the stops (>= 1)"),
        Parameter("c_r", 0.5, "", "coefficient of restitution of the stops at d0dot"),
        Parameter("d0dot", 0.01, "m/s", "reference impact velocity of the stops' damping"),
        Parameter("d0dot_from_impact", 0, "", "must be 0: the stops use d0dot", integer=True),
        Parameter("z_0", 0.0, "m", "initial piston (at rest)"),
        Parameter("A_w", 60.0, "N", "amplitude of the gust's force (positive up)"),
        Parameter("t_g", 0.1, "s", "start of the gust"),
        Parameter("T_g", 0.5, "s", "duration of the gust"),
    ),
    inputs=(Variable("F", "N", "voice-coil force (positive up)", 0.0),),
    outputs=(Variable("z", "m", "piston of the segment at this actuator"),
             Variable("zdot", "m/s", "piston rate"),
             Variable("F_stop", "N", "force of the stops on the mass (positive up)"),
             Variable("mode", "", "0 free, 1 on the upper stop, -1 on the lower stop"),
             Variable("F_w", "N", "force of the gust")),
    flow=flow,
    events=(
        Event("upper_contact", RISING, guard=lambda x, q, u, p: x[0] - p.z_s, jump=to(UPPER),
              active=lambda q: q["mode"] == FREE),
        Event("upper_release", FALLING, guard=lambda x, q, u, p: x[0] - p.z_s, jump=to(FREE),
              active=lambda q: q["mode"] == UPPER),
        Event("lower_contact", FALLING, guard=lambda x, q, u, p: x[0] + p.z_s, jump=to(LOWER),
              active=lambda q: q["mode"] == FREE),
        Event("lower_release", RISING, guard=lambda x, q, u, p: x[0] + p.z_s, jump=to(FREE),
              active=lambda q: q["mode"] == LOWER),
    ),
    initial=initial,
    output_fn=lambda t, x, q, u, p: {"z": x[0], "zdot": x[1], "F_stop": stop_force(x, q, p), "mode": q["mode"],
                                     "F_w": gust(t, p)},
    check=check,
    integer_outputs=frozenset({"mode"}),
    default_input=lambda t, p: {"F": 0.0},
    plots=((("z",), ("F_stop", "F_w"), ("mode",)),),
    default_stop_time=1.0,
    default_step=1e-3,
)
