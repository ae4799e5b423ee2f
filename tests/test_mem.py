"""PogoStickMem.fmu (docs/models.md "PogoStickMem"): mem-spring and mem-dashpot legs, through the built FMU.

References are independent of the code under test: the closed-form event times of the basic stick
(pogofmu.references.closed_form), a solve_ivp model of the mem-stick (tests/references.py), the
energy balance, and the geometry of the pinched loop.
"""
import re

import numpy as np
import pytest
from references import scipy_mem
from support import Instance, assert_parameter_rejected, reference_events, simulate

NAME = "PogoStickMem"
M, K, C, X_I, G = 1.0, 100.0, 0.5, 1.0, 9.81
E0 = M * G * 1.5  # E = m ydot^2/2 + m g y at the default start (y = 1.5 m, at rest)
TIGHT = {"method": 8, "rel_tol": 1e-11, "abs_tol": 1e-14}
LAWS = (0, 1, 2)



def mem_run(stop_time, output_interval=1e-3, **params):
    return simulate(NAME, start_values=dict(log_events=1, **params), stop_time=stop_time,
                    output_interval=output_interval)


# ---- the linear limit ---------------------------------------------------------------------------

@pytest.mark.parametrize("law", LAWS)
def test_zero_memory_reproduces_the_closed_form_events(law):
    """beta = gamma = 0 is the basic PogoStick for every law: the 19 closed-form events to 1e-9 s
    (a non-zero initial absement must not matter either)."""
    run = mem_run(10.0, 1e-2, spring_law=law, beta=0.0, gamma=0.0, a_0=0.3, **TIGHT)
    got, ref = run.events(), reference_events()
    assert [e["name"] for e in got] == [e["name"] for e in ref]
    for e, r in zip(got, ref):
        assert abs(e["time"] - r["time"]) < 1e-9, (e, r)
    assert run["n_events"][-1] == 19


@pytest.mark.parametrize("law,beta,gamma", [(1, 1.0, 0.0), (1, 1.0, 2.0), (2, 1.0, 2.0), (0, 0.0, 3.0)])
def test_events_and_absement_agree_with_scipy(law, beta, gamma):
    """Mem-spring and mem-dashpot dynamics against an independent solve_ivp model (3 s)."""
    t_end = 3.0
    ref = scipy_mem(law, beta, gamma, t_end)
    run = mem_run(t_end, 1e-2, spring_law=law, beta=beta, gamma=gamma, **TIGHT)
    got = run.events()
    assert [e["name"] for e in got] == [name for name, _, _ in ref]
    assert len(got) >= 5
    for e, (name, t, X) in zip(got, ref):
        assert abs(e["time"] - t) < 1e-8, (name, e["time"], t)
        assert e["state"]["a"] == pytest.approx(X[5], abs=1e-9)
    sol_a = ref[-1][2][5]  # a is frozen in flight after the last event
    if ref[-1][0] == "liftoff":
        assert run["a"][-1] == pytest.approx(sol_a, abs=1e-9)


def test_absement_is_the_integral_of_the_deflection():
    """a' = x: trapezoidal quadrature of the sampled deflection matches the output a."""
    run = mem_run(3.0, 1e-4, a_0=0.25)
    t, x, a = run["time"], run["x"], run["a"]
    integral = 0.25 + np.concatenate(([0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * np.diff(t))))
    assert np.max(np.abs(integral - a)) < 1e-6
    assert a[-1] < 0.25 - 0.05  # it moved (compression only decreases a)


# ---- pinched loops, energy ------------------------------------------------------------------------

@pytest.mark.parametrize("law", (1, 2))
def test_mem_spring_loop_is_pinched_and_encloses_area(law):
    """Mem-spring alone (c = 0): r = k(a) x, so r = 0 wherever x = 0; the loop of one contact
    encloses the energy the spring absorbed (positive softening, negative hardening)."""
    beta = 1.0
    run = mem_run(1.6, 1e-4, spring_law=law, beta=beta, c=0.0)
    t, x, r, s, a = run["time"], run["x"], run["r"], run["s"], run["a"]
    # pinched: in flight x = 0 and r = 0; in contact |r| <= k_max |x| -> r vanishes with x
    assert np.all(x[s == 0] == 0.0) and np.all(r[s == 0] == 0.0)
    k_max = K * (1 + beta * np.max(np.abs(a))) if law == 2 else K
    assert np.all(np.abs(r) <= k_max * np.abs(x) * (1 + 1e-12) + 1e-15)
    # the law itself: r / x = k(a)
    c_ = s == 1
    k_a = K / (1 + beta * np.abs(a[c_])) if law == 1 else K * (1 + beta * np.abs(a[c_]))
    np.testing.assert_allclose(r[c_], k_a * x[c_], rtol=1e-12, atol=1e-14)
    # loop area of the first contact = energy lost by the mass in that contact (from the event log)
    ev = run.events()
    td, lo = ev[0], ev[1]
    assert (td["name"], lo["name"]) == ("touchdown", "liftoff")
    sel = (t >= td["time"]) & (t <= lo["time"])
    xs, rs = np.concatenate(([0.0], x[sel], [0.0])), np.concatenate(([0.0], r[sel], [0.0]))
    area = np.sum(0.5 * (rs[1:] + rs[:-1]) * np.diff(xs))  # = integral of r dx = work absorbed
    energy = lambda e: M * G * e["state"]["y"] + 0.5 * M * e["state"]["ydot"] ** 2  # noqa: E731
    lost = energy(td) - energy(lo)
    assert abs(lost) > 0.05, "the loop of one contact must enclose a non-zero area"
    assert (lost > 0) == (law == 1)
    assert area == pytest.approx(lost, rel=1e-3)


def test_mem_dashpot_loop_is_pinched_in_the_force_velocity_plane():
    """Mem-dashpot (spring law linear): r - k x = c (1 + gamma x^2) xdot, zero wherever xdot = 0."""
    gamma = 5.0
    run = mem_run(1.0, 1e-4, spring_law=0, gamma=gamma, c=2.0)
    x, xdot, r, s = run["x"], run["xdot"], run["r"], run["s"]
    c_ = s == 1
    r_d = r[c_] - K * x[c_]
    np.testing.assert_allclose(r_d, 2.0 * (1 + gamma * x[c_] ** 2) * xdot[c_], rtol=1e-10, atol=1e-12)
    i = np.argmin(np.abs(xdot[c_]))  # bottom of the contact: xdot ~ 0
    assert abs(r_d[i]) <= 2.0 * (1 + gamma) * abs(xdot[c_][i]) + 1e-12


@pytest.mark.parametrize("law", LAWS)
def test_energy_balance(law):
    """E + W_leg = E(0) within 1e-8 E(0) over the whole run, for every law (F_ext = 0)."""
    run = mem_run(6.0, 1e-3, spring_law=law, beta=1.0, gamma=2.0, **TIGHT)
    E = 0.5 * M * run["ydot"] ** 2 + M * G * run["y"]
    np.testing.assert_allclose(run["E"], E, rtol=1e-14)
    assert np.max(np.abs(run["E"] + run["W_leg"] - E0)) <= 1e-8 * E0
    assert np.all(run["W_ext"] == 0.0)
    assert run["W_leg"][-1] > 0.5 * E0 * 0.1  # the leg did absorb energy


def test_energy_balance_with_forcing():
    """E + W_leg = E(0) + W_ext with a piecewise-constant F_ext (stepped by hand)."""
    inst = Instance(NAME).init(**TIGHT, beta=0.5)
    try:
        rng = np.random.default_rng(3)
        worst = 0.0
        for j in range(30):
            inst.set(F_ext=float(rng.uniform(-5.0, 5.0)))
            inst.run_to(inst.t + 0.1, 1e-2)
            E, W, Wx = inst.get("E", "W_leg", "W_ext")
            worst = max(worst, abs(E + W - E0 - Wx))
        assert Wx != 0.0
        assert worst <= 1e-8 * E0
    finally:
        inst.close()


def test_first_contact_absorbs_softening_over_linear_over_hardening():
    """Work absorbed by the leg over the first contact: softening > linear > hardening."""
    absorbed = {}
    for law in LAWS:
        run = mem_run(1.0, 1e-3, spring_law=law, beta=1.0, **TIGHT)
        ev = run.events()
        assert [e["name"] for e in ev[:2]] == ["touchdown", "liftoff"]
        t_lo = ev[1]["time"]
        i = np.searchsorted(run["time"], t_lo) + 1  # a sample in the first flight: W_leg is frozen
        absorbed[law] = run["W_leg"][i]
        e = lambda ev_: M * G * ev_["state"]["y"] + 0.5 * M * ev_["state"]["ydot"] ** 2  # noqa: E731
        assert absorbed[law] == pytest.approx(e(ev[0]) - e(ev[1]), rel=1e-9, abs=1e-9)
    assert absorbed[1] > absorbed[0] > absorbed[2]
    assert absorbed[0] > 0


# ---- leaving the domain -------------------------------------------------------------------------

def test_softening_beta_5_bottoms_out_with_a_clear_error():
    """beta = 5: the softening leg bottoms out near t = 5 s; the run ends with fmi2Fatal and a
    message that names the condition and the time (no nonsense values before it)."""
    from fmpy.fmi1 import FMICallException

    ref = scipy_mem(1, 5.0, 0.0, 10.0)
    assert ref[-1][0] == "bottom"
    t_bottom = ref[-1][1]
    assert 4.5 < t_bottom < 5.5
    inst = Instance(NAME).init(beta=5.0, **TIGHT)
    xbar_seen = []
    with pytest.raises(FMICallException) as exc:
        while inst.t < 10.0:
            inst.step(1e-2)
            xbar_seen.append(inst.get("xbar"))
    assert "(error)" in str(exc.value)
    # FMI 2.0: nothing may be called on the instance after fmi2Fatal
    text = " ".join(m[2] for m in inst.messages)
    assert "xbar" in text and "bottomed out" in text, text
    t_msg = float(re.search(r"domain at t = ([0-9.eE+-]+) s", text).group(1))
    assert abs(t_msg - t_bottom) < 1e-6, (t_msg, t_bottom)
    assert all(0.0 < v <= X_I for v in xbar_seen)
    assert abs(inst.t - t_bottom) <= 1e-2 + 1e-9


# ---- bad input, memory across FMU state ----------------------------------------------------------

@pytest.mark.parametrize("param,value,rule", [
    ("beta", -1.0, "beta >= 0"),
    ("gamma", -0.5, "gamma >= 0"),
    ("k", -100.0, "k >= 0"),
    ("spring_law", 3, "spring_law is 0 (linear), 1 (softening) or 2 (hardening)"),
])
def test_bad_parameters_are_rejected_with_a_clear_message(param, value, rule):
    assert_parameter_rejected(NAME, {param: value}, param, rule)


def test_fmu_state_restores_the_absement():
    """Save in the first flight (a frozen, non-zero), run on, restore: a and the run are the same."""
    inst = Instance(NAME).init()
    try:
        inst.run_to(0.9, 1e-3)  # first flight: 0.711 < t < 1.238
        a_saved, t_saved = inst.get("a"), inst.t
        assert a_saved < -0.01
        state = inst.fmu.getFMUstate()
        inst.run_to(3.0, 1e-2)
        first = inst.outputs()
        assert first["a"] < a_saved - 0.01
        inst.fmu.setFMUstate(state)
        inst.t = t_saved
        assert inst.get("a") == a_saved
        inst.run_to(3.0, 1e-2)
        assert inst.outputs() == first
        inst.fmu.freeFMUstate(state)
    finally:
        inst.close()
