"""PogoStick.fmu against the closed-form event times and the energy balance.

Every test drives the built FMU through fmpy. Event times come from the FMU's event log
(log_events = 1), which reports every event whatever the communication step.
"""
import math

import numpy as np
import pytest

from support import Instance, init_failure_text, reference_events, simulate

REF = reference_events()
T_REF = np.array([e["time"] for e in REF])
V_REF = np.array([e["ydot"] for e in REF])
NAMES_REF = [e["name"] for e in REF]


def events(**start_values):
    run = simulate("PogoStick", start_values={"log_events": 1, **start_values})
    ev = run.events()
    return run, ev


def test_reference_csv_is_the_closed_form():
    """Sanity of the reference itself: alternating touchdown/liftoff, |ydot| kept across flight."""
    assert len(REF) == 19
    assert NAMES_REF == ["touchdown", "liftoff"] * 9 + ["touchdown"]
    for lo, td in zip(REF[1::2], REF[2::2]):  # a flight is a parabola: lands with the take-off speed
        assert td["ydot"] == pytest.approx(-lo["ydot"], rel=1e-15)
        assert td["time"] - lo["time"] == pytest.approx(2 * lo["ydot"] / 9.81, rel=1e-12)


def test_dopri5_matches_all_19_reference_events():
    run, ev = events(method=5, rel_tol=1e-10)
    assert [e["name"] for e in ev] == NAMES_REF, "wrong sequence or a 20th event in 10 s"
    t = np.array([e["time"] for e in ev])
    v = np.array([e["state"]["ydot"] for e in ev])
    assert np.max(np.abs(t - T_REF)) < 1e-8
    assert np.max(np.abs(v - V_REF)) < 1e-7
    # the outputs agree with the log
    assert run["n_events"][-1] == 19
    assert run["t_last_event"][-1] == t[-1]
    assert run["last_event"][-1] == 1  # touchdown
    assert run["s"][-1] == 1  # settled in contact


def test_dop853_matches_all_19_reference_events_to_1e12():
    _, ev = events(method=8, rel_tol=1e-12)
    assert [e["name"] for e in ev] == NAMES_REF
    t = np.array([e["time"] for e in ev])
    assert np.max(np.abs(t - T_REF)) < 1e-12


@pytest.mark.parametrize("step", [1e-2, 0.1, 1.0])
def test_event_times_do_not_depend_on_the_communication_step(step):
    base = [e["time"] for e in events(method=5, rel_tol=1e-10)[1]]
    run = simulate("PogoStick", start_values={"log_events": 1, "method": 5, "rel_tol": 1e-10},
                   output_interval=step)
    got = [e["time"] for e in run.events()]
    assert len(got) == len(base) == 19
    assert np.max(np.abs(np.array(got) - base)) <= 1e-12
    assert run["time"][-1] == pytest.approx(10.0)


def _max_event_error(rel_tol, max_step):
    _, ev = events(method=5, rel_tol=rel_tol, max_step=max_step)
    assert len(ev) == 19, f"rel_tol={rel_tol}, max_step={max_step}: {len(ev)} events"
    return np.max(np.abs(np.array([e["time"] for e in ev]) - T_REF))


def test_tolerance_proportionality_fig21():
    """Unbounded max_step: the event-time error falls in proportion to rel_tol (slope ~ 1)."""
    tols = np.array([1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10])
    errs = np.array([_max_event_error(tol, 0.0) for tol in tols])
    slope = np.polyfit(np.log10(tols), np.log10(errs), 1)[0]
    assert 0.7 <= slope <= 1.3, (slope, errs)
    assert errs[-1] < errs[0] / 1e4


@pytest.mark.parametrize("rel_tol", [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10])
def test_19_events_at_every_tolerance_with_max_step_fig22(rel_tol):
    """docs/sweeps-and-studies.md: with max_step 0.01 s the step bound sets the error at 1.7e-7 s
    down to rel_tol 1e-7, below which it joins the unbounded curve (~26 rel_tol); allowed: 3x that."""
    err = _max_event_error(rel_tol, 0.01)
    assert err < 3 * max(1.7e-7 if rel_tol > 1e-9 else 0.0, 26 * rel_tol), err


def test_energy_balance_without_input():
    run = simulate("PogoStick", start_values={"rel_tol": 1e-10})
    E0 = 1.0 * 9.81 * 1.5
    assert run["E"][0] == pytest.approx(E0, rel=1e-15)
    balance = run["E"] + run["W_leg"]
    assert np.max(np.abs(balance - E0)) <= 1e-8 * E0
    assert np.all(run["W_ext"] == 0.0)
    # W_leg = spring energy k x^2/2 + dashpot dissipation int c xdot^2 dt: the latter never decreases
    dissipated = run["W_leg"] - 0.5 * 100.0 * run["x"] ** 2
    assert np.all(np.diff(dissipated) >= -1e-9 * E0)
    assert dissipated[-1] > 0.3 * E0


def _forcing():
    """A piecewise-constant F_ext (N) changing on the communication grid, as a master holds it."""
    return [(0.0, 0.0), (0.9, 4.0), (1.6, -3.0), (2.3, 0.0), (3.0, 6.0), (3.4, 0.0)]


def _forced_reference(stop):
    """Independent solution: scipy DOP853 at rtol 1e-12 on Eq. 43 with F_ext, terminal events."""
    from scipy.integrate import solve_ivp

    m, k, c, x_i, g = 1.0, 100.0, 0.5, 1.0, 9.81
    pieces = _forcing() + [(stop, None)]
    t, Y, s, times = 0.0, np.array([1.0, 0.0, 1.5, 0.0, 0.5]), 0, []
    for (ta, F), (tb, _) in zip(pieces[:-1], pieces[1:]):
        while t < tb:
            def rhs(_t, Y, s=s, F=F):
                if s:
                    a = (F - k * (Y[0] - x_i) - c * Y[1]) / m - g
                    return [Y[1], a, Y[3], a, 0.0]
                return [0.0, 0.0, Y[3], F / m - g, Y[3] - Y[1]]

            def ev(_t, Y, s=s):
                return Y[0] - x_i if s else Y[4]
            ev.terminal, ev.direction = True, (1 if s else -1)
            sol = solve_ivp(rhs, (t, tb), Y, method="DOP853", rtol=1e-12, atol=1e-14, events=ev,
                            max_step=0.01)
            if sol.status == 1:
                t, Y = sol.t_events[0][0], sol.y_events[0][0].copy()
                times.append(t)
                if s:
                    Y[0], Y[1], Y[4], s = x_i, 0.0, 0.0, 0
                else:
                    Y[1], Y[4], s = Y[3], 0.0, 1
            else:
                t, Y = tb, sol.y[:, -1]
    return np.array(times)


def test_forced_run_matches_independent_solution_and_energy_balance():
    stop, h = 5.0, 1e-2
    grid = np.arange(0.0, stop + h / 2, h)
    table = _forcing()
    F = np.array([[v for t0, v in table if t0 <= t + 1e-12][-1] for t in grid])
    signal = np.array(list(zip(grid, F)), dtype=[("time", np.float64), ("F_ext", np.float64)])
    run = simulate("PogoStick", start_values={"log_events": 1, "method": 8, "rel_tol": 1e-11},
                   stop_time=stop, output_interval=h, input=signal)
    got = np.array([e["time"] for e in run.events()])
    ref = _forced_reference(stop)
    assert len(got) == len(ref) >= 8
    assert np.max(np.abs(got - ref)) < 1e-8
    E0 = 9.81 * 1.5
    balance = run["E"] + run["W_leg"] - run["W_ext"]
    assert np.max(np.abs(balance - E0)) <= 1e-8 * E0
    assert np.max(np.abs(run["W_ext"])) > 0.5


# ---- bad input: error status, message naming variable, value and rule; host survives ---------

BAD_PARAMETERS = [
    ({"m": 0.0}, "parameter m = 0.0", "m > 0"),
    ({"m": -1.0}, "parameter m = -1.0", "m > 0"),
    ({"k": -5.0}, "parameter k = -5.0", "k >= 0"),
    ({"c": -0.1}, "parameter c = -0.1", "c >= 0"),
    ({"x_i": 0.0}, "parameter x_i = 0.0", "x_i > 0"),
    ({"y_0": -0.5}, "parameter y_0 = -0.5", "y_0 > 0"),
    ({"z_0": 0.4}, "parameter z_0 = 0.4", "z_0 = y_0 - xbar_0"),
    ({"g": math.nan}, "parameter g = nan", "finite"),
    ({"rel_tol": 0.0}, "parameter rel_tol = 0.0", "rel_tol"),
    ({"method": 4}, "parameter method = 4", "5 (DOPRI5) or 8 (DOP853)"),
]


@pytest.mark.parametrize("values, names, rule", BAD_PARAMETERS)
def test_bad_parameter_is_rejected_with_a_clear_message(values, names, rule):
    text = init_failure_text("PogoStick", **values)
    assert names in text and rule in text, text
    assert run_fresh_instance()  # the host process goes on, a new instance works


def run_fresh_instance():
    run = simulate("PogoStick", stop_time=0.5)
    return run["n_events"][-1] == 1


def test_nan_input_and_negative_step_are_refused_then_the_instance_goes_on():
    from fmpy.fmi1 import FMICallException

    inst = Instance("PogoStick").init()
    try:
        inst.run_to(0.1, 1e-2)
        inst.set(F_ext=math.nan)
        with pytest.raises(FMICallException):
            inst.step(1e-2)
        # (the model, the input, its value, the time the step starts at, the rule)
        said = [m[2] for m in inst.messages if "input F_ext = nan" in m[2]]
        assert said and said[0] == f"PogoStick: input F_ext = nan at t = {inst.t!r} s violates the rule: F_ext must be " \
                                   f"a finite number", said
        inst.set(F_ext=0.0)
        with pytest.raises(FMICallException):
            inst.fmu.doStep(currentCommunicationPoint=inst.t, communicationStepSize=-0.5)
        assert any("step_size = -0.5 violates the rule: 0 <= step_size" in m[2] for m in inst.messages)
        inst.run_to(0.5, 1e-2)
        assert inst.get("n_events") == 1
        assert inst.get("t_last_event") == pytest.approx(T_REF[0], abs=1e-6)
    finally:
        inst.close()


def test_leg_bottoming_out_is_an_error_naming_condition_and_time():
    from fmpy.fmi1 import FMICallException

    inst = Instance("PogoStick").init(k=5.0)  # static deflection m g / k = 1.96 m > x_i
    with pytest.raises(FMICallException) as exc:
        inst.run_to(2.0, 1e-2)
    assert "(error)" in str(exc.value)
    text = "\n".join(m[2] for m in inst.messages)
    assert "xbar" in text and "bottomed out" in text and "t = 0.57" in text, text
    # closed form: touchdown at T_REF[0] with speed v0, then x'' = -(k/m) x - (c/m) x' - g from
    # x = 0 reaches x = -x_i; check the reported time against an independent integration
    from scipy.integrate import solve_ivp

    v0 = V_REF[0]
    sol = solve_ivp(lambda t, X: [X[1], -5.0 * X[0] - 0.5 * X[1] - 9.81], (0, 2), [0.0, v0],
                    events=lambda t, X: X[0] + 1.0, rtol=1e-12, atol=1e-14)
    t_bottom = T_REF[0] + sol.t_events[0][0]
    reported = float(text.split("domain at t = ")[1].split(" s")[0])
    assert reported == pytest.approx(t_bottom, abs=1e-6)


def test_state_saved_in_flight_and_in_contact_replays_identically():
    inst = Instance("PogoStick").init()
    try:
        for t_save, mode in ((0.25, 0), (0.5, 1), (1.0, 0), (1.4, 1)):
            inst.run_to(t_save, 1e-3)
            assert inst.get("s") == mode
            state = inst.fmu.getFMUstate()
            t0 = inst.t
            inst.run_to(t0 + 0.37, 1e-3)  # crosses at least one event
            first = inst.outputs()
            inst.fmu.setFMUstate(state)
            inst.t = t0
            assert inst.get("s") == mode
            inst.run_to(t0 + 0.37, 1e-3)
            assert inst.outputs() == first
            inst.fmu.freeFMUstate(state)
    finally:
        inst.close()


def test_event_states_lie_on_their_guards():
    """The state handed to each jump is on the guard (to round-off), not off by the dense
    output's interpolation error (7e-11 m at the default rel_tol before the engine landed it)."""
    _, ev = events()  # FMU defaults: method 0 (DOPRI5 here: never stiff), rel_tol 1e-6
    assert len(ev) == 19
    for e in ev:
        g = e["state"]["z"] if e["name"] == "touchdown" else e["state"]["xbar"] - 1.0
        assert abs(g) < 1e-13, e
