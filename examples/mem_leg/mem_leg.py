"""A hopping mass on a leg with a mem-spring (pogofmu.elements.MemSpring): flight and contact.

The leg is massless and vertical with free length x_i; in contact its deflection is x = y - x_i
(<= 0) and its restoring force r = k(a) x, where the absement a (a' = x in contact) is the
mem-spring's memory: a softening law k(a) = k / (1 + beta |a|) makes each landing softer.
"""
from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable, require_positive
from pogofmu.elements import MemSpring

SPRING = MemSpring()  # parameters k, spring_law, beta, a_0


def flow(t, x, q, u, p):
    y, ydot, a = x
    if q["s"] == 1:
        deflection = y - p.x_i
        r = SPRING.force(deflection, ydot, (a,), q, p)
        return [ydot, -r / p.m - p.g, deflection]
    return [ydot, -p.g, 0.0]


def check(p):
    require_positive(p, "m", "g", "x_i")
    SPRING.check(p)


MODEL = HybridModel(
    name="MemLeg",
    description="a mass hopping on a massless leg whose spring is a mem-spring (softening with absement)",
    states=(Variable("y", "m", "height of the mass"), Variable("ydot", "m/s", "velocity of the mass"),
            Variable("a", "m.s", "absement of the leg (memory of the mem-spring)")),
    parameters=(Parameter("m", 1.0, "kg", "mass"), Parameter("g", 9.81, "m/s2", "gravity"),
                Parameter("x_i", 1.0, "m", "free length of the leg"),
                Parameter("y_0", 1.5, "m", "initial height of the mass")) + SPRING.parameters,
    inputs=(),
    outputs=(Variable("y", "m", "height of the mass"), Variable("r", "N", "force of the leg"),
             Variable("s", "", "mode: 0 flight, 1 contact")),
    flow=flow,
    events=(
        Event("touchdown", FALLING, guard=lambda x, q, u, p: x[0] - p.x_i, jump=lambda x, q, u, p: (x, {"s": 1}),
              active=lambda q: q["s"] == 0),
        Event("liftoff", RISING, guard=lambda x, q, u, p: x[0] - p.x_i, jump=lambda x, q, u, p: (x, {"s": 0}),
              active=lambda q: q["s"] == 1),
    ),
    initial=lambda p: ([p.y_0, 0.0, p.a_0], {"s": 0}),
    output_fn=lambda t, x, q, u, p: {
        "y": x[0], "s": q["s"],
        "r": SPRING.force(x[0] - p.x_i, x[1], (x[2],), q, p) if q["s"] == 1 else 0.0},
    check=check,
    integer_outputs=frozenset({"s"}),
    plots=((("y",), ("r",), ("s",)),),
    default_stop_time=5.0,
)
