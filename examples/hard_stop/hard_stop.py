"""A force-driven oscillator against a stiff hard stop.

A mass on a spring and a dashpot, driven by the input force F, with a hard stop at z = z_s: a
Hunt-Crossley contact (the Penetrator's soil law, from pogofmu.elements) of stiffness K = 1e7 N/m.
Two modes, two state events: `contact` when z reaches z_s, `release` when it comes back.
"""
import math

from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable, require_positive
from pogofmu.elements import HuntCrossley

STOP = HuntCrossley()  # its parameters K, n, c_r, d0dot, d0dot_from_impact are this model's too


def stop_force(x, q, p):
    """The stop's force on the mass (N, pushing it back), 0 off the stop."""
    if q["s"] == 1:
        return STOP.force_of(p, p.d0dot, x[0] - p.z_s, x[1])
    return 0.0


def flow(t, x, q, u, p):
    return [x[1], (u[0] - p.k * x[0] - p.c * x[1] - stop_force(x, q, p)) / p.m]


def check(p):
    require_positive(p, "m", "k", "z_s")
    STOP.check(p)


MODEL = HybridModel(
    name="HardStop",
    description="force-driven mass-spring-damper against a stiff Hunt-Crossley hard stop at z = z_s",
    states=(Variable("z", "m", "position of the mass"), Variable("zdot", "m/s", "velocity of the mass")),
    parameters=(
        Parameter("m", 1.0, "kg", "mass"),
        Parameter("k", 100.0, "N/m", "spring stiffness"),
        Parameter("c", 0.5, "N.s/m", "damping coefficient"),
        Parameter("z_s", 0.1, "m", "position of the hard stop"),
        Parameter("K", 1.0e7, "N/m^n", "stiffness of the stop (Hunt-Crossley)"),
        Parameter("n", 1.0, "", "Hunt-Crossley exponent of the stop (>= 1)"),
        Parameter("c_r", 0.8, "", "coefficient of restitution of the stop at d0dot"),
        Parameter("d0dot", 1.0, "m/s", "reference impact velocity of the stop's damping"),
        Parameter("d0dot_from_impact", 0, "", "1: reference velocity from each impact (not used here)",
                  integer=True),
        Parameter("z_0", 0.0, "m", "initial position"),
        Parameter("F0", 20.0, "N", "amplitude of the default experiment's drive"),
        Parameter("f", 1.5, "Hz", "frequency of the default experiment's drive"),
    ),
    inputs=(Variable("F", "N", "driving force on the mass (start: a push of 30 N into the stop)", 30.0),),
    outputs=(Variable("z", "m", "position of the mass"), Variable("zdot", "m/s", "velocity of the mass"),
             Variable("F_stop", "N", "force of the hard stop on the mass"),
             Variable("s", "", "mode: 0 free, 1 on the stop")),
    flow=flow,
    events=(
        Event("contact", RISING, guard=lambda x, q, u, p: x[0] - p.z_s, jump=lambda x, q, u, p: (x, {"s": 1}),
              active=lambda q: q["s"] == 0),
        Event("release", FALLING, guard=lambda x, q, u, p: x[0] - p.z_s, jump=lambda x, q, u, p: (x, {"s": 0}),
              active=lambda q: q["s"] == 1),
    ),
    initial=lambda p: ([p.z_0, 0.0], {"s": 0}),
    output_fn=lambda t, x, q, u, p: {"z": x[0], "zdot": x[1], "F_stop": stop_force(x, q, p), "s": q["s"]},
    check=check,
    integer_outputs=frozenset({"s"}),
    default_input=lambda t, p: {"F": p.F0 * math.sin(2 * math.pi * p.f * t)},  # (host side: any Python)
    plots=((("z",), ("F_stop",), ("s",)),),
    default_stop_time=4.0,
)
