"""A bouncing ball: free fall, and a bounce with restitution e at the floor."""
from pogofmu import FALLING, Event, HybridModel, Parameter, Variable, require, require_nonnegative, require_positive

h, v = Variable("h", "m", "height above the floor"), Variable("v", "m/s", "velocity (up)")


def check(p):
    require_positive(p, "g")      # the floor is below: a ball started under it, or pulled up, never meets it
    require_nonnegative(p, "h_0")
    require(0 <= p.e < 1, "e", p.e, "0 <= e < 1")


MODEL = HybridModel(
    name="Ball",
    description="bouncing ball",
    states=(h, v),
    parameters=(Parameter("g", 9.81, "m/s2", "gravitational acceleration"),
                Parameter("e", 0.8, "", "coefficient of restitution"),
                Parameter("h_0", 1.0, "m", "initial height")),
    inputs=(),
    outputs=(h, v),
    flow=lambda t, x, q, u, p: [x[1], -p.g],
    events=(Event("bounce", FALLING, guard=lambda x, q, u, p: x[0],
                  jump=lambda x, q, u, p: ([0.0, -p.e * x[1]], q)),),
    initial=lambda p: ([p.h_0, 0.0], {}),
    output_fn=lambda t, x, q, u, p: {"h": x[0], "v": x[1]},
    check=check,
    default_stop_time=3.0,
)
