"""Penetrator.fmu: the stick driven into a Hunt-Crossley soil (docs/models.md "Penetrator").

Every test drives the built FMU through fmpy.  The reference (tests/references.py) is written
independently of the package: Eq. 50 integrated by scipy's DOP853 at rtol = 1e-13, with scipy's own event
location (touchdown: the foot height y - x_i - x_lift exp(-(k/c)(t - t_lift)) falling, i.e.
y - x_i once the massless leg has relaxed after liftoff; liftoff: delta falling; a new record of
the penetration: delta' falling through 0 while delta exceeds every earlier penetration).
"""
import math

import numpy as np
import pytest

from references import PENETRATOR_DEFAULTS as DEFAULTS
from references import hunt_crossley
from references import penetrator_reference as reference
from support import Instance, assert_parameter_rejected, simulate

CONTACT_EVENTS = ("touchdown", "liftoff")


# ---------------------------------------------------------------------------------------------
# helpers driving the FMU
# ---------------------------------------------------------------------------------------------

def run(stop_time=10.0, **start_values):
    return simulate("Penetrator", start_values={"log_events": 1, **start_values}, stop_time=stop_time)


def step_to(inst, t_target):
    """One doStep from inst.t that ends exactly at t_target (as the FMU computes it)."""
    h = t_target - inst.t
    while inst.t + h < t_target:
        h = math.nextafter(h, math.inf)
    while inst.t + h > t_target:
        h = math.nextafter(h, -math.inf)
    inst.fmu.doStep(currentCommunicationPoint=inst.t, communicationStepSize=h)
    inst.t = inst.t + h
    assert inst.t == t_target


def assert_events_match(ev, ref, tol_contact, tol_peak):
    """Same event sequence; touchdown/liftoff times within tol_contact; the times of penetration
    records (delta' = 0 at a flat maximum: ill-conditioned, error ~ rel_tol) within tol_peak."""
    assert [e["name"] for e in ev] == [nm for nm, _, _ in ref]
    for e, (nm, t, _) in zip(ev, ref):
        tol = tol_peak if nm == "max_penetration" else tol_contact
        assert abs(e["time"] - t) < tol, (nm, e["time"], t)


def energy_residual(res, P):
    E0 = P["m"] * (0.5 * P["ydot_0"] ** 2 + P["g"] * P["y_0"])
    r = res["E"] + res["W_leg"] + res["W_soil"] - E0 - res["W_ext"]
    return np.max(np.abs(r)) / E0


def check_contact_boundaries(start_values, stop_time=10.0):
    """At every touchdown delta_dot is the foot's impact speed, -ydot when the leg is back at its
    free length; at every liftoff F_soil returns to 0 (FMU stepped exactly onto each event time
    of its own log, and just before each liftoff).  Returns the numbers of touchdowns, of
    touchdowns with the leg relaxed, and of liftoffs."""
    P = dict(DEFAULTS, **start_values)
    ev = run(stop_time, **start_values).events()
    inst = Instance("Penetrator").init(stop_time=stop_time, log_events=1, **start_values)
    n_td = n_lo = n_relaxed = 0
    try:
        for e in ev:
            if e["name"] == "touchdown":
                step_to(inst, e["time"])
                o = inst.outputs()
                assert o["s"] == 1 and o["t_last_event"] == e["time"], (e, o)
                assert o["delta"] == 0.0 and o["z"] == 0.0
                # the penetration starts at the foot's speed: -ydot once the leg has relaxed after
                # the previous liftoff, in general -(ydot - x') = -ydot - (k/c) x with x = y - x_i
                foot_speed = -o["ydot"] - P["k"] / P["c"] * (o["y"] - P["x_i"])
                assert abs(o["delta_dot"] - foot_speed) <= 1e-9, (e["time"], o["delta_dot"], foot_speed)
                # leg back at its free length (its remaining relaxation speed below 1e-10 m/s)
                if P["k"] / P["c"] * abs(e["state"]["y"] - P["x_i"]) <= 1e-10:
                    assert abs(o["delta_dot"] + o["ydot"]) <= 1e-9, (e["time"], o["delta_dot"], o["ydot"])
                    n_relaxed += 1
                n_td += 1
            elif e["name"] == "liftoff":
                # the logged state just before the jump: independent Hunt-Crossley force ~ 0
                st = e["state"]
                x = [st["y"], st["ydot"], st["delta"]]
                d0 = inst.get("d0dot_used")
                assert abs(hunt_crossley(x, d0, **start_values)) <= 1e-6, (e, hunt_crossley(x, d0, **start_values))
                step_to(inst, e["time"] - 1e-9)
                o = inst.outputs()
                assert o["s"] == 1 and 0.0 <= o["delta"] <= 1e-6 and abs(o["F_soil"]) <= 1e-6, (e["time"], o)
                step_to(inst, e["time"])
                o = inst.outputs()
                assert o["s"] == 0 and o["F_soil"] == 0.0 and o["delta"] == 0.0 and o["delta_dot"] == 0.0, o
                n_lo += 1
    finally:
        inst.close()
    return n_td, n_relaxed, n_lo


# ---------------------------------------------------------------------------------------------
# defaults
# ---------------------------------------------------------------------------------------------

def test_reference_itself_is_sane():
    """The reference's first touchdown is the free-fall time; flights are parabolas that end
    where the foot, y - x_i - x_lift exp(-(k/c) t), reaches the surface."""
    ref, _ = reference()
    assert ref[0][0] == "touchdown"
    assert ref[0][1] == pytest.approx(math.sqrt(2 * 0.5 / 9.81), abs=1e-13)
    n_flights = 0
    for (n1, t1, x1), (n2, t2, x2) in zip(ref, ref[1:]):
        if n1 == "liftoff":
            assert n2 == "touchdown"
            dt = t2 - t1
            y_parabola = x1[0] + x1[1] * dt - 9.81 / 2 * dt * dt
            assert x2[0] == pytest.approx(y_parabola, abs=1e-12)
            assert x2[1] == pytest.approx(x1[1] - 9.81 * dt, abs=1e-11)
            assert y_parabola == pytest.approx(1.0 + (x1[0] - 1.0) * math.exp(-200.0 * dt), abs=1e-12)
            n_flights += 1
    assert n_flights == 9


def test_defaults_first_touchdown_and_models_md_numbers():
    r = run()
    ev = r.events()
    ref, ref_max = reference()
    assert ev[0]["name"] == "touchdown"
    assert abs(ev[0]["time"] - 0.3192754284) < 1e-10
    assert abs(ev[0]["time"] - math.sqrt(2 * 0.5 / 9.81)) < 1e-12
    contact = [e for e in ev if e["name"] in CONTACT_EVENTS]
    # docs/models.md "Penetrator": first liftoff near 0.7082 s with ydot near 2.828 m/s, maximum
    # penetration near 0.0254 m, 19 (touchdown/liftoff) events in 10 s
    assert contact[1]["name"] == "liftoff"
    assert contact[1]["time"] == pytest.approx(0.7082, abs=1e-4)
    assert contact[1]["state"]["ydot"] == pytest.approx(2.828, abs=1e-3)
    assert r["delta_max"][-1] == pytest.approx(0.0254, abs=1e-4)
    assert len(contact) == 19
    # the whole sequence (with the one record of penetration) as the reference
    assert_events_match(ev, ref, 1e-7, 1e-5)
    assert r["delta_max"][-1] == pytest.approx(ref_max, rel=1e-7)
    assert r["n_events"][-1] == len(ref) == 20
    assert r["s"][-1] == 1  # settled in contact


def test_defaults_touchdown_and_liftoff_invariants():
    n_td, n_relaxed, n_lo = check_contact_boundaries({})
    # the last flight (0.099 s, 20 relaxation times) leaves 5e-12 m of leg compression
    # (relaxation speed 9e-10 m/s): there delta_dot = -ydot holds only through the general law
    assert (n_td, n_relaxed, n_lo) == (10, 9, 9)


def test_delta_never_negative_and_soil_force_zero_in_flight():
    r = simulate("Penetrator", stop_time=10.0, output_interval=5e-4)
    assert np.min(r["delta"]) >= -1e-12
    flight = r["s"] == 0
    assert flight.any() and (~flight).any()
    assert np.all(r["F_soil"][flight] == 0.0) and np.all(r["delta"][flight] == 0.0)
    assert np.all(r["delta_max"] >= r["delta"])
    assert np.all(np.diff(r["delta_max"]) >= 0)


def test_delta_max_is_the_running_maximum():
    """Exact at every output: the running max of delta, including points between the samples."""
    r = simulate("Penetrator", stop_time=2.0, output_interval=1e-4, start_values={"rel_tol": 1e-10})
    running = np.maximum.accumulate(r["delta"])
    # sampled running max can only be below the true one, by at most the curvature over a sample
    assert np.all(r["delta_max"] >= running - 1e-15)
    assert np.max(r["delta_max"] - running) < 1e-8
    _, ref_max = reference()
    assert r["delta_max"][-1] == pytest.approx(ref_max, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# convergence of the event times
# ---------------------------------------------------------------------------------------------

def _first_events(n, **sv):
    return run(stop_time=4.0, **sv).events()[:n]


def test_event_times_converge_and_match_reference():
    ref, _ = reference()
    ref10 = ref[:10]
    loose = _first_events(10, rel_tol=1e-8)
    tight = _first_events(10, rel_tol=1e-12, abs_tol=1e-14)
    names = [n for n, _, _ in ref10]
    assert [e["name"] for e in loose] == [e["name"] for e in tight] == names
    t_ref = np.array([t for _, t, _ in ref10])
    t_loose = np.array([e["time"] for e in loose])
    t_tight = np.array([e["time"] for e in tight])
    assert np.max(np.abs(t_loose - t_tight)) < 1e-6
    assert np.max(np.abs(t_loose - t_ref)) < 1e-6
    assert np.max(np.abs(t_tight - t_ref)) < 1e-8
    # the states at the events too (before the jump)
    for e, (_, _, x) in zip(tight, ref10):
        assert e["state"]["ydot"] == pytest.approx(x[1], abs=1e-8)
        assert e["state"]["y"] == pytest.approx(x[0], abs=1e-9)


def test_dop853_matches_reference():
    ref, _ = reference()
    ev = _first_events(10, method=8, rel_tol=1e-12, abs_tol=1e-14)
    assert [e["name"] for e in ev] == [n for n, _, _ in ref[:10]]
    assert np.max(np.abs(np.array([e["time"] for e in ev]) - [t for _, t, _ in ref[:10]])) < 1e-8


@pytest.mark.parametrize("step", [0.1, 1.0])
def test_event_times_do_not_depend_on_the_communication_step(step):
    base = [e["time"] for e in run(stop_time=4.0).events()]
    r = simulate("Penetrator", start_values={"log_events": 1}, stop_time=4.0, output_interval=step)
    got = [e["time"] for e in r.events()]
    assert len(got) == len(base) > 5
    assert np.max(np.abs(np.array(got) - base)) <= 1e-12


# ---------------------------------------------------------------------------------------------
# energy
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("sv", [{}, {"n": 1.0}, {"n": 2.0}, {"d0dot_from_impact": 1}, {"method": 8}],
                         ids=["defaults", "n=1", "n=2", "d0dot_from_impact", "dop853"])
def test_energy_balance(sv):
    r = simulate("Penetrator", start_values=sv, stop_time=10.0)
    assert energy_residual(r.res, dict(DEFAULTS, **sv)) < 1.5e-8  # docs/fmus.md: <= 4e-9 E(0)
    # both sinks absorb energy over a completed contact: the soil dissipates (W_soil grows), the
    # leg ends each contact with W_leg >= 0 (dashpot loss + the strain energy dropped at liftoff)
    assert r["W_soil"][-1] > 0 and r["W_leg"][-1] > 0
    assert r["E"][-1] < r["E"][0]


def test_energy_balance_with_external_force():
    """A time-varying F_ext (held per communication step): E + W_leg + W_soil = E(0) + W_ext."""
    t = np.arange(0.0, 5.0 + 1e-9, 0.01)
    signal = np.zeros(len(t), dtype=[("time", float), ("F_ext", float)])
    signal["time"] = t
    signal["F_ext"] = 4.0 * np.sin(3.0 * t)
    r = simulate("Penetrator", stop_time=5.0, output_interval=0.01, input=signal)
    assert np.max(np.abs(r["W_ext"])) > 0.1  # the input did work
    assert energy_residual(r.res, DEFAULTS) < 1.5e-8  # docs/fmus.md: <= 4e-9 E(0)


# ---------------------------------------------------------------------------------------------
# other soils: n = 1 (linear), n = 2; the impact-speed switch
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("n", [1.0, 2.0])
def test_linear_and_quadratic_soils(n):
    sv = {"n": n}
    r = simulate("Penetrator", start_values=dict(sv, log_events=1), stop_time=10.0, output_interval=1e-3)
    assert np.min(r["delta"]) >= -1e-12
    assert energy_residual(r.res, dict(DEFAULTS, **sv)) < 1.5e-8  # docs/fmus.md: <= 4e-9 E(0)
    ev = r.events()
    ref, ref_max = reference(t_end=3.0, **sv)
    got = [e for e in ev if e["time"] <= 3.0]
    assert_events_match(got, ref, 1e-7, 1e-5)
    assert r["delta_max"][-1] == pytest.approx(ref_max, rel=1e-6)
    n_td, n_relaxed, n_lo = check_contact_boundaries(sv)
    # the last hops are short: the leg (c/k = 5 ms) may not have relaxed fully before touchdown
    assert n_td >= 5 and n_relaxed >= 5 and n_lo >= 4


def test_d0dot_from_impact_uses_each_impact_speed():
    sv = {"d0dot_from_impact": 1, "y_0": 2.0, "d0dot": 1.0}  # d0dot unused: every contact has an impact
    r = run(stop_time=4.0, **sv)
    ev = r.events()
    ref, ref_max = reference(t_end=4.0, **sv)
    assert_events_match(ev, ref, 1e-7, 1e-5)
    # the switch changes the dynamics: with d0dot = 1 fixed, the first liftoff is elsewhere
    fixed, _ = reference(t_end=1.2, y_0=2.0, d0dot=1.0)
    lo_switch = next(t for nm, t, _ in ref if nm == "liftoff")
    lo_fixed = next(t for nm, t, _ in fixed if nm == "liftoff")
    assert abs(lo_switch - lo_fixed) > 1e-4  # 1000 times the tolerance of the comparison above
    # d0dot_used is the latest impact speed
    last_td = [e for e in ev if e["name"] == "touchdown"][-1]
    assert r["d0dot_used"][-1] == pytest.approx(-last_td["state"]["ydot"], rel=1e-12)
    assert r["d0dot_used"][-1] != sv["d0dot"]


def test_start_in_contact():
    """y_0 = x_i, ydot_0 = 0: the foot rests on the surface; delta_dot(0) = -ydot_0 = 0 and the
    stick settles at the static penetration (m g / K)^(1/n) with leg compression m g / k."""
    sv = {"y_0": 1.0, "ydot_0": 0.0, "c": 5.0}
    r = simulate("Penetrator", start_values=sv, stop_time=10.0)
    assert r["s"][0] == 1 and r["delta_dot"][0] == 0.0
    assert np.all(r["s"] == 1)
    assert r["delta"][-1] == pytest.approx((9.81 / 1e4) ** (1 / 1.5), rel=1e-4)
    assert r["F_soil"][-1] == pytest.approx(9.81, rel=1e-4)
    assert r["y"][-1] + r["delta"][-1] - 1.0 == pytest.approx(-9.81 / 100, rel=1e-4)
    assert energy_residual(r.res, dict(DEFAULTS, **sv)) < 1.5e-8  # docs/fmus.md: <= 4e-9 E(0)


# ---------------------------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name,value,rule", [
    ("c", 0.0, "c > 0"), ("c", -0.5, "c > 0"),
    ("K", -1.0, "K >= 0"),
    ("n", 0.5, "n >= 1"),
    ("c_r", -0.1, "0 <= c_r <= 1"), ("c_r", 1.5, "0 <= c_r <= 1"),
    ("d0dot", 0.0, "d0dot > 0"), ("d0dot", -3.0, "d0dot > 0"),
    ("d0dot_from_impact", 2, "d0dot_from_impact is 0 or 1"),
])
def test_bad_parameters_are_rejected_clearly(name, value, rule):
    assert_parameter_rejected("Penetrator", {name: value}, name, rule)


def test_slow_leg_touches_down_before_it_has_relaxed():
    """c = 5: the leg relaxes with c/k = 50 ms, the stick lifts off below x_i and lands again
    before the leg is back at its free length (the paper's flight model, leg snapped to x_i,
    has no touchdown for this: its foot would hang below the surface)."""
    sv = {"c": 5.0}
    r = run(**sv)
    ev = r.events()
    ref, ref_max = reference(**sv)
    assert_events_match(ev, ref, 1e-7, 1e-5)
    lo = next(e for e in ev if e["name"] == "liftoff")
    td = next(e for e in ev if e["name"] == "touchdown" and e["time"] > lo["time"])
    assert lo["state"]["y"] < 1.0 - 0.03 and td["state"]["y"] < 1.0 - 1e-3  # lands with a compressed leg
    assert energy_residual(r.res, dict(DEFAULTS, **sv)) < 1.5e-8  # docs/fmus.md: <= 4e-9 E(0)
    n_td, n_relaxed, n_lo = check_contact_boundaries(sv)
    assert n_td >= 2 and n_lo >= 1 and n_relaxed < n_td


def test_start_on_the_surface_pulled_out_starts_in_flight():
    """y_0 < x_i with the mass rising fast: the foot leaves the surface at once, so the stick
    starts in flight with its compressed leg relaxing (foot height 0 at t = 0, then rising)."""
    r = simulate("Penetrator", start_values={"y_0": 0.99, "ydot_0": 3.0, "log_events": 1}, stop_time=1.0,
                 output_interval=1e-3)
    assert r["s"][0] == 0 and r["z"][0] == pytest.approx(0.0, abs=1e-15)
    assert r["z"][1] > 0
    ev = r.events()
    assert ev[0]["name"] == "touchdown"
    # flight from y = 0.99 at 3 m/s: lands at y = x_i on the way down, leg relaxed by then
    a, b, c = -9.81 / 2, 3.0, 0.99 - 1.0
    assert ev[0]["time"] == pytest.approx((-b - math.sqrt(b * b - 4 * a * c)) / (2 * a), abs=1e-9)
