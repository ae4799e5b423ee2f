"""What every FMU in dist/ must satisfy; a new FMU joins by existing.

Validation, units and descriptions, the default experiment reaching its stop time, bad input
ending in an error status with a clear message while the host survives, FMU state round trips,
and agreement with an independent importer (libcosimpy).

The suite runs on both backends of the FMI 2.0 FMUs: the Python-hosted ones (``dist/<Model>.fmu``)
and the native ones (``dist/native/<Model>.fmu``), with the same expectations.
"""
import json
import math
import xml.etree.ElementTree as ET
import zipfile

import pytest

from pogofmu import exporter as build
from pogofmu.runtime.solver import SOLVER_PARAMETERS
from support import DIST, Instance, example_models, fmu_path, init_failure_text, model_of, run_libcosim, simulate

FMUS = build.model_names()
# the Python-hosted and the native FMU of every model: the project's, and the example files
# exported as a user's model (what this suite demands holds for any valid model)
EXAMPLES = [f"examples/{n}" for n in sorted(example_models())]
BOTH = FMUS + [f"native/{n}" for n in FMUS] + EXAMPLES + [f"examples/native/{n[9:]}" for n in EXAMPLES]


def model_description(name):
    with zipfile.ZipFile(fmu_path(name)) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


def slave_model(name):
    return model_of(name)


def native(name):
    return "native/" in name


def test_every_slave_was_built():
    assert FMUS, "no models in the registry"
    assert sorted(p.stem for p in DIST.glob("*.fmu")) == FMUS


@pytest.mark.parametrize("name", BOTH)
def test_fmpy_validation_reports_no_problem(name):
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(fmu_path(name))) == []


@pytest.mark.parametrize("name", BOTH)
def test_units_and_descriptions(name):
    root = model_description(name)
    defined = {u.get("name") for u in root.iter("Unit")}
    model = slave_model(name)
    declared = {v.name: v.unit for v in model.all_outputs() + model.inputs}
    declared.update({p.name: p.unit for p in model.parameters + SOLVER_PARAMETERS})
    n_with_unit = 0
    for sv in root.iter("ScalarVariable"):
        name_ = sv.get("name")
        assert sv.get("description"), f"{name_} has no description"
        real = sv.find("Real")
        if real is None:
            continue
        unit = real.get("unit")
        assert unit == (declared[name_] or None), f"{name_}: unit {unit!r} != model's {declared[name_]!r}"
        if unit:
            assert unit in defined, f"unit {unit} of {name_} missing from UnitDefinitions"
            n_with_unit += 1
    assert n_with_unit >= 5
    de = root.find("DefaultExperiment")
    assert de is not None and float(de.get("stopTime")) > 0 and float(de.get("stepSize")) > 0
    assert root.find("CoSimulation").get("canGetAndSetFMUstate") == "true"


@pytest.mark.parametrize("name", BOTH)
def test_default_experiment_reaches_stop_time(name):
    run = simulate(name)  # asserts the final time
    assert not run.errors
    for col in run.res.dtype.names:
        assert all(math.isfinite(v) for v in run.res[col]), f"{col} not finite"


@pytest.mark.parametrize("name", BOTH)
def test_nan_parameter_is_rejected_and_host_survives(name):
    model = slave_model(name)
    par = next(p for p in model.parameters if not p.integer)
    text = init_failure_text(name, **{par.name: float("nan")})  # fmi2Error, then reset and run
    assert f"parameter {par.name} = nan" in text and "finite" in text, text
    run = simulate(name, stop_time=0.1)  # and a fresh instance works
    assert run.res["time"][-1] == pytest.approx(0.1)


@pytest.mark.parametrize("name", BOTH)
def test_bad_step_and_nan_input_are_refused_instance_survives(name):
    from fmpy.fmi1 import FMICallException

    model = slave_model(name)
    inst = Instance(name).init()
    try:
        with pytest.raises(FMICallException) as exc:
            inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=-1e-3)
        assert "(error)" in str(exc.value)
        assert any("step_size = -0.001" in m[2] and "0 <= step_size" in m[2] for m in inst.messages)
        # a non-finite communication point or a step whose end is not finite is
        # refused at once (before: NaN/+inf/1e300 never returned, -inf returned OK doing nothing)
        for t, h, text in ((math.nan, 1e-3, "currentCommunicationPoint = nan"),
                           (math.inf, 1e-3, "currentCommunicationPoint = inf"),
                           (-math.inf, 1e-3, "currentCommunicationPoint = -inf"),
                           (0.0, math.inf, "step_size = inf"), (0.0, math.nan, "step_size = nan"),
                           (0.0, 1e300, "step_size = 1e+300")):
            if h == 1e300 and not model.states:
                # a model without states takes no internal steps: the step is
                # done at once, the outputs are those of the law at the held inputs
                saved = inst.fmu.getFMUstate()
                before = inst.outputs()
                inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=h)
                assert inst.outputs() == before
                # and the engine takes no internal step for it (counted, not timed)
                from pogofmu.runtime.solver import Simulator
                sim = Simulator(model)
                sim.advance(h)
                assert sim.n_steps == 0 and sim.t_out == h
                inst.fmu.setFMUstate(saved)
                inst.fmu.freeFMUstate(saved)
                continue
            with pytest.raises(FMICallException) as exc:
                inst.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            assert "(error)" in str(exc.value)
            assert text in inst.messages[-1][2], inst.messages[-1]
        for var in model.inputs:
            if var.name in model.integer_inputs:
                continue  # an FMI Integer cannot hold NaN
            inst.set(**{var.name: float("nan")})
            with pytest.raises(FMICallException):
                inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
            assert any(f"input {var.name} = nan" in m[2] for m in inst.messages), inst.messages
            inst.set(**{var.name: var.start})
        # the same instance goes on after the refused steps
        inst.run_to(0.05, 1e-3)
        assert inst.t == pytest.approx(0.05)
    finally:
        inst.close()


@pytest.mark.parametrize("name", BOTH)
def test_fmu_state_round_trip(name):
    """Save the state at several times, run on, restore, run again: identical outputs."""
    stop = 2.0
    inst = Instance(name).init()
    try:
        for t_save in (0.2, 0.5, 0.9, 1.3):
            inst.run_to(t_save, 1e-3)
            state = inst.fmu.getFMUstate()
            t0 = inst.t
            inst.run_to(t_save + 0.4, 1e-2)
            first = inst.outputs()
            inst.fmu.setFMUstate(state)
            inst.t = t0
            inst.run_to(t_save + 0.4, 1e-2)
            second = inst.outputs()
            assert first == second, f"{name}: state restored at t = {t_save} gives different outputs"
            inst.fmu.setFMUstate(state)  # restore again: the saved state is reusable
            inst.t = t0
            inst.fmu.freeFMUstate(state)
        inst.run_to(stop, 1e-2)
    finally:
        inst.close()


@pytest.mark.parametrize("name", BOTH)
def test_serialized_state_restores_bit_identically_in_a_fresh_instance(name):
    """fmi2SerializeFMUstate / fmi2DeSerializeFMUstate (canSerializeFMUstate = true): a state taken
    mid-run (integrator ahead of the communication point, events behind) and restored in another
    instance continues exactly as the original; foreign or damaged bytes are refused by name."""
    from fmpy.fmi1 import FMICallException

    a, b = Instance(name, "original").init(), Instance(name, "copy").init()
    try:
        a.run_to(0.73, 1e-3)
        blob = a.fmu.serializeFMUstate(a.fmu.getFMUstate())
        body, _, seal = bytes(blob).rpartition(b"\n")
        head = body.split(b"\n", 1)[0]  # (a header line, then the bytes: one format for both kinds, one adapter)
        assert json.loads(head)["owner"][0] == slave_model(name).name and len(seal) == 64  # the model, a seal
        b.fmu.setFMUstate(b.fmu.deSerializeFMUstate(blob))
        b.t = a.t
        assert b.outputs() == a.outputs()
        for inst in (a, b):
            inst.step(1e-4)  # served from the dense output of the step the integrator took ahead
            inst.run_to(2.0, 7e-3)
        assert a.outputs() == b.outputs(), f"{name}: the deserialized state runs differently"
        # (the project's runs have events by then; a user's model need not)
        assert a.get("n_events") > 0 or not slave_model(name).states or name.startswith("examples/")
        # a state of another model, and damaged bytes, are refused with fmi2Error and a reason
        other = next(n for n in (BOTH if native(name) else FMUS) if n != name and native(n) == native(name))
        c = Instance(other).init()
        foreign = c.fmu.serializeFMUstate(c.fmu.getFMUstate())
        c.close()
        for data, text in ((foreign, f"belongs to model '{slave_model(other).name}'"), (bytes(blob)[:-7], "damaged"),
                           (b"garbage", "not a serialized pogofmu FMU state")):
            with pytest.raises(FMICallException):
                b.fmu.deSerializeFMUstate(data)
            assert text in b.messages[-1][2], b.messages[-1]
        b.run_to(2.5, 7e-3)  # the refused calls left the instance usable
    finally:
        a.close()
        b.close()


@pytest.mark.parametrize("name", [n for n in BOTH if native(n)])
def test_a_native_state_holds_its_models_arrays_not_the_engines_maxima(name):
    """fmi2GetFMUstate copies the whole instance, so its size is the cost of every save (a
    synchronized master saves each component before each step). A native FMU's arrays are sized to
    its model (pg_sizes.h): its state is far below what five arrays of the engine's maximum input
    count alone would take (the state's inputs and their slopes, the engine's inputs, slopes and
    inputs at a model call: 40 kB), where the engine's maxima made it 76 kB."""
    from pogofmu.exporter.export import engine_limits

    inst = Instance(name).init()
    try:
        inst.run_to(0.1, 1e-3)
        size = len(bytes(inst.fmu.serializeFMUstate(inst.fmu.getFMUstate())))
    finally:
        inst.close()
    assert size < 5 * engine_limits()["U"] * 8, f"{name}: a serialized state of {size} bytes"


@pytest.mark.parametrize("name", FMUS + EXAMPLES)
def test_libcosimpy_agrees_with_fmpy(name):
    model = slave_model(name)
    outputs = [v.name for v in model.all_outputs()]
    stop, step = 2.0, 1e-3
    ref = simulate(name, stop_time=stop, output_interval=step)
    got = run_libcosim(name, stop, step, outputs)
    assert got.pop("_ok")
    for out in outputs:
        # (libcosim's communication points are sums of steps, fmpy's multiples: where a run restarts its
        # integrator at them the two agree to the solver's tolerance, not to the bit — the mirror
        # actuator's stops and gust: 2e-8 relative at rel_tol 1e-6; the project's models to 1e-9)
        rel = 1e-7 if name.startswith("examples/") else 1e-9
        assert got[out] == pytest.approx(float(ref.res[out][-1]), rel=rel, abs=1e-12), out


@pytest.mark.parametrize("name", FMUS + EXAMPLES)
def test_master_script_writes_results_and_every_figure(name, tmp_path):
    """The fmpy master script: time series, event table and each figure the model asks for
    (force-deflection loops, time histories; its outputs against time if it names none), drawn
    from outputs that exist, for the project's models and a user's alike."""
    from pogofmu import experiments

    folder = DIST / name.rpartition("/")[0] if "/" in name else DIST
    stem = name.rpartition("/")[2]
    experiments.run(folder, tmp_path, [stem])
    model = experiments.model_of(folder / f"{stem}.fmu")
    assert model is not None and model.name == stem
    recorded = {v.name for v in model.all_outputs()} | ({v.name for v in model.inputs} if model.default_input else set())
    plots = model.plots or experiments.default_plots(model)
    signals = [n for fig in plots for panel in fig for n in (panel[1:4] if panel[0] == "vs" else panel)]
    assert signals and all(n in recorded for n in signals), signals
    out = tmp_path / stem
    rows = round(model.default_stop_time / model.default_step)
    assert (out / "timeseries.csv").read_text().count("\n") > min(1000, rows)
    pngs = sorted(out.glob("figure*.png"))
    assert len(pngs) == len(plots) and all(p.stat().st_size > 10_000 for p in pngs)
    rows = (out / "events.csv").read_text().splitlines()
    run = simulate(name) if model.default_input is None else None  # (else the run has the default inputs)
    if run is not None:
        assert len(rows) - 1 == len({int(n) for n in run["n_events"] if n > 0})
    import csv

    with (out / "timeseries.csv").open() as f:
        counts = [int(float(r["n_events"])) for r in csv.DictReader(f)]
    assert len(rows) - 1 == counts[-1]


# the loops the issues ask for: force-deflection (mem-spring pinched, SMA flag) and the soil's
# Hunt-Crossley hysteresis
LOOPS = {"PogoStickMem": ("x", "r"), "PogoStickSMA": ("x", "r"), "Penetrator": ("delta", "F_soil")}


@pytest.mark.parametrize("name, loop", sorted(LOOPS.items()))
def test_loop_figures_asked_for_by_the_issues(name, loop):
    model = slave_model(name)
    assert any(panel[:3] == ("vs",) + loop for fig in model.plots for panel in fig)


@pytest.mark.parametrize("name", BOTH)
def test_default_experiment_declares_the_default_rel_tol(name):
    """The tolerance an importer passes becomes rel_tol (tests/test_tolerance.py), so the declared
    one is the default rel_tol: fmpy, which passes it, runs the FMU as an importer passing none."""
    from pogofmu.runtime.solver import solver_defaults

    de = model_description(name).find("DefaultExperiment")
    assert float(de.get("tolerance")) == solver_defaults()["rel_tol"]


def test_an_importer_in_model_exchange_puts_the_contacts_at_the_closed_form_to_its_tolerance():
    """fmpy's model exchange with no tolerance given reads DefaultExperiment's (1e-6): the
    PogoStick's contacts within 3e-4 s of the closed form; given 1e-10, within 3e-7 s (docs/fmi3.md:
    9.9e-5 s and 6.8e-8 s)."""
    from fmpy import simulate_fmu

    from support import parse_event_log, reference_events

    ref = [e["time"] for e in reference_events()]

    def error(**kwargs):
        messages = []
        simulate_fmu(str(fmu_path("fmi3/PogoStick")), fmi_type="ModelExchange", stop_time=10, output_interval=1e-3,
                     start_values={"log_events": 1}, debug_logging=True,
                     logger=lambda *a: messages.append((a[-3], a[-2].decode(), a[-1].decode())), **kwargs)
        got = [e["time"] for e in parse_event_log(messages)]
        assert len(got) == len(ref) == 19
        return max(abs(a - b) for a, b in zip(got, ref))

    declared, tight = error(), error(relative_tolerance=1e-10)
    assert tight < 3e-7 and declared < 3e-4 and tight < declared / 100, (tight, declared)


def _initial_outputs(name, **params):
    inst = Instance(name)
    try:
        inst.init(**params)
        return inst.outputs()
    finally:
        inst.close()


@pytest.mark.parametrize("name", [n for n in BOTH if native(n)])
def test_initial_unknowns_declare_exactly_the_parameters_they_depend_on(name):
    """Each parameter moved alone before initialization changes exactly the initial outputs that
    declare it (InitialUnknowns' dependencies, read by fmpy as an importer does), through the FMU."""
    from fmpy import read_model_description

    md = read_model_description(str(fmu_path(name)))
    declared = {u.variable.name: {d.name for d in u.dependencies} for u in md.initialUnknowns}
    assert all(u.dependencies is not None for u in md.initialUnknowns)
    base = _initial_outputs(name)
    model = slave_model(name)
    seen = {n: set() for n in declared}
    for par in model.parameters:
        v = par.default
        for moved in ((v + 1, v - 1) if par.integer else (v * (1 + 1e-3) + 1e-3, v * (1 - 1e-3) - 1e-3)):
            try:
                got = _initial_outputs(name, **{par.name: moved})
            except Exception:  # noqa: BLE001 - a moved value that breaks a rule: no information
                continue
            for n in declared:
                if got[n] != base[n]:
                    seen[n].add(par.name)
    for n in declared:
        params = declared[n] & {p.name for p in model.parameters}
        assert seen[n] <= params, f"{name}: {n} changed with {seen[n] - params}, not declared"


def _symbolic_units(name):
    return any("^n" in (v.unit or "") for v in slave_model(name).parameters)


@pytest.mark.parametrize("name", [n for n in BOTH if not native(n) and not _symbolic_units(n)])
def test_syssimx_reads_the_model_structure(name):
    """syssimx reads the dependencies of every Outputs and InitialUnknowns entry (it crashed on an
    InitialUnknown without them). (A Hunt-Crossley stiffness's unit N/m^n, whose exponent is a
    parameter, is not a unit pint parses: docs/known-issues.md.)"""
    from syssimx.components.fmu import FMUComponent

    comp = FMUComponent("c", str(fmu_path(name)))
    assert set(comp.model_structure["initialUnknowns"]) == {v.name for v in slave_model(name).all_outputs()}
