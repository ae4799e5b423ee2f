"""An array input and array outputs (FMI 3.0 arrays, FMI 2.0 scalars z[1] ... z[3]): a gain with a
bias and an integrator, whose closed form the tests compare with.

    r[i] = g z[i] + w i              (direct feed-through from z and w)
    y'   = (z[1] + 2 z[2] + 3 z[3]) / tau    (so y(t) = y_0 + t (z[1] + 2 z[2] + 3 z[3]) / tau for constant inputs)
    s    = [y, 2 y]
"""
from pogofmu import HybridModel, Parameter, Variable, require_positive

N = 3

y = Variable("y", "m", "integral of the weighted inputs over tau")

MODEL = HybridModel(
    name="ArrayGain",
    description="array inputs and outputs: a gain with a bias, and an integrator",
    states=(y,),
    parameters=(Parameter("g", 2.0, "", "gain"),
                Parameter("y_0", 0.5, "m", "initial value of y"),
                Parameter("tau", 1.0, "s", "time constant of the integrator")),
    inputs=(Variable("z", "m", "the signals", shape=(N,)),
            Variable("w", "m", "the bias per index")),
    outputs=(Variable("r", "m", "gain and bias of each signal", shape=(N,)),
             y,
             Variable("s", "m", "y and twice y", shape=(2,))),
    flow=lambda t, x, q, u, p: [(u[0] + 2.0 * u[1] + 3.0 * u[2]) / p.tau],
    events=(),
    initial=lambda p: ([p.y_0], {}),
    output_fn=lambda t, x, q, u, p: {"r": [p.g * u[i] + u[N] * (i + 1) for i in range(N)], "y": x[0],
                                     "s": [x[0], 2.0 * x[0]]},
    feedthrough={"r": ("z", "w")},
    check=lambda p: require_positive(p, "tau"),
    default_stop_time=1.0,
    default_step=0.01,
)
