"""Hypothesis strategies of valid parameter sets of the project's models (shared by the property
suite and the native engine's tests)."""
import math

from hypothesis import assume
from hypothesis import strategies as st

STOP = 2.0  # s: the property suite's runs (the mem-spring's absement grows at most x_i per second)


def logf(lo, hi):
    """Log-uniform floats in [lo, hi]."""
    return st.floats(math.log10(lo), math.log10(hi)).map(lambda e: 10.0 ** e)


SOLVER = st.fixed_dictionaries({
    "method": st.sampled_from([5, 8]),
    "rel_tol": logf(1e-10, 1e-4),
    "abs_tol": logf(1e-14, 1e-8),
    "max_step": st.sampled_from([0.0, 0.01, 0.05]),
})


@st.composite
def stick_params(draw, name):
    m, x_i = draw(logf(0.1, 10.0)), draw(st.floats(0.2, 2.0))
    g = draw(st.sampled_from([9.81, 1.62, 0.28]) | logf(0.1, 30.0))
    c = draw(st.just(0.0) | st.floats(0.0, 5.0))
    p = dict(m=m, x_i=x_i, g=g, c=c, **draw(SOLVER))
    if name == "PogoStickSMA":
        k1 = draw(logf(50.0, 5e3))
        x3 = -x_i * draw(st.floats(0.02, 0.3))
        x1 = max(x3 * draw(st.floats(1.2, 3.0)), -0.9 * x_i)
        p.update(k1=k1, k2=k1 * draw(st.floats(0.05, 0.999999)), x1=x1, x3=x3)
        k_low, k_fast, deflection_max = p["k2"], k1, 0.9 * abs(x1)
    else:
        k = draw(logf(20.0, 5e3))
        p["k"] = k
        k_low = k_fast = k
        deflection_max = 0.2 * x_i
        if name == "PogoStickMem":
            law, beta = draw(st.sampled_from([0, 1, 2])), draw(st.floats(0.0, 3.0))
            a_0 = draw(st.floats(-0.2, 0.2))
            p.update(spring_law=law, beta=beta, gamma=draw(st.floats(0.0, 3.0)), a_0=a_0)
            grow = beta * (abs(a_0) + x_i * STOP)  # |a| <= |a_0| + x_i t
            if law == 1:
                k_low = k / (1 + grow)
            elif law == 2:
                k_fast = k * (1 + grow)
    if draw(st.booleans()):  # flight start
        z_0, ydot_0 = draw(st.floats(1e-3 * x_i, 2.0)), draw(st.floats(-3.0, 3.0))
        p.update(xbar_0=x_i, xdot_0=0.0, y_0=x_i + z_0, z_0=z_0, ydot_0=ydot_0)
    else:  # contact start, on the virgin line for the SMA
        xbar_0 = x_i - draw(st.floats(0.0, 1.0)) * deflection_max
        ydot_0 = draw(st.floats(-2.0, 2.0))
        p.update(xbar_0=xbar_0, xdot_0=ydot_0, y_0=xbar_0, z_0=0.0, ydot_0=ydot_0)
    # the leg cannot bottom out: even the softest leg stores 4x the total energy at full compression
    energy = m * (g * p["y_0"] + p["ydot_0"] ** 2 / 2) + k_fast * (x_i - p["xbar_0"]) ** 2 / 2
    assume(k_low * x_i ** 2 / 2 >= 4 * energy)
    assume(math.sqrt(m / k_fast) >= 1e-4 and (c == 0 or m / c >= 1e-4))
    p["_scale"] = min(x_i, m * g / k_fast, abs(p.get("x3", x_i)))  # smallest length the error control must resolve
    p["abs_tol"] = min(p["abs_tol"], 1e-3 * p["_scale"])  # the rule (README "Errors")
    return p


@st.composite
def penetrator_params(draw):
    m, x_i, k = draw(logf(0.1, 10.0)), draw(st.floats(0.2, 2.0)), draw(logf(20.0, 5e3))
    g = draw(st.sampled_from([9.81, 1.62]) | logf(0.1, 30.0))
    K, n = draw(logf(1e2, 1e6)), draw(st.floats(1.0, 2.0))
    p = dict(m=m, k=k, c=draw(st.floats(0.05, 5.0)), x_i=x_i, g=g, K=K, n=n, c_r=draw(st.floats(0.0, 1.0)),
             d0dot=draw(logf(0.3, 10.0)), d0dot_from_impact=draw(st.sampled_from([0, 1])), **draw(SOLVER))
    if draw(st.booleans()):
        p.update(y_0=x_i + draw(st.floats(1e-3, 2.0)), ydot_0=draw(st.floats(-3.0, 3.0)))
    else:
        p.update(y_0=x_i * (1 - draw(st.floats(0.0, 0.1))), ydot_0=draw(st.floats(-1.0, 1.0)))
    energy = m * (g * p["y_0"] + p["ydot_0"] ** 2 / 2) + k * (x_i - min(p["y_0"], x_i)) ** 2 / 2
    assume(k * (x_i / 2) ** 2 / 2 >= 4 * energy and K * (x_i / 2) ** (n + 1) / (n + 1) >= 4 * energy)
    K_s = K * n * (m * g / K) ** ((n - 1) / n)  # soil stiffness at the resting depth
    assume(min(p["c"] / k, math.sqrt(m / k), p["c"] / K_s) >= 1e-4)
    p["_scale"] = min(x_i, m * g / k, (m * g / K) ** (1 / n))
    p["abs_tol"] = min(p["abs_tol"], 1e-3 * p["_scale"])  # the rule (README "Errors")
    return p


# a thrust held over each communication step, cycled: upward only (in [0, 2 m g]), so the leg can
# still not bottom out; it forces liftoffs (F > m g) and restarts the integrator at input changes
THRUST = st.lists(st.floats(0.0, 2.0), min_size=1, max_size=8)
