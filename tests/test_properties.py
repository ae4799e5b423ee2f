"""Property-based tests (hypothesis) over every FMU's parameters, through the built FMUs.

* **valid** parameter sets (physical ranges where the leg cannot bottom out and no time scale is
  faster than 1e-4 s, any solver settings within the rules) run to the stop time with finite
  outputs and the energy balance ``E + W_leg (+ W_soil) = E(0) + W_ext`` within a tolerance set
  by the solver tolerances (HopController: the law's invariants instead);
* **invalid** sets (one rule broken: a sign, a range, NaN/inf, an inconsistent start, a solver
  knob; every rule of every FMU its own test case) end in fmi2Error at initialization with a
  message naming the parameter;
* **wide** sets (valid sets with up to three parameters scaled by any magnitude from 1e-12 to
  1e12, either sign) either complete with finite outputs or end in a message naming a variable
  and its rule, or a physical condition and the time -- never a raw Python error, never a hang
  (the work budget bounds every run); at least half of them get past the rules into the engine;
* **physics**: random valid sticks have the events of an independent scipy model of their
  equations (which a wrong force law fails; the energy balance cannot tell).

Budget: ``POGOFMU_FUZZ`` unset (CI) runs a few derandomized examples per test (seconds);
``POGOFMU_FUZZ=long`` runs 200 random examples per test (minutes).
"""
import math
import os
import re
from functools import lru_cache

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from parameter_sets import THRUST, logf, penetrator_params, stick_params
from references import reference_stick
from support import Instance, example_models, fmu_path, model_of

LONG = os.environ.get("POGOFMU_FUZZ", "") == "long"
FUZZ = settings(max_examples=200 if LONG else 20, deadline=None, derandomize=not LONG, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much], print_blob=True)
RAW = ("Traceback", "Error:", "ZeroDivision", "Overflow", "division by zero", "math domain", "object")
STICKS = ("PogoStick", "PogoStickMem", "PogoStickSMA")
STOP, STEP = 2.0, 0.01


@lru_cache(maxsize=None)
def _unzipped(name):
    from fmpy import extract

    return extract(str(fmu_path(name)))


def _run(name, params, stop=STOP, step=STEP, inputs=None, outputs=("E", "W_leg", "W_ext")):
    """Initialize with ``params`` and step to ``stop``; return ``(None, {output: [values]})`` or
    ``(message text, partial outputs)`` if a call fails.  The instance is always freed."""
    from fmpy.fmi1 import FMICallException

    inst = Instance(name, unzip_dir=_unzipped(name))
    rec = {n: [] for n in outputs}
    try:
        try:
            inst.init(**params)
            for n in outputs:
                rec[n].append(inst.get(n))
            k = 0
            while inst.t < stop - 1e-9:
                if inputs is not None:
                    inst.set(**inputs[k % len(inputs)])
                inst.step(step)
                k += 1
                for n in outputs:
                    rec[n].append(inst.get(n))
        except FMICallException as exc:
            assert "(error)" in str(exc), exc  # fmi2Error, never fmi2Fatal: the instance stays usable
            text = "\n".join(m[2] for m in inst.messages if m[0] >= 3)
            return text or str(exc), rec
        return None, rec
    finally:
        inst.close()


def _check_valid_run(name, p, soil=False, thrust=()):
    scale = p.pop("_scale")
    outputs = ("E", "W_leg", "W_ext") + (("W_soil",) if soil else ())
    inputs = [{"F_ext": f * p["m"] * p["g"]} for f in thrust] or None
    err, rec = _run(name, p, outputs=outputs, inputs=inputs)
    if os.environ.get("POGOFMU_FUZZ_TRACE"):
        print(name, len(rec["E"]), p)
    assert err is None, f"{name} {p}: {err}"
    for n, values in rec.items():
        assert all(math.isfinite(v) for v in values), (n, p)
    E0 = rec["E"][0]
    works = [rec["W_leg"], rec["W_ext"]] + ([rec["W_soil"]] if soil else [])
    ref = max(abs(E0), max(abs(v) for w in [rec["E"]] + works for v in w))
    residual = max(abs(e + wl + (ws if soil else 0.0) - wx - E0) for e, wl, wx, ws in
                   zip(rec["E"], rec["W_leg"], rec["W_ext"], rec["W_soil"] if soil else rec["E"]))
    tol = 100 * (p["rel_tol"] + p["abs_tol"] / scale) * ref + 1e-12 * ref
    assert residual <= tol, f"{name} {p}: energy residual {residual:.3g} J > {tol:.3g} J"


@pytest.mark.parametrize("name", STICKS)
def test_valid_stick_parameters_give_a_result(name):
    @FUZZ
    @given(stick_params(name))
    def check(p):
        _check_valid_run(name, p)

    check()


@pytest.mark.parametrize("name", STICKS)
def test_valid_stick_parameters_with_thrust_give_a_result(name):
    @FUZZ
    @given(stick_params(name), THRUST)
    def check(p, thrust):
        _check_valid_run(name, p, thrust=thrust)

    check()


@FUZZ
@given(penetrator_params(), st.just(()) | THRUST)
def test_valid_penetrator_parameters_give_a_result(p, thrust):
    _check_valid_run("Penetrator", p, soil=True, thrust=thrust)


HOP_INPUTS = st.lists(st.fixed_dictionaries({"y": st.floats(0.1, 3.0), "ydot": st.floats(-5.0, 5.0),
                                             "s": st.sampled_from([0, 1])}), min_size=1, max_size=20)


@FUZZ
@given(p=st.fixed_dictionaries({
    "x_i": st.floats(0.2, 2.0), "tau_E": logf(1e-3, 1.0), "K_D": st.floats(0.0, 2.0), "F_max": logf(1.0, 100.0),
    "m": logf(0.1, 10.0), "g": logf(0.1, 30.0), "k": logf(10.0, 1e4), "c": st.floats(0.0, 5.0),
    "max_step": st.sampled_from([0.0, 0.01, 1e-4])}), dh=st.floats(0.01, 2.0), inputs=HOP_INPUTS)
def test_valid_hop_controller_parameters_give_the_law(p, dh, inputs):
    """The law's invariants (MODELS/README): thrust in [0, F_max], zero unless extending in contact,
    E_est = m ydot^2/2 + m g y + s k (y - x_i)^2/2 and E_err = m g h_target - E_est."""
    p = dict(p, h_target=p["x_i"] + dh)
    outputs = ("F_ext", "E_est", "E_err")
    err, rec = _run("HopController", p, stop=len(inputs) * 1e-3, step=1e-3, inputs=inputs, outputs=outputs)
    assert err is None, err
    for u, F, E, e in zip(inputs, rec["F_ext"][1:], rec["E_est"][1:], rec["E_err"][1:]):
        assert 0.0 <= F <= p["F_max"]
        if not (u["s"] == 1 and u["ydot"] > 0):
            assert F == 0.0
        E_ref = p["m"] * u["ydot"] ** 2 / 2 + p["m"] * p["g"] * u["y"] + u["s"] * p["k"] * (u["y"] - p["x_i"]) ** 2 / 2
        assert E == pytest.approx(E_ref, rel=1e-12, abs=1e-12)
        assert e == pytest.approx(p["m"] * p["g"] * p["h_target"] - E_ref, rel=1e-9, abs=1e-9)


# ---- invalid parameters: one rule broken, the message names it -----------------------------------

BAD_NUMBER = st.sampled_from([math.nan, math.inf, -math.inf])
NEG = st.floats(-1e6, 0.0, exclude_max=False).filter(lambda v: v <= 0.0)

# (parameter, strategy for a value that breaks a rule, names the message may report)
BREAKERS = {
    "common": [
        ("rel_tol", st.sampled_from([0.0, 1e-15, 0.5, 2e-3, -1e-6]), ("rel_tol",)),
        ("abs_tol", st.floats(-1.0, 0.0) | st.floats(1.0, 1e3), ("abs_tol",)),
        ("max_step", st.floats(-1.0, -1e-9) | st.floats(1e-12, 1e-6), ("max_step",)),
        ("initial_step", st.floats(-1.0, -1e-9), ("initial_step",)),
        ("method", st.integers(-3, 12).filter(lambda v: v not in (0, 1, 5, 8)), ("method",)),
        ("log_events", st.integers(2, 9) | st.integers(-9, -1), ("log_events",)),
        ("max_steps_per_second", st.floats(-1e3, 9.0), ("max_steps_per_second",)),
    ],
    "stick": [
        ("m", NEG, ("m",)), ("x_i", NEG, ("x_i", "xbar_0")), ("g", st.floats(-1e3, -1e-9), ("g",)),
        ("c", st.floats(-1e3, -1e-9), ("c",)), ("y_0", NEG, ("y_0", "z_0")),
        ("z_0", st.floats(0.1, 5.0).filter(lambda v: v != 0.5), ("z_0",)), ("xdot_0", st.floats(0.1, 5.0), ("xdot_0",)),
    ],
    "PogoStick": [("k", st.floats(-1e3, -1e-9), ("k",))],
    "PogoStickMem": [("k", st.floats(-1e3, -1e-9), ("k",)), ("beta", st.floats(-1e3, -1e-9), ("beta",)),
                     ("gamma", st.floats(-1e3, -1e-9), ("gamma",)), ("spring_law", st.integers(3, 9), ("spring_law",))],
    "PogoStickSMA": [("k2", st.floats(100.0, 1e3), ("k2",)), ("k2", NEG, ("k2",)),
                     ("x3", st.floats(0.0, 1.0), ("x3", "x1")), ("x1", st.floats(-0.1, 1.0), ("x1",))],
    "Penetrator": [("m", NEG, ("m",)), ("c", NEG, ("c",)), ("k", st.floats(-1e3, -1e-9), ("k",)),
                   ("K", st.floats(-1e3, -1e-9), ("K",)), ("n", st.floats(-2.0, 0.999), ("n",)),
                   ("c_r", st.floats(1.001, 5.0) | st.floats(-5.0, -1e-3), ("c_r",)),
                   ("d0dot", NEG, ("d0dot",)), ("d0dot_from_impact", st.integers(2, 9), ("d0dot_from_impact",)),
                   ("y_0", NEG, ("y_0",)), ("x_i", NEG, ("x_i",))],
    "HopController": [("h_target", st.floats(-1.0, 1.0), ("h_target",)), ("tau_E", NEG, ("tau_E",)),
                      ("F_max", NEG, ("F_max",)), ("K_D", st.floats(-5.0, -1e-9), ("K_D",)),
                      ("m", NEG, ("m",))],
}
_SOLVER_FLOATS = ["rel_tol", "abs_tol", "max_step"]
_STICK_FLOATS = ["m", "c", "x_i", "g", "y_0", "ydot_0"] + _SOLVER_FLOATS
FLOAT_PARAMS = {"PogoStick": _STICK_FLOATS + ["k"], "PogoStickMem": _STICK_FLOATS + ["k", "beta", "gamma", "a_0"],
                "PogoStickSMA": _STICK_FLOATS + ["k1", "k2", "x1", "x3"],
                "Penetrator": ["m", "k", "c", "x_i", "g", "K", "n", "c_r", "d0dot", "y_0", "ydot_0"] + _SOLVER_FLOATS,
                "HopController": ["h_target", "tau_E", "F_max", "K_D", "m", "g", "k", "c", "x_i"] + _SOLVER_FLOATS}


def breakers(name):
    out = BREAKERS["common"] + BREAKERS.get(name, [])
    if name in STICKS:
        out += BREAKERS["stick"]
    if name == "HopController":  # no states: abs_tol and max_step are unused, only their signs are rules
        out = [b if b[0] not in ("abs_tol", "max_step") else (b[0], st.floats(-1.0, -1e-9), b[2]) for b in out]
    # max_step = inf is valid (unbounded, as 0): only NaN and -inf break its rules
    out += [(f, st.sampled_from([math.nan, -math.inf]) if f == "max_step" else BAD_NUMBER, (f,))
            for f in FLOAT_PARAMS[name]]
    return out


ALL_FMUS = STICKS + ("Penetrator", "HopController")


RULES = [(name, i) for name in ALL_FMUS for i in range(len(breakers(name)))]


@pytest.mark.parametrize("name,i", RULES, ids=[f"{n}-{breakers(n)[i][0]}-{i}" for n, i in RULES])
def test_each_parameter_rule_is_refused_naming_the_parameter(name, i):
    """Each rule of each FMU its own case (a few values drawn for it): the FMU refuses the set at
    initialization with fmi2Error, the message names the parameter, says which rule it violates,
    and holds no raw Python error."""
    param, values, names = breakers(name)[i]

    @settings(FUZZ, max_examples=50 if LONG else 3)
    @given(values)
    def check(value):
        err, _ = _run(name, {param: value}, stop=0.02)
        assert err is not None, f"{name}: {param} = {value!r} was accepted"
        assert any(re.search(rf"\b{re.escape(n)} = ", err) for n in names), (param, value, err)
        assert "violate" in err, err
        assert not any(raw in err for raw in RAW), err

    check()


def generic_breakers(model):
    """The rules every FMU has, whatever its model: the solver settings' (the model's rules aside),
    and a finite value of every float parameter."""
    floats = [p.name for p in model.parameters if not p.integer]
    # (abs_tol too large for the motion is a rule of the models that state their scales: here only its sign)
    signs_only = ("abs_tol", "max_step") if not model.states else ("abs_tol",)  # (no states: only their signs)
    common = [b if b[0] not in signs_only else (b[0], st.floats(-1.0, -1e-9), b[2]) for b in BREAKERS["common"]]
    return common + [(f, BAD_NUMBER, (f,)) for f in floats]


EXAMPLE_RULES = [(f"examples/{n}", i) for n, m in sorted(example_models().items())
                 for i in range(len(generic_breakers(m)))]


@pytest.mark.parametrize("name,i", EXAMPLE_RULES,
                         ids=[f"{n}-{generic_breakers(model_of(n))[i][0]}-{i}" for n, i in EXAMPLE_RULES])
def test_the_rules_every_fmu_has_hold_for_a_users_model(name, i):
    """The example files, exported as a user's model is: every rule that holds for any model (the
    solver's settings, finite parameters) refused at initialization naming the parameter."""
    param, values, names = generic_breakers(model_of(name))[i]

    @settings(FUZZ, max_examples=3)
    @given(values)
    def check(value):
        err, _ = _run(name, {param: value}, stop=0.02, outputs=())
        assert err is not None, f"{name}: {param} = {value!r} was accepted"
        assert any(re.search(rf"\b{re.escape(n)} = ", err) for n in names), (param, value, err)
        assert "violate" in err, err
        assert not any(raw in err for raw in RAW), err

    check()


# ---- wide fuzz: anything within reach, a result or a clear answer ---------------------------------

WIDE = st.floats(-12, 12).map(lambda e: 10.0 ** e)

CLEAR = re.compile(r"(parameters? .*\b\w+ = .* violates? the rule)|(\bt = [0-9.eE+-]+ s)"
                   r"|(most extreme magnitude: \w+ = )")


# parameters whose rules tie them to each other are scaled together (else nearly every scaling of
# one breaks a rule and the fuzz never reaches the engine): the SMA's plateau corners x3 < x1 < 0
# keep their order, its stiffnesses k2 < k1 theirs
TOGETHER = {"PogoStickSMA": {"x1": ("x1", "x3"), "x3": ("x1", "x3"), "k1": ("k1", "k2"), "k2": ("k1", "k2")}}
FACTOR = st.tuples(st.sampled_from([1.0] * 7 + [-1.0]), WIDE).map(lambda t: t[0] * t[1])  # 1 in 8 negated
VALID = {**{n: stick_params(n) for n in STICKS}, "Penetrator": penetrator_params(),
         "HopController": st.fixed_dictionaries({
             "x_i": st.floats(0.2, 2.0), "tau_E": logf(1e-3, 1.0), "K_D": st.floats(0.0, 2.0), "F_max": logf(1.0, 100.0),
             "m": logf(0.1, 10.0), "g": logf(0.1, 30.0), "k": logf(10.0, 1e4), "c": st.floats(0.0, 5.0),
             "_scale": st.just(1.0)}).map(lambda p: dict(p, h_target=p["x_i"] + 0.5))}


@pytest.mark.parametrize("name", ALL_FMUS)
def test_any_parameters_give_a_result_or_a_clear_message(name):
    """Wide fuzz around valid sets: a valid set with one to three of its parameters scaled by any
    factor from 1e-12 to 1e12 (one in eight negated) and any tolerances. Each run completes
    with finite outputs or ends in a message naming a variable and its rule, or a physical
    condition and the time — never a raw Python error, never a hang; and most sets get past the
    rules into the integrator (at least half of them: the fuzz exercises the engine, not only
    the checks)."""
    floats = [f for f in FLOAT_PARAMS[name] if f not in _SOLVER_FLOATS]
    reached = []

    @settings(FUZZ, max_examples=200 if LONG else 40)  # (the share that reaches the engine is judged)
    @given(VALID[name], st.dictionaries(st.sampled_from(floats), FACTOR, min_size=1, max_size=3),
           st.fixed_dictionaries({"rel_tol": logf(1e-14, 1e-3), "abs_tol": logf(1e-300, 1e-6)}))
    def check(valid, factors, tols):
        p = dict(valid, **tols)
        scale = p.pop("_scale")
        p["abs_tol"] = min(p["abs_tol"], 1e-3 * scale)  # (the tolerances' own rules: the rule cases above)
        for f, factor in factors.items():
            for g in TOGETHER.get(name, {}).get(f, (f,)):  # the SMA's flag: its corners move together
                p[g] = p.get(g, 1.0) * factor
        if name in STICKS:  # a start consistent with the scaled sizes: flight above x_i, else contact
            if p["y_0"] > p["x_i"]:
                p.update(xbar_0=p["x_i"], xdot_0=0.0, z_0=p["y_0"] - p["x_i"])
            else:
                p.update(xbar_0=p["y_0"], xdot_0=p["ydot_0"], z_0=0.0)
        outputs = ("y",) if name != "HopController" else ("F_ext",)
        err, rec = _run(name, p, stop=1.0, step=0.05, outputs=outputs)
        if os.environ.get("POGOFMU_FUZZ_TRACE"):
            print("WIDE", name, "OK" if err is None else err.splitlines()[-1][:230])
        if err is None:
            assert all(math.isfinite(v) for v in rec[outputs[0]]), (p, rec)
        else:
            assert CLEAR.search(err), (p, err)
            assert not any(raw in err for raw in RAW), (p, err)
        reached.append(err is None or " violate" not in err)  # past initialization's rules

    check()
    if os.environ.get("POGOFMU_FUZZ_TRACE"):
        print("REACHED", name, sum(reached), "of", len(reached))
    assert sum(reached) >= len(reached) / 2, f"{name}: {sum(reached)} of {len(reached)} sets reached the integrator"


# ---- physics on random valid sets: the FMU's events against an independent model --------------
# The energy balance above holds for any leg law (W_leg is the work of the same force the mass
# feels), so it cannot catch a wrong force law. Here each stick's equations are written again,
# directly from docs/models.md (flight: free fall, the leg at rest; contact: the leg's force on
# the mass, m ydot' = -r - m g; the SMA's flag as one branch per mode): the flight in closed form,
# the contact integrated by scipy's DOP853 at rtol 1e-12 with terminal events; the FMU runs the
# same random set at a tight tolerance, and every event's name and time must agree (a 1 % error in
# a spring constant moves a liftoff by ~1e-3 s; the tolerance is 2e-8 s: the largest disagreements
# seen are 1.1e-8 s, after 15 events of a stiff random leg in 4 s, and 1.4e-8 s after 18 events of
# a soft one, at rel_tol 1e-11 against scipy's 1e-12; at least 8 random sticks must reach the
# comparison).

PHYSICS_TIGHT = {"method": 8, "rel_tol": 1e-11}
PHYSICS_STOP = 4.0  # s: most random drops touch down and lift off within it



@pytest.mark.parametrize("name", STICKS)
def test_random_valid_sticks_have_the_independent_models_events(name):
    from hypothesis import reject

    accepted = []

    @settings(FUZZ, max_examples=200 if LONG else 12, phases=[Phase.explicit, Phase.reuse, Phase.generate])
    @given(stick_params(name))  # (no shrinking: each example is a run of a few seconds)
    def check(p):
        p.pop("_scale")
        p.update(PHYSICS_TIGHT, abs_tol=min(p["abs_tol"], 1e-9 * p["x_i"]))
        if p["z_0"] == 0 and p["x_i"] - p["xbar_0"] < 1e-6 * p["x_i"]:
            reject()  # a contact start on the liftoff guard: the reference cannot see an event at t = 0
        worst = _worst_against_reference(name, p)
        if worst is None:
            reject()  # no event to compare (or a reload, which the reference does not model)
        accepted.append(worst)

    check()
    assert len(accepted) >= 8, f"only {len(accepted)} random sticks reached the comparison"


def _worst_against_reference(name, p):
    """The FMU's events against the reference's: the same names in the same order, and the largest
    difference of their times (asserted under 2e-8 s); None where the reference cannot judge."""
    from support import simulate

    ref = reference_stick(name, p, PHYSICS_STOP)
    if not ref:
        return None
    run = simulate(name, start_values=dict(p, log_events=1), stop_time=PHYSICS_STOP, output_interval=0.05)
    got = [(e["name"], e["time"]) for e in run.events()]
    inner = lambda evs: [e for e in evs if e[1] < PHYSICS_STOP - 1e-6]  # noqa: E731
    assert [n for n, _ in inner(got)] == [n for n, _ in inner(ref)], (p, got, ref)
    worst = max((abs(a[1] - b[1]) for a, b in zip(inner(got), inner(ref))), default=0.0)
    if os.environ.get("POGOFMU_FUZZ_TRACE"):
        print("PHYSICS", name, len(inner(got)), f"{worst:.2e}")
    assert worst < 2e-8, (p, worst, got, ref)
    return worst


def test_a_flight_inside_one_step_of_the_reference():
    """Found by the long fuzz (2026-12-06): this mem-leg stick's last bounce lifts off at 1.2 mm/s
    and flies 2 v/g = 6.5 ms, inside one 10 ms step of scipy, whose event search then reported the
    touchdown at the liftoff itself (z = 0 at both ends of its bracket). The FMU was right; the
    reference's flight is now the closed form. Both must see the 6.5 ms flight."""
    p = {"m": 0.4641588833612779, "x_i": 1.490766316677516, "g": 0.37456700427643586,
         "c": 0.6642379509758357, "max_step": 0.05, "abs_tol": 8.576289160403522e-10, "k": 457.5414682648723,
         "spring_law": 2, "beta": 0.3128820328162569, "gamma": 0.95604409949401, "a_0": -9.907643076933816e-112,
         "xbar_0": 1.490766316677516, "xdot_0": 0.0, "y_0": 1.4922570829941935, "z_0": 0.001490766316677516,
         "ydot_0": -4.286689423471293e-60, **PHYSICS_TIGHT}
    assert _worst_against_reference("PogoStickMem", p) is not None
    ref = reference_stick("PogoStickMem", p, PHYSICS_STOP)
    flights = [b[1] - a[1] for a, b in zip(ref, ref[1:]) if (a[0], b[0]) == ("liftoff", "touchdown")]
    assert min(flights) > 6e-3, flights


def test_a_liftoff_inside_one_contact_step_of_the_reference():
    """Found by CI (2026-12-06): this SMA stick, in a slow contact at g = 1, lifts off at 2.6 mm/s
    and lands 5.3 ms later; the leg's excursion over its rest length (3.4 um) starts and ends inside
    one 10 ms step of scipy, whose sign check at step ends did not see it. The FMU was right; the
    reference now also locates a guard on xbar that is on its after side where xbar turns. Both
    must see the 5.3 ms flight."""
    p = {"m": 5.6217166434568195, "x_i": 0.7475408204592973, "g": 1.0, "c": 3.0, "method": 5,
         "max_step": 0.01, "abs_tol": 1e-13, "k1": 2799.5051021368517, "k2": 2208.5866915040483,
         "x1": -0.08020296884695541, "x3": -0.0356641542934129, "xbar_0": 0.7411877517647752,
         "xdot_0": -2.1221177661295474e-191, "y_0": 0.7411877517647752, "z_0": 0.0,
         "ydot_0": -2.1221177661295474e-191, **PHYSICS_TIGHT}
    p["abs_tol"] = min(p["abs_tol"], 1e-9 * p["x_i"])
    assert _worst_against_reference("PogoStickSMA", p) is not None
    ref = reference_stick("PogoStickSMA", p, PHYSICS_STOP)
    flights = [b[1] - a[1] for a, b in zip(ref, ref[1:]) if (a[0], b[0]) == ("liftoff", "touchdown")]
    assert 5e-3 < min(flights) < 6e-3, flights


def test_the_physics_check_catches_a_one_percent_spring_error():
    """The check above can fail: the reference with k 1 % too stiff disagrees with the FMU."""
    from support import simulate

    p = dict(m=1.0, g=9.81, x_i=1.0, c=0.5, k=100.0, xbar_0=1.0, xdot_0=0.0, y_0=1.5, z_0=0.5, ydot_0=0.0,
             **PHYSICS_TIGHT, abs_tol=1e-12)
    run = simulate("PogoStick", start_values=dict(p, log_events=1), stop_time=STOP, output_interval=0.05)
    got = [t for _, t in ((e["name"], e["time"]) for e in run.events())]
    right = [t for _, t in reference_stick("PogoStick", p, STOP)]
    wrong = [t for _, t in reference_stick("PogoStick", dict(p, k=101.0), STOP)]
    assert max(abs(a - b) for a, b in zip(got, right)) < 1e-9
    assert max(abs(a - b) for a, b in zip(got, wrong)) > 1e-4
