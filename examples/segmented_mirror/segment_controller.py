"""The local position loop of one actuator: a PID on the piston with force saturation and
back-calculation anti-windup (docs/segmented-mirror.md).

    e   = r - z                                  command r (from the reconstructor), piston z
    F_u = K_p e + K_i I - K_d (z - w)/T_f        derivative of the filtered piston w
    F   = clip(F_u, -F_max, F_max)
    I'  = e + (F - F_u)/(K_i T_t)                back-calculation: winds back while saturated
    w'  = (z - w)/T_f

The right-hand side is continuous; its kinks, where F_u crosses +-F_max, are events (entering
and leaving saturation), so model exchange stops there and the saturated output ``sat`` is exact.
"""
from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable, require, require_finite, \
    require_positive


def unsaturated(x, u, p):
    """The PID's force before the clip (N)."""
    I, w = x
    r, z = u
    return p.K_p * (r - z) + p.K_i * I - p.K_d * (z - w) / p.T_f


def saturated(F_u, p):
    return min(max(F_u, -p.F_max), p.F_max)


def flow(t, x, q, u, p):
    F_u = unsaturated(x, u, p)
    r, z = u
    return [(r - z) + (saturated(F_u, p) - F_u) / (p.K_i * p.T_t), (z - x[1]) / p.T_f]


def outputs(t, x, q, u, p):
    F_u = unsaturated(x, u, p)
    sat = 1 if F_u > p.F_max else (-1 if F_u < -p.F_max else 0)
    return {"F": saturated(F_u, p), "F_u": F_u, "sat": sat}


def check(p):
    require_finite(p)
    require_positive(p, "K_p", "K_i", "K_d", "T_f", "T_t", "F_max")
    require(p.locate_saturation in (0, 1), "locate_saturation", p.locate_saturation, "locate_saturation is 0 or 1")


def no_jump(x, q, u, p):
    return x, q  # the clip switches with the state and the inputs: nothing to reset


def upper(x, q, u, p):
    """The upper kink of the clip; a constant 1 when its location is not asked for."""
    return unsaturated(x, u, p) - p.F_max if p.locate_saturation == 1 else 1.0


def lower(x, q, u, p):
    return unsaturated(x, u, p) + p.F_max if p.locate_saturation == 1 else 1.0


MODEL = HybridModel(
    name="SegmentController",
    description="PID position loop of a segment actuator with force saturation +-F_max and back-calculation "
                "anti-windup; entering and leaving saturation are events",
    states=(Variable("I", "m.s", "integral of the position error"),
            Variable("w", "m", "piston filtered by T_f (the derivative acts on it)")),
    parameters=(
        Parameter("K_p", 3.3e5, "N/m", "proportional gain"),
        Parameter("K_i", 4.0e6, "N/(m.s)", "integral gain"),
        Parameter("K_d", 7.0e3, "N.s/m", "derivative gain (on the measured piston)"),
        Parameter("T_f", 1.0e-3, "s", "time constant of the derivative's filter"),
        Parameter("T_t", 0.04, "s", "tracking time constant of the anti-windup"),
        Parameter("F_max", 25.0, "N", "largest force of the voice coil"),
        Parameter("locate_saturation", 1, "", "1: entering and leaving saturation are events; 0: they are "
                  "not located (a co-simulation whose master would stop the whole system at each kink)",
                  integer=True),
        Parameter("I_0", 0.0, "m.s", "initial integral"),
        Parameter("z_0", 0.0, "m", "initial filtered piston (the actuator's initial piston)"),
    ),
    inputs=(Variable("r", "m", "piston command", 0.0), Variable("z", "m", "measured piston", 0.0)),
    outputs=(Variable("F", "N", "voice-coil force command, clipped to +-F_max"),
             Variable("F_u", "N", "PID force before the clip"),
             Variable("sat", "", "0 linear, 1 saturated at +F_max, -1 at -F_max")),
    flow=flow,
    events=(
        Event("saturate_high", RISING, guard=upper, jump=no_jump),
        Event("leave_high", FALLING, guard=upper, jump=no_jump),
        Event("saturate_low", FALLING, guard=lower, jump=no_jump),
        Event("leave_low", RISING, guard=lower, jump=no_jump),
    ),
    initial=lambda p: ([p.I_0, p.z_0], {}),
    output_fn=outputs,
    check=check,
    integer_outputs=frozenset({"sat"}),
    feedthrough={"F": ("r", "z"), "F_u": ("r", "z"), "sat": ("r", "z")},
    default_input=lambda t, p: {"r": 5e-4 if t > 0.01 else 0.0, "z": 0.0},
    plots=((("F", "F_u"), ("sat",)),),
    default_stop_time=0.1,
    default_step=1e-4,
)
