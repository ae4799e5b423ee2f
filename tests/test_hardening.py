"""The engine's hardening: starts on a guard, the work budget (per second simulated, and per call:
max_steps_per_call, the same refusal from both backends; fmi2CancelStep refused naming it), tight
tolerances, extreme parameters, messages that name the rule, refused tolerances, the event log in
constant memory —
each against an independent reference (closed form, the closed-form event table, the energy
balance, the rule). Bad steps and NaN inputs: tests/test_conformance.py; the SSP master's
inputs and memory: tests/test_ssp.py; the README's usage and packaging:
tests/test_readme_and_packaging.py.
"""
import math
import re

import numpy as np
import pytest

from support import (BACKENDS, ERROR, STEP, Instance, RawInstance, assert_parameter_rejected,
                     init_failure_text, reference_events, simulate)

G = 9.81
STICKS = ["PogoStick", "PogoStickMem", "PogoStickSMA"]
RAW = ("ZeroDivisionError", "OverflowError", "division by zero", "Traceback", "event storm")


def _energy_residual(run, soil=False):
    """E + W_leg (+ W_soil) - E(0) - W_ext over the whole run (0 for an exact solution)."""
    E = np.asarray(run["E"])
    bal = E + run["W_leg"] + (run["W_soil"] if soil else 0.0) - run["W_ext"]
    return float(np.max(np.abs(bal - E[0])))


# ---- a start exactly on a guard behaves as the physics says --------------------------------

@pytest.mark.parametrize("name", STICKS)
def test_stick_at_free_length_moving_up_lifts_off_at_t0(name):
    """y_0 = xbar_0 = x_i = 1, z_0 = 0, ydot_0 = xdot_0 = 1: contact at the free length with the mass
    moving up.  Physics: liftoff at t = 0, then a parabola z = t - g t^2/2 (the foot leaves with the
    leg at its free length), touchdown at 2/g with ydot = -1.  Before: fmi2Error at t = 1e-5 s,
    "leg deflection x = 4.4e-05 m must stay <= 0"."""
    run = simulate(name, start_values=dict(y_0=1.0, xbar_0=1.0, z_0=0.0, ydot_0=1.0, xdot_0=1.0, log_events=1,
                                           method=8, rel_tol=1e-12, abs_tol=1e-14),
                   stop_time=0.3, output_interval=1e-3)
    ev = run.events()
    assert [e["name"] for e in ev[:2]] == ["liftoff", "touchdown"], ev
    assert ev[0]["time"] == 0.0
    assert ev[1]["time"] == pytest.approx(2.0 / G, abs=1e-12)
    i = np.searchsorted(run["time"], 0.1)
    t = run["time"][i]
    assert run["y"][i] == pytest.approx(1.0 + t - G * t * t / 2, abs=1e-12)
    assert run["s"][i] == 0


@pytest.mark.parametrize("solver, before_init", [
    (dict(method=8, rel_tol=1e-12, abs_tol=1e-14), True),
    # found by the property suite: the first steps (1e-9 s) leave xbar = x_i + g t^2/2 exactly at
    # x_i (below an ulp), and the guard, still at zero after the first step, was disarmed
    (dict(c=0.0, rel_tol=1e-4, abs_tol=1e-12, max_step=0.0), False)])
def test_thrust_above_weight_lifts_off_from_rest_at_t0(solver, before_init):
    """At rest at the free length (contact), F_ext = 2 m g (set before initialization or at the
    first step): liftoff at t = 0 (within the first steps, 1e-8 s), then free flight with
    acceleration F/m - g: y = 1 + (F/m - g) t^2/2 (closed form)."""
    inst = Instance("PogoStick")
    try:
        if before_init:
            inst.set(F_ext=2 * G)
        inst.init(y_0=1.0, xbar_0=1.0, z_0=0.0, ydot_0=0.0, xdot_0=0.0, **solver)
        inst.set(F_ext=2 * G)
        inst.run_to(0.5, 1e-2)
        n, t_last, kind, s, y = inst.get("n_events", "t_last_event", "last_event", "s", "y")
    finally:
        inst.close()
    assert (n, kind, s) == (1, 2, 0)  # one liftoff
    assert 0.0 <= t_last <= 1e-8
    assert y == pytest.approx(1.0 + G * 0.25 / 2, abs=1e-9)


# ---- a work budget; a model without states takes no steps ---------------------------------

def _run_until_error(name, h=1e-2, t_end=10.0, **params):
    from fmpy.fmi1 import FMICallException

    inst = Instance(name).init(**params)
    try:
        with pytest.raises(FMICallException) as exc:
            while inst.t < t_end - 1e-12:
                inst.step(h)
        assert "(error)" in str(exc.value)
        return inst.messages, inst.t
    finally:
        inst.close()


def test_stiff_dashpot_ends_in_a_budget_error_naming_the_stiffness():
    """c = 1e6 (m/c = 1 us) with the explicit method only (method = 5): a warning, then an error
    naming the work budget, the time scale m/c with c's value, and what to change."""
    messages, t = _run_until_error("PogoStick", c=1e6, method=5)
    warnings = [m[2] for m in messages if m[0] == 1]
    errors = [m[2] for m in messages if m[0] >= 3]
    assert any("stiff" in w and "max_steps_per_second" in w for w in warnings), messages
    text = errors[-1]
    assert "work budget exhausted" in text and "max_steps_per_second = 100000" in text, text
    assert "m/c (leg dashpot) = 1e-06 s" in text and "c = 1000000.0" in text, text
    assert "raise max_steps_per_second" in text, text
    assert t < 1.0  # stopped in the first contact (touchdown at 0.319 s)


def test_budget_is_a_parameter_a_larger_one_lets_the_run_finish():
    """c = 3e4 needs ~1e4 steps per second of contact: refused with a budget of 2000, completed with
    the default 1e5, with the energy balance holding (independent check of the result)."""
    messages, _ = _run_until_error("PogoStick", t_end=2.0, c=3e4, max_steps_per_second=2000, method=5)
    assert any("max_steps_per_second = 2000" in m[2] for m in messages if m[0] >= 3), messages
    run = simulate("PogoStick", start_values=dict(c=3e4, method=5), stop_time=2.0, output_interval=1e-2)
    assert not run.errors
    assert _energy_residual(run) <= 1e-6 * run["E"][0]


@pytest.mark.parametrize("c", [3e4, 1e6])
def test_the_default_method_runs_the_stiff_dashpot_within_the_budget_and_keeps_the_energy_balance(c):
    """What exhausts DOPRI5's budget (c = 1e6) the default method 0 runs: it switches to Rodas5P in
    the contact, within the default budget, and the energy balance holds as for DOPRI5 at c = 3e4."""
    run = simulate("PogoStick", start_values=dict(c=c), stop_time=2.0, output_interval=1e-2)
    assert not run.errors, run.errors
    assert run["time"][-1] == pytest.approx(2.0)
    assert _energy_residual(run) <= 1e-6 * run["E"][0]


def test_tiny_max_step_is_refused_with_the_budget_rule():
    assert_parameter_rejected("PogoStick", {"max_step": 1e-8}, "max_step", "max_step >= 2/max_steps_per_second")


def test_a_model_without_states_takes_no_internal_steps():
    """HopController (no states) with max_step = 1e-6: before, 8 s of CPU per simulated second
    (internal steps of max_step on nothing).  Its max_step is unused, so it is not refused, and
    the engine takes no step: over 1e4 s, n_steps stays 0."""
    from pogofmu.runtime.solver import Simulator
    from pogofmu.runtime.models.hop_controller import MODEL

    sim = Simulator(MODEL, dict(max_step=1e-6))
    sim.advance(1e4)
    assert sim.n_steps == 0 and sim.t_out == 1e4
    run = simulate("HopController", start_values={"max_step": 1e-6}, stop_time=2.0)  # the FMU, 2000 steps
    assert not run.errors


# ---- one call's work is bounded by a parameter: max_steps_per_call ----------------------------

def _set_reals(inst, **values):
    import ctypes

    for name, value in values.items():
        vr = (ctypes.c_uint32 * 1)(inst.vars[name].valueReference)
        if inst.vars[name].type in ("Integer", "Int32"):  # (method)
            v = (ctypes.c_int32 * 1)(value)
            status = inst.raw("fmi2SetInteger", vr, 1, v) if inst.fmi == 2 else inst.raw("fmi3SetInt32", vr, 1, v, 1)
        else:
            v = (ctypes.c_double * 1)(value)
            status = inst.raw("fmi2SetReal", vr, 1, v) if inst.fmi == 2 else inst.raw("fmi3SetFloat64", vr, 1, v, 1)
        assert status == 0, inst.last()


def _bounded_call(backend, fmi, h, **settings):
    """Initialize with `settings`, take one step of `h` s; the status, the message, the step's CPU
    seconds (of this process, which runs the FMU: not the wall time, which a loaded machine stretches)."""
    import time

    inst = RawInstance(backend, fmi)
    try:
        _set_reals(inst, **settings)
        inst.enter_initialization()
        inst.exit_initialization()
        start = time.process_time()
        status, _ = inst.do_step(h)
        return status, inst.last(), time.process_time() - start, inst
    except BaseException:
        inst.close()
        raise


@pytest.mark.parametrize("fmi", [2, 3])
def test_a_step_needing_more_than_max_steps_per_call_is_refused_at_once(fmi):
    """step_size/max_step = 1e4 internal steps at least, max_steps_per_call = 1000: refused before
    any work, naming the parameter, its value and how to raise it; the instance goes on with a
    shorter step.  The same text from both backends."""
    texts = []
    for backend in BACKENDS:
        status, text, seconds, inst = _bounded_call(backend, fmi, 100.0, max_steps_per_call=1000.0)
        try:
            assert status == ERROR and seconds < 1.0, (status, text, seconds)
            assert "max_steps_per_call = 1000" in text and "raise the parameter max_steps_per_call" in text, text
            inst.t = 0.0  # the refused step moved nothing
            assert inst.do_step(1e-2)[0] == 0, inst.last()
        finally:
            inst.close()
        texts.append(text)
    assert texts[0] == texts[1], texts


@pytest.mark.parametrize("fmi", [2, 3])
def test_a_call_that_takes_more_than_max_steps_per_call_ends_naming_it(fmi):
    """max_step = 0 (unbounded: nothing to refuse beforehand) and a stiff leg (c = 3e4, ~1e4
    internal steps per second of contact, with the explicit method 5: the default method 0 would
    go implicit there) in one step of 2 s: the call stops after 2000 internal
    steps with Error naming max_steps_per_call, where it stopped and how to go on — identically on
    both backends (the engines count the same steps); with the parameter raised the same step
    completes."""
    texts = []
    for backend in BACKENDS:
        status, text, seconds, inst = _bounded_call(backend, fmi, 2.0, c=3e4, max_step=0.0, max_steps_per_call=2000.0,
                                                    method=5)
        try:
            assert status == ERROR, (status, text)
            assert "max_steps_per_call = 2000 internal steps taken in one call" in text, text
            assert "raise the parameter max_steps_per_call" in text and "shorter communication steps" in text, text
        finally:
            inst.close()
        texts.append(text)
        status, text, _, inst = _bounded_call(backend, fmi, 2.0, c=3e4, max_step=0.0, max_steps_per_call=1e6, method=5)
        inst.close()
        assert status == 0, text
    assert texts[0] == texts[1], texts


def test_max_steps_per_call_is_a_parameter_with_a_rule():
    from support import assert_parameter_rejected

    assert_parameter_rejected("PogoStick", {"max_steps_per_call": 0.5}, "max_steps_per_call",
                              "1 <= max_steps_per_call < inf")


@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
def test_fmi2_cancel_step_is_refused_naming_the_rule(backend):
    """FMI 2.0 §4.2.2: fmi2CancelStep only stops an asynchronous fmi2DoStep that returned fmi2Pending;
    these FMUs declare canRunAsynchronuously = false and never return it, so a call is Error naming
    the rule (the instance goes on)."""
    inst = RawInstance(backend, 2)
    try:
        inst.reach(STEP)
        assert inst.raw("fmi2CancelStep") == ERROR
        text = inst.last()
        assert "fmi2CancelStep refused" in text and "fmi2Pending" in text and "max_steps_per_call" in text, text
        assert inst.do_step()[0] == 0, inst.last()
    finally:
        inst.close()


# ---- tight tolerances work -----------------------------------------------------------------

@pytest.mark.parametrize("abs_tol, rel_tol, tol", [(1e-20, 1e-6, 1e-6), (1e-24, 1e-10, 1e-8), (1e-300, 1e-6, 1e-6)])
def test_tight_absolute_tolerances_work(abs_tol, rel_tol, tol):
    """Before: "step size collapsed" at t = 0 (the starting-step estimate was 1e-15 s); and a raw
    ZeroDivisionError for abs_tol = 1e-300.  Now the 19 closed-form events, each to `tol`."""
    run = simulate("PogoStick", start_values=dict(abs_tol=abs_tol, rel_tol=rel_tol, log_events=1))
    got = run.events()
    ref = reference_events()
    assert [e["name"] for e in got] == [e["name"] for e in ref]
    assert max(abs(a["time"] - b["time"]) for a, b in zip(got, ref)) < tol


# ---- SMA with k2 close to k1; Penetrator with a huge K ------------------------------------

def test_sma_with_k2_almost_k1_is_the_linear_stick():
    """k2 -> k1: both plateaus merge with the elastic lines, the leg is the linear spring k1 = 100 ||
    c = 0.5, i.e. the default PogoStick: its closed-form touchdowns and liftoffs.  Before, k2 >=
    0.999 k1 ended in "spring never extends" (a false upper_plateau right after a reversal)."""
    run = simulate("PogoStickSMA", start_values=dict(k2=100.0 * (1 - 1e-9), log_events=1, method=8,
                                                     rel_tol=1e-12, abs_tol=1e-14))
    got = [e for e in run.events() if e["name"] in ("touchdown", "liftoff")]
    ref = reference_events()
    assert [e["name"] for e in got] == [e["name"] for e in ref]
    assert max(abs(a["time"] - b["time"]) for a, b in zip(got, ref)) < 1e-8


@pytest.mark.parametrize("ratio", [0.999, 0.9999])
def test_sma_near_parallel_plateaus_keep_the_energy_balance(ratio):
    run = simulate("PogoStickSMA", start_values=dict(k2=100.0 * ratio))
    assert not run.errors
    assert _energy_residual(run) <= 1e-5 * run["E"][0]


def test_penetrator_soil_stiffness_beyond_resolution_is_refused():
    """K = 1e17 (n = 1.5): the foot's time scale in the soil c/K_s is 7e-13 s.  Before: a missed
    touchdown after a false liftoff, falling through the ground.  Now a rule naming K."""
    text = init_failure_text("Penetrator", K=1e17)
    assert "K = 1e+17" in text and "c/K_s" in text and ">= 1e-09 s" in text, text


# ---- every message names the variable, value and rule ---------------------------------------

@pytest.mark.parametrize("name", STICKS + ["Penetrator"])
@pytest.mark.parametrize("param, value", [("g", 1e300), ("m", 1e-300), ("k", 1e300)])
def test_extreme_magnitudes_get_a_rule_not_a_raw_error(name, param, value):
    if name == "PogoStickSMA" and param == "k":
        param = "k1"
    text = init_failure_text(name, **{param: value})
    assert f"{param} = {value!r}" in text and "violate" in text and "time scale" in text, text
    assert not any(raw in text for raw in RAW), text


# ---- tolerances that cannot control the error are refused ---------------------------------

def test_loose_abs_tol_is_refused_with_the_scale_it_must_resolve():
    """abs_tol = 1, max_step = 0.287 completed with the energy balance off by 90 % of E(0)."""
    text = init_failure_text("PogoStick", abs_tol=1.0, max_step=0.287)
    assert "parameter abs_tol = 1.0" in text and "m g/k (static leg deflection)" in text, text
    limit = float(re.search(r"\) = ([0-9.e+-]+);", text).group(1))
    assert limit == pytest.approx(1e-3 * 1.0 * G / 100.0, rel=1e-3)
    # at the limit the result is controlled: the energy balance within 1e-3 E(0)
    run = simulate("PogoStick", start_values=dict(abs_tol=limit, max_step=0.287))
    assert _energy_residual(run) <= 1e-3 * run["E"][0]


def test_abs_tol_above_a_tiny_start_names_the_state_that_sets_the_scale():
    """A model that declares no scale of its motion: abs_tol is held to 1e-3 x its largest initial
    state. A ball dropped from h0 = 1e-15 m (a user's start value) is refused naming the state h
    and its value, which the user's parameter gave it; the message named only "the largest initial
    state magnitude" (a user's audit, 2026-12-07). With abs_tol under the limit it runs: the drop
    time sqrt(2 h0 / g) to 1e-6 of itself."""
    from pogofmu.runtime.solver import Simulator

    ball = _elastic_ball()
    with pytest.raises(Exception) as info:
        Simulator(ball, {"h0": 1e-15}).advance(1e-3)
    text = str(info.value)
    assert "parameter abs_tol = " in text and "the largest initial state magnitude (y = 1e-15 at the start) = 1e-18" \
        in text, text
    sim = Simulator(ball, {"h0": 1e-15, "abs_tol": 1e-21}, keep_history=True)
    sim.advance(2e-8)
    assert sim.events[0].time == pytest.approx(math.sqrt(2e-15 / G), rel=1e-6)


def test_loose_rel_tol_is_refused():
    assert_parameter_rejected("PogoStick", {"rel_tol": 0.01}, "rel_tol", "rel_tol <= 0.001")
    assert_parameter_rejected("Penetrator", {"abs_tol": 1e-3}, "abs_tol", "resting depth in the soil")


# ---- the event log in constant memory ---------------------------------------------------

def _elastic_ball():
    from pogofmu.runtime.model import FALLING, Event, HybridModel, Parameter, Variable

    return HybridModel(
        name="Ball", description="elastic ball", states=(Variable("y", "m"), Variable("v", "m/s")),
        parameters=(Parameter("h0", 1e-3),), inputs=(), outputs=(),
        flow=lambda t, x, q, u, p: [x[1], -G],
        events=(Event("impact", FALLING, lambda x, q, u, p: x[0], lambda x, q, u, p: ([0.0, -x[1]], q)),),
        initial=lambda p: ([p.h0, 0.0], {}), output_fn=lambda *a: {})


def _footprint(obj, seen=None):
    """Bytes reachable from a snapshot (containers, records, floats), not counting the shared model,
    parameters, method and functions."""
    import sys
    import types
    from collections import deque

    seen = set() if seen is None else seen
    if id(obj) in seen or isinstance(obj, (types.FunctionType, type)):
        return 0
    seen.add(id(obj))
    size = sys.getsizeof(obj)
    if isinstance(obj, dict):
        items = [v for k, v in obj.items() if k not in ("model", "p", "pair")]
    elif isinstance(obj, (list, tuple, deque, set)):
        items = list(obj)
    elif hasattr(obj, "__dict__"):
        items = list(vars(obj).values())
    elif hasattr(obj, "__slots__"):
        items = [getattr(obj, a) for a in obj.__slots__ if hasattr(obj, a) and a not in ("fun", "pair")]
    else:
        items = []
    return size + sum(_footprint(v, seen) for v in items)


def test_state_size_is_constant_as_events_grow():
    """Before: ~1.9 kB more per event in every fmi2GetFMUstate copy.  Without log_events the
    snapshot's size is the same after 300 and 3000 events; with it, the history is there."""
    from pogofmu.runtime.solver import Simulator

    model = _elastic_ball()
    period = 2 * math.sqrt(2e-3 / G)
    sizes = {}
    for keep in (False, True):
        sim = Simulator(model, dict(max_step=0.0, log_events=int(keep)))
        for n in (300, 3000):
            sim.advance((n - 0.25) * period)  # impact k at (k - 1/2) period
            assert sim.n_events == n
            sizes[keep, n] = _footprint(sim.snapshot())
        assert sim.last_event.name == "impact"
        assert sim.last_event.time == pytest.approx((n - 0.5) * period, abs=1e-9 * n)
    assert sizes[False, 3000] <= sizes[False, 300] + 64
    assert sizes[True, 3000] > sizes[True, 300] + 2700 * 50


def test_outputs_and_log_agree_without_the_history():
    """n_events / t_last_event / last_event come from the constant-memory record: equal to the
    event log of a log_events = 1 run, and a state saved late restores to identical outputs."""
    sv = dict(c=0.0, k=1e4, y_0=1.01, z_0=0.01)  # elastic hopping: 17 events per second
    quiet = simulate("PogoStick", start_values=sv, stop_time=30.0, output_interval=1e-2)
    loud = simulate("PogoStick", start_values=dict(sv, log_events=1), stop_time=30.0, output_interval=1e-2)
    ev = loud.events()
    assert len(ev) > 400
    assert int(quiet["n_events"][-1]) == len(ev) == ev[-1]["index"]
    assert float(quiet["t_last_event"][-1]) == ev[-1]["time"]
    assert int(quiet["last_event"][-1]) == {"touchdown": 1, "liftoff": 2}[ev[-1]["name"]]


def test_a_collapse_after_one_event_is_not_called_an_event_storm():
    """After a single event the dynamics become too fast to resolve (acceleration 1e300 m/s2 once
    the ball has hit the ground): the message says so, names the event and the time; "event
    storm" is kept for accumulating events (test_engine.py::test_zeno_ends_in_a_clear_error)."""
    from pogofmu.runtime.solver import Simulator
    from pogofmu.runtime.model import FALLING, Event, HybridModel, ModelError, Parameter, Variable, ZenoError

    model = HybridModel(
        name="Ball", description="ball on a hard floor", states=(Variable("y", "m"), Variable("v", "m/s")),
        parameters=(Parameter("h0", 1.0),), inputs=(), outputs=(),
        flow=lambda t, x, q, u, p: [x[1], -G if not q["hit"] else 1e300 * (1.0 + x[0] * x[0])],
        events=(Event("impact", FALLING, lambda x, q, u, p: x[0], lambda x, q, u, p: (x, dict(q, hit=1)),
                      lambda q: not q["hit"]),),
        initial=lambda p: ([p.h0, 0.0], {"hit": 0}), output_fn=lambda *a: {})
    sim = Simulator(model, dict(max_step=0.0))
    with pytest.raises(ModelError) as exc:
        sim.advance(2.0)
    text = str(exc.value)
    assert not isinstance(exc.value, ZenoError) and "event storm" not in text, text
    t_impact = math.sqrt(2 / G)
    assert "right after event 1 (impact)" in text, text
    assert float(re.search(r"at t = ([0-9.eE+-]+) s", text).group(1)) == pytest.approx(t_impact, abs=1e-9)


# ---- found by the property suite ----------------------------------------------------------------

SWITCHING = [
    # (name, thrust fractions of m g, parameters): each failed before
    ("PogoStick", (0.0, 2.0), dict(method=5, abs_tol=1e-8, max_step=0.0)),
    ("PogoStickMem", (0.0, 1.125), dict(m=10 ** 0.75, k=1000.0, method=8, abs_tol=10 ** -8.5, max_step=0.0)),
    # the foot comes back to exactly z = 0 with zero speed at t = 0.03 s, where the thrust switches
    # off: the run-ahead step saw z touch 0 without crossing, and the touchdown was never handled
    ("PogoStick", (1.5, 0.0), dict(method=5, abs_tol=1e-8, max_step=0.0)),
    # the same with DOP853: a zero-length hop at t = 0.03 left z = -3e-18 m at the input change
    ("PogoStick", (1.5, 0.0), dict(method=8, abs_tol=1e-8, max_step=0.05)),
    # a step of 0.05 s holding a foot that dips below the ground and rises again (both ends above)
    ("PogoStick", (1.5, 0.23818687449414466), dict(method=5, rel_tol=1e-6, abs_tol=1e-8, max_step=0.05)),
]


@pytest.mark.parametrize("name, thrust, params", SWITCHING)
def test_switching_thrust_from_rest_at_the_free_length(name, thrust, params):
    """c = 0, from rest at the free length, F_ext switching every 10 ms between the fractions
    `thrust` of m g (found by the property suite and a scan of such runs).  Before: with
    max_step = 0 the exactly integrated flight grew the step tenfold per step (to 1e151 s) and a
    domain violation at t = 6e7 s was reported at t = 0.05 s; touchdowns were missed (a foot
    touching the ground at an input change, or dipping below it inside one step) and the mass
    fell through the ground.  Now the run completes, the foot never goes below the ground, and
    the energy balance E + W_leg = E(0) + W_ext holds."""
    params = dict(dict(m=1.0, k=100.0, rel_tol=1e-4), **params)
    m = params["m"]
    linear = dict(spring_law=0, beta=0.0) if name == "PogoStickMem" else {}
    inst = Instance(name).init(c=0.0, xbar_0=1.0, y_0=1.0, z_0=0.0, **linear, **params)
    try:
        E0 = inst.get("E")
        worst, ys = 0.0, []
        for i in range(200):
            inst.set(F_ext=thrust[i % 2] * m * G)
            inst.step(1e-2)
            E, W_leg, W_ext, y, z = inst.get("E", "W_leg", "W_ext", "y", "z")
            worst = max(worst, abs(E + W_leg - W_ext - E0))
            ys.append(y)
            assert z >= -1e-12, (inst.t, z)  # the foot never below the ground
    finally:
        inst.close()
    assert min(ys) > 0
    assert worst <= 1e-2 * E0


def test_penetration_dipping_below_zero_inside_a_step_is_a_liftoff():
    """Penetrator under a thrust cycling through (1.20, 1.5, 0.73, 0.5) m g every 10 ms, DOP853,
    max_step = 0 (found by a scan of such runs): a contact step whose two ends have delta > 0 held
    a dip to delta = -2.6e-6 m at t = 1.79 s (the foot above the surface in contact).  Now the
    liftoff/touchdown pair inside the step is found: delta >= 0 in contact, the foot height >= 0
    in flight at every communication point, and E + W_leg + W_soil = E(0) + W_ext."""
    thrust = (1.2021019646842688, 1.5, 0.728039827614527, 0.5)
    inst = Instance("Penetrator").init(rel_tol=1e-6, abs_tol=1e-9, max_step=0.0, method=8, y_0=1.0, c=2.0)
    try:
        E0 = inst.get("E")
        worst = 0.0
        for i in range(200):
            inst.set(F_ext=thrust[i % 4] * G)
            inst.step(1e-2)
            s, delta, z, E, W_leg, W_soil, W_ext = inst.get("s", "delta", "z", "E", "W_leg", "W_soil", "W_ext")
            assert (delta if s == 1 else z) >= -1e-9, (inst.t, s, delta, z)
            worst = max(worst, abs(E + W_leg + W_soil - W_ext - E0))
        assert inst.get("n_events") > 10
    finally:
        inst.close()
    assert worst <= 1e-5 * E0


ZENO_BALL = '''\
"""A ball with restitution 0.5 that bounces infinitely often before t = 3 sqrt(2 h0/g) (Zeno)."""
from pogofmu import FALLING, Event, HybridModel, Parameter, Variable

MODEL = HybridModel(
    name="ZenoBall", description="bouncing ball",
    states=(Variable("y", "m", "height above the floor"), Variable("v", "m/s", "velocity (up)")),
    parameters=(Parameter("e", 0.5, "", "coefficient of restitution"), Parameter("h0", 1.0, "m", "initial height")),
    inputs=(), outputs=(Variable("y", "m", "height above the floor"),),
    flow=lambda t, x, q, u, p: [x[1], -9.81],
    events=(Event("impact", FALLING, lambda x, q, u, p: x[0],
                  lambda x, q, u, p: ([0.0, -p.e * x[1]], dict(q, n=q["n"] + 1))),),
    initial=lambda p: ([p.h0, 0.0], {"n": 0}), output_fn=lambda t, x, q, u, p: {"y": x[0]})
'''


@pytest.fixture(scope="module")
def zeno_ball(tmp_path_factory):
    """ZENO_BALL exported as a user does it (``pogofmu export``, FMI 2.0): {backend: FMU path}."""
    from support import run_pogofmu

    folder = tmp_path_factory.mktemp("zeno")
    (folder / "zeno_ball.py").write_text(ZENO_BALL)
    proc = run_pogofmu("export", "zeno_ball.py", "--out", "out", "--fmi", "2", "--platforms", "x86_64-linux",
                       cwd=folder, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return {"python": folder / "out" / "ZenoBall.fmu", "native": folder / "out" / "native" / "ZenoBall.fmu"}


@pytest.mark.parametrize("backend", ["python", "native"])
def test_an_event_storm_inside_an_fmu_step_is_an_error_and_the_instance_is_restorable(zeno_ball, backend, tmp_path):
    """docs/errors.md: an event storm ends fmi2DoStep with fmi2Error naming it and the time, never a
    hang or Fatal; later steps are refused naming the cause; a state saved before restores and the
    instance steps on. Both kinds of FMU (one adapter), driven through fmpy's FMI 2.0 functions."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    from support import fmi2_callbacks

    path = zeno_ball[backend]
    md = read_model_description(str(path))
    y_vr = next(v.valueReference for v in md.modelVariables if v.name == "y")
    got = []
    keep = fmi2_callbacks(got)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path), str(tmp_path / "x")),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="ball")
    fmu.instantiate(loggingOn=True, callbacks=keep.struct)
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        t_zeno = 3 * math.sqrt(2 * 1.0 / G)
        fmu.doStep(0.0, 1.0)
        saved = fmu.getFMUState()
        with pytest.raises(FMICallException) as exc:
            fmu.doStep(1.0, 1.0)
        assert exc.value.status == ERROR, exc.value.status
        storm = [text for status, _, text in got if status == ERROR and "event storm" in text]
        assert storm and "impact" in storm[0], got[-3:]
        at = float(re.search(r"t = ([0-9.eE+-]+) s", storm[0]).group(1))
        assert at == pytest.approx(t_zeno, abs=1e-3), storm[0]
        with pytest.raises(FMICallException) as again:
            fmu.doStep(2.0, 0.1)
        assert again.value.status == ERROR, again.value.status
        assert "refused" in got[-1][2] and "event storm" in got[-1][2], got[-1]
        fmu.setFMUState(saved)  # back before the storm: the instance steps again
        fmu.doStep(1.0, 0.1)
        # after its first bounce at sqrt(2/g) s the ball flies up and falls again: above the floor at 1.1 s
        (y,) = fmu.getReal([y_vr])
        assert 0.0 < y < 1.0, y
        fmu.freeFMUState(saved)
    finally:
        fmu.freeInstance()


@pytest.mark.parametrize("backend", ["", "native/"], ids=["python", "native"])
def test_an_input_set_before_the_first_step_gives_the_bits_of_one_set_in_initialization_mode(backend):
    """F_ext = 5 N set in Instantiated, in Initialization Mode, or after fmi2ExitInitializationMode and
    before the first fmi2DoStep: the same problem, and now the same bits (the last was a restart at
    t = 0 that kept the first step estimated with the old input, 1.2817305327419086 against ...097)."""
    def run(when):
        inst = Instance(f"{backend}PogoStick")
        try:
            if when == "instantiated":
                inst.set(F_ext=5.0)
            inst.fmu.setupExperiment(startTime=0.0)
            inst.fmu.enterInitializationMode()
            if when == "initialization":
                inst.set(F_ext=5.0)
            inst.fmu.exitInitializationMode()
            if when == "before the first step":
                inst.set(F_ext=5.0)
            inst.run_to(1.0, 1e-3)
            return inst.get("y", "ydot")
        finally:
            inst.close()

    runs = {when: run(when) for when in ("instantiated", "initialization", "before the first step")}
    assert len({tuple(v) for v in runs.values()}) == 1, runs
