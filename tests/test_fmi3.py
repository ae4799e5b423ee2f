"""The FMI 3.0 FMUs (dist/fmi3/<Model>.fmu), as users run them.

* model exchange through fmpy's CVode: PogoStick's events against the closed-form reference,
  the other models' events against the FMI 2.0 FMUs' (whose engine is independent of CVode);
* co-simulation with event mode and early return, through fmpy and through a C host without
  Python: every ``lastSuccessfulTime`` is an FMI 2.0 event time to 1e-12 s;
* the event-indicator logic of model exchange driven by hand (direction, restart rule, flags);
* conformance: validation, the FMI 2.0 variables unchanged, bad parameters, FMU state round trips,
  several FMI 2.0 and 3.0 FMUs in one fresh process.

Every test runs on both backends: the Python-hosted FMUs (dist/fmi3/) and the native ones
(dist/native/fmi3/), which tests/test_native_fmu.py also compares with each other.
"""
import ctypes
import json
import math
import subprocess
import zipfile
from functools import lru_cache

import numpy as np
import pytest

from pogofmu import exporter as build
from support import DIST, ROOT, compile_c_host, fmu_path, parse_event_log, reference_events, simulate

MODELS = {name: build.slave_class(name).model for name in build.model_names()}
FMUS = sorted(MODELS)
# the models whose co-simulation steps hold events (a model without states switches only with its inputs)
WITH_EVENTS = sorted(name for name, model in MODELS.items() if model.events and model.states)
C_HOST_SOURCE = ROOT / "tests" / "c_host" / "fmi3_host.c"
BARE_ENV = {"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8"}


BACKENDS = {"python": "fmi3", "native": "native/fmi3"}
_FOLDER = {"now": "fmi3"}


@pytest.fixture(autouse=True, scope="module", params=list(BACKENDS))
def backend(request):
    """The FMI 3.0 FMUs under test: the Python-hosted ones, then the native ones."""
    _FOLDER["now"] = BACKENDS[request.param]
    yield request.param
    _FOLDER["now"] = "fmi3"


def fmu3_path(name):
    path = DIST / _FOLDER["now"] / f"{name}.fmu"
    assert path.exists(), f"{path} missing: the session fixture builds every FMU first"
    return path


def md3(name):
    return _md3(name, _FOLDER["now"])


@lru_cache(maxsize=None)
def _md3(name, folder):
    from fmpy import read_model_description

    return read_model_description(str(DIST / folder / f"{name}.fmu"))


@lru_cache(maxsize=None)
def md2(name):
    from fmpy import read_model_description

    return read_model_description(str(fmu_path(name)))


def simulate3(name, **kwargs):
    """fmpy simulate_fmu on the FMI 3.0 FMU with every log message collected: (result, messages)."""
    from fmpy import simulate_fmu

    messages = []

    def logger(env, status, category, message):
        messages.append((status, category.decode() if category else "", message.decode() if message else ""))

    start = dict(kwargs.pop("start_values", {}))
    stop = kwargs.pop("stop_time", float(md3(name).defaultExperiment.stopTime))
    res = simulate_fmu(str(fmu3_path(name)), start_values=start, stop_time=stop, debug_logging=True,
                       logger=logger, **kwargs)
    assert math.isclose(res["time"][-1], stop, abs_tol=1e-9), (name, res["time"][-1], messages[-3:])
    return res, messages


@lru_cache(maxsize=None)
def fmi2_events(name):
    """(kind, time) of every event of the FMI 2.0 FMU's default experiment."""
    run = simulate(name, start_values={"log_events": 1})
    assert not run.errors
    return tuple((e["name"], e["time"]) for e in run.events())


# ---------------------------------------------------------------------------------------------
# build and model description
# ---------------------------------------------------------------------------------------------

def test_every_slave_has_an_fmi3_fmu():
    assert sorted(p.stem for p in (DIST / _FOLDER["now"]).glob("*.fmu")) == FMUS


@pytest.mark.parametrize("name", FMUS)
def test_fmi3_validates_and_offers_both_interfaces(name, backend):
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(fmu3_path(name))) == []
    md = md3(name)
    assert md.fmiVersion == "3.0"
    assert md.modelExchange is not None and md.coSimulation is not None
    assert md.coSimulation.hasEventMode
    with zipfile.ZipFile(fmu3_path(name)) as z:
        binaries = [n for n in z.namelist() if n.startswith("binaries/")]
    # what the build recorded it made: the native FMUs one binary per platform asked for (the same
    # platforms for every FMU of the build), the Python-hosted ones x86-64 Linux's only
    record = json.loads((DIST / "pogofmu-build.json").read_text())
    entry = record[fmu3_path(name).relative_to(DIST).as_posix()]
    suffix = {"linux": ".so", "windows": ".dll", "darwin": ".dylib"}
    expected = (sorted(f"binaries/{p}/{name}{suffix[p.split('-')[1]]}" for p in entry["platforms"])
                if backend == "native" else [f"binaries/x86_64-linux/{name}.so"])
    assert sorted(binaries) == expected and entry["binaries"] == sorted(b.split("/")[1] for b in binaries)
    assert len({tuple(e["platforms"]) for e in record.values()}) == 1


@pytest.mark.parametrize("name", FMUS)
def test_fmi3_keeps_the_fmi2_variables(name):
    """Same names, value references, types, causalities, units, descriptions and start values."""
    v3 = {v.name: v for v in md3(name).modelVariables}
    model = MODELS[name]
    for v in md2(name).modelVariables:
        w = v3[v.name]
        assert (w.valueReference, w.causality, w.variability, w.description) == \
               (v.valueReference, v.causality, v.variability, v.description), v.name
        assert w.type == {"Real": "Float64", "Integer": "Int32"}[v.type], v.name
        assert w.unit == v.unit, v.name
        assert (w.start is None) == (v.start is None) and (v.start is None or float(w.start) == float(v.start)), v.name
    units = {u.name for u in md3(name).unitDefinitions}
    assert all(v.unit in units for v in md3(name).modelVariables if v.unit)
    # one state per model state (its derivative named der(...)), one indicator per guard
    md = md3(name)
    assert [d.variable.derivative.name for d in md.derivatives] == [s.name for s in model.states]
    assert [d.variable.name for d in md.derivatives] == [f"der({s.name})" for s in model.states]
    assert [z.variable.name for z in md.eventIndicators] == [f"guard_{e.name}" for e in model.events]
    assert md.numberOfContinuousStates == len(model.states)
    assert md.numberOfEventIndicators == len(model.events)


# ---------------------------------------------------------------------------------------------
# model exchange through fmpy's CVode
# ---------------------------------------------------------------------------------------------

def me_events(name, **kwargs):
    res, messages = simulate3(name, fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10,
                              start_values={"log_events": 1}, **kwargs)
    assert not [m for m in messages if m[0] >= 3], messages[-3:]
    return res, parse_event_log(messages)


def test_me_pogostick_events_match_the_closed_form():
    res, events = me_events("PogoStick", output_interval=1e-2)
    ref = reference_events()
    assert len(ref) == 19
    assert [e["name"] for e in events] == [r["name"] for r in ref]
    worst = max(abs(e["time"] - r["time"]) for e, r in zip(events, ref))
    assert worst < 3e-7, worst  # docs/fmi3.md: 7e-8 s
    # the event counter output counts the jumps the FMU applied: no spurious event
    assert int(res["n_events"][-1]) == 19


def independent_events(name, stop):
    """[(name, time)] of the default experiment by the scipy model in tests/references.py
    (DOP853 at rtol 1e-13, the equations written there from docs/models.md, not the package's)."""
    from pogofmu.runtime.models import get

    from references import penetrator_reference, scipy_mem, scipy_sma

    if name == "PogoStickMem":
        p = get(name).params()
        return [(n, t) for n, t, _ in scipy_mem(p.spring_law, p.beta, p.gamma, stop, c=p.c, a0=p.a_0)]
    if name == "PogoStickSMA":
        return scipy_sma(stop)
    return [(n, t) for n, t, _ in penetrator_reference(stop)[0]]


@pytest.mark.parametrize("name", ["PogoStickMem", "PogoStickSMA", "Penetrator"])
def test_me_events_match_an_independent_model(name):
    """Model exchange through CVode against the scipy models (not against the FMI 2.0 FMU, which
    runs the same model code): every event, in order, within 2e-7 s (docs/fmi3.md: 5e-8 s)."""
    _, events = me_events(name, output_interval=1e-2)
    ref = independent_events(name, float(md3(name).defaultExperiment.stopTime))
    assert len(ref) >= 10
    assert [e["name"] for e in events] == [k for k, _ in ref]
    worst = max(abs(e["time"] - t) for e, (_, t) in zip(events, ref))
    assert worst < 2e-7, worst


def test_me_hopcontroller_outputs_equal_fmi2():
    """A model without states: model exchange evaluates the same control law."""
    inputs = {"y": 0.9, "ydot": 0.5, "s": 1}
    res, _ = simulate3("HopController", fmi_type="ModelExchange", solver="CVode", stop_time=0.1,
                       output_interval=0.01, start_values=inputs)
    ref = simulate("HopController", start_values=inputs, stop_time=0.1, output_interval=0.01)
    assert res["F_ext"][-1] == ref["F_ext"][-1] and res["F_ext"][-1] > 0


def test_me_outputs_follow_the_inputs_at_once():
    """Model exchange has no steps: an output that feeds through from an input (the controller's
    thrust) changes when the input is set (the control law, evaluated here independently)."""
    inst = MEInstance("HopController", F_max=1000.0)
    inst.set("y", 0.9)
    inst.set("ydot", 0.5)
    inst.set("s", 1)
    m, g, k, c, x_i, h, tau = 1.0, 9.81, 100.0, 0.5, 1.0, 1.5, 0.02
    E = 0.5 * m * 0.25 + m * g * 0.9 + 0.5 * k * (0.9 - x_i) ** 2
    expected = c * 0.5 + (m * g * h - E) / (tau * 0.5)  # 526.4 N < F_max: not clipped
    assert 0 < expected < 1000.0
    assert inst.get("F_ext") == pytest.approx(expected, rel=1e-12)
    inst.set("ydot", -0.5)  # compression: no thrust
    assert inst.get("F_ext") == 0.0 and inst.get("phase") == 1
    inst.fmu.freeInstance()


def test_me_leg_bottoming_out_is_an_error_with_condition_and_time():
    """PogoStickMem, softening leg beta = 5 (README: bottoms out at t = 4.989 s in FMI 2.0):
    under CVode the run ends in fmi3Error naming the condition, at the importer's step there."""
    from fmpy import simulate_fmu
    from fmpy.fmi1 import FMICallException

    messages = []
    with pytest.raises(FMICallException) as exc:
        simulate_fmu(str(fmu3_path("PogoStickMem")), fmi_type="ModelExchange", solver="CVode",
                     relative_tolerance=1e-10, start_values={"beta": 5.0}, stop_time=10, debug_logging=True,
                     logger=lambda env, st, cat, msg: messages.append((st, msg.decode())))
    assert "(error)" in str(exc.value)
    text = [m for st, m in messages if st >= 3][0]
    assert "leg length xbar" in text and "the leg bottomed out" in text, text
    t = float(text.split("at t = ")[1].split(" s")[0])
    assert 4.98 < t < 5.0, text


class MEInstance:
    """One FMI 3.0 model-exchange instance driven by hand through fmpy's FMU3Model."""

    def __init__(self, name, **params):
        from fmpy import extract
        from fmpy.fmi3 import FMU3Model

        self.md = md3(name)
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.messages = []

        def logger(env, status, category, message):
            self.messages.append((status, category.decode() if category else "", message.decode()))

        self.fmu = FMU3Model(guid=self.md.guid, unzipDirectory=extract(str(fmu3_path(name))),
                             modelIdentifier=self.md.modelExchange.modelIdentifier, instanceName="me")
        self.fmu.instantiate(loggingOn=True, logMessage=logger)
        self.fmu.enterInitializationMode(startTime=0.0)
        for k, v in params.items():
            self.set(k, v)
        self.fmu.exitInitializationMode()  # now in Event Mode
        self.nx, self.nz = self.md.numberOfContinuousStates, self.md.numberOfEventIndicators
        flags = self.fmu.updateDiscreteStates()
        assert flags[0] is False and flags[1] is False
        self.fmu.enterContinuousTimeMode()

    def set(self, name, value):
        """A real input at once; a discrete one (FMI 3.0: only in Event Mode) through Event Mode."""
        v = self.vars[name]
        if v.type == "Float64":
            self.fmu.setFloat64([v.valueReference], [float(value)])
        else:
            self.fmu.enterEventMode()
            self.fmu.setInt32([v.valueReference], [int(value)])
            self.fmu.updateDiscreteStates()
            self.fmu.enterContinuousTimeMode()

    def get(self, name):
        v = self.vars[name]
        return (self.fmu.getFloat64 if v.type == "Float64" else self.fmu.getInt32)([v.valueReference])[0]

    def states(self):
        x = np.zeros(self.nx)
        self.fmu.getContinuousStates(x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), self.nx)
        return x

    def set_states(self, x):
        x = np.asarray(x, dtype=float)
        self.fmu.setContinuousStates(x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), self.nx)

    def indicators(self):
        z = np.zeros(self.nz)
        self.fmu.getEventIndicators(z.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), self.nz)
        return z

    def update(self):
        """Event Mode: (values of continuous states changed, nominals changed)."""
        self.fmu.enterEventMode()
        flags = self.fmu.updateDiscreteStates()
        self.fmu.enterContinuousTimeMode()
        assert flags[0] is False and flags[1] is False  # no further iteration, no termination
        return flags[3], flags[2]


def test_me_jumps_only_for_guards_crossed_in_their_direction():
    """PogoStick by hand: the state is set as an importer's solver would, the flags are read."""
    inst = MEInstance("PogoStick")
    names = [d.variable.derivative.name for d in inst.md.derivatives]
    ix = {n: i for i, n in enumerate(names)}
    x = inst.states()
    assert list(inst.indicators()) == [x[ix["z"]], 1.0]  # touchdown guard z; liftoff inactive in flight
    assert [inst.get("guard_touchdown"), inst.get("guard_liftoff")] == [x[ix["z"]], 1.0]
    # no crossing: nothing happens
    assert inst.update() == (False, False) and inst.get("s") == 0
    # the foot crossed the ground (falling): touchdown, xdot <- ydot, z <- 0
    x[ix["y"]], x[ix["ydot"]], x[ix["z"]] = 0.999, -3.0, -0.001
    inst.fmu.setTime(0.32)
    inst.set_states(x)
    assert inst.update() == (True, False)
    x = inst.states()
    assert inst.get("s") == 1 and x[ix["z"]] == 0.0 and x[ix["xdot"]] == -3.0 and inst.get("n_events") == 1
    assert inst.get("t_last_event") == 0.32
    # liftoff guard xbar - x_i is exactly 0 after the touchdown: armed at zero (the engine's rule,
    # docs/solver.md "Event semantics"), its indicator shifted by its rounding band, just on its
    # before side (no root at the restart); a rise to the after side while the flow compresses the
    # leg (xdot < 0, carrying the guard back) applies nothing
    assert -1e-12 < inst.indicators()[1] < 0.0
    x[ix["xbar"]] = 1.001
    inst.set_states(x)
    assert inst.indicators()[1] == pytest.approx(0.001)
    assert inst.update() == (False, False) and inst.get("s") == 1
    # compression (before side seen by the indicators), then extension past x_i: liftoff (the body
    # moving up: a liftoff with it moving down touches down again at the same instant, a cascade)
    x[ix["xbar"]], x[ix["xdot"]], x[ix["ydot"]] = 0.9, 1.0, 1.0
    inst.set_states(x)
    assert inst.indicators()[1] == pytest.approx(-0.1)
    x[ix["xbar"]] = 1.0 + 1e-9
    inst.set_states(x)
    assert inst.update() == (True, False)
    assert inst.get("s") == 0 and inst.states()[ix["xbar"]] == 1.0 and inst.get("n_events") == 2
    # a falling guard crossing upwards (z from the after side back up) applies nothing
    x = inst.states()
    x[ix["z"]] = -1e-3
    inst.set_states(x)
    inst.indicators()
    assert inst.update() == (False, False) and inst.get("s") == 0
    # derivatives are the model's flow (flight: dxbar = xdot = 0, dydot = -g)
    dx = np.zeros(inst.nx)
    inst.fmu.getContinuousStateDerivatives(dx.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), inst.nx)
    assert dx[ix["ydot"]] == -9.81 and dx[ix["xbar"]] == 0.0
    assert inst.get("der(ydot)") == -9.81
    inst.fmu.terminate()
    inst.fmu.freeInstance()


def test_me_domain_violation_is_an_error_naming_the_condition():
    from fmpy.fmi1 import FMICallException

    inst = MEInstance("PogoStick")
    x = inst.states()
    x[2] = -0.5  # y < 0
    inst.set_states(x)
    with pytest.raises(FMICallException) as exc:
        inst.fmu.completedIntegratorStep()
    assert "(error)" in str(exc.value)
    assert any("mass height y" in m[2] and "must stay > 0" in m[2] for m in inst.messages), inst.messages
    # the stopped instance refuses further calls, naming them and the remedy as FMI 3.0 spells them
    with pytest.raises(FMICallException):
        inst.fmu.completedIntegratorStep()
    text = inst.messages[-1][2]
    assert "fmi3CompletedIntegratorStep refused: the instance stopped" in text and "fmi3SetFMUState" in text, text
    inst.fmu.freeInstance()


# ---------------------------------------------------------------------------------------------
# co-simulation with event mode and early return
# ---------------------------------------------------------------------------------------------

def off_grid_times(times, h):
    return sorted({float(t) for t in times if abs(t / h - round(t / h)) > 1e-6})


@pytest.mark.parametrize("h", [1e-3, 0.1])
@pytest.mark.parametrize("name", WITH_EVENTS)
def test_cs_early_return_lands_on_the_fmi2_event_times(name, h):
    res, messages = simulate3(name, fmi_type="CoSimulation", use_event_mode=True, early_return_allowed=True,
                              output_interval=h)
    assert not [m for m in messages if m[0] >= 3]
    ref = [t for _, t in fmi2_events(name)]
    got = off_grid_times(res["time"], h)  # fmpy samples at every lastSuccessfulTime of an early return
    assert len(got) == len(ref)
    worst = max(abs(a - b) for a, b in zip(got, ref))
    assert worst <= 1e-12, worst
    # each event time appears twice: the left limit after fmi3DoStep, the right limit after Event Mode
    times = np.asarray(res["time"])
    for k, t in enumerate(got, start=1):
        rows = np.flatnonzero(times == t)
        assert len(rows) == 2, (t, rows)
        assert res["n_events"][rows[0]] == k - 1 and res["n_events"][rows[1]] == k


def test_cs_early_return_without_event_mode_returns_after_the_jump():
    """earlyReturnAllowed alone: the FMU handles each event itself and returns right after it."""
    h = 0.1
    res, _ = simulate3("PogoStick", fmi_type="CoSimulation", early_return_allowed=True, output_interval=h)
    got = off_grid_times(res["time"], h)
    ref = [t for _, t in fmi2_events("PogoStick")]
    assert len(got) == len(ref) and max(abs(a - b) for a, b in zip(got, ref)) <= 1e-12
    times = np.asarray(res["time"])
    for k, t in enumerate(got, start=1):
        rows = np.flatnonzero(times == t)
        assert len(rows) == 1 and res["n_events"][rows[0]] == k  # one sample, after the jump


@pytest.mark.parametrize("name", FMUS)
def test_cs_without_event_mode_equals_fmi2(name):
    stop = min(2.0, float(md3(name).defaultExperiment.stopTime))
    res, _ = simulate3(name, fmi_type="CoSimulation", output_interval=1e-2, stop_time=stop)
    ref = simulate(name, output_interval=1e-2, stop_time=stop)
    for v in md2(name).modelVariables:
        if v.causality == "output":
            assert np.array_equal(res[v.name], ref[v.name]), v.name


@pytest.fixture(scope="module")
def c_host3(tmp_path_factory):
    return compile_c_host(C_HOST_SOURCE, tmp_path_factory.mktemp("c_host3") / "fmi3_host")


def run_c_host3(exe, tmp_path, name, stop, h, events, params=()):
    d = tmp_path / name
    if not d.exists():
        with zipfile.ZipFile(fmu3_path(name)) as z:
            z.extractall(d)
    args = [str(exe), str(d), name, md3(name).guid, repr(stop), repr(h), str(int(events)), *params]
    proc = subprocess.run(args, capture_output=True, text=True, env=BARE_ENV, timeout=300)
    return proc


@pytest.mark.parametrize("h", [1e-3, 0.1])
@pytest.mark.parametrize("name", ["PogoStick", "Penetrator"])
def test_c_host_early_return_lands_on_the_fmi2_event_times(name, h, c_host3, tmp_path):
    stop = float(md3(name).defaultExperiment.stopTime)
    proc = run_c_host3(c_host3, tmp_path, name, stop, h, True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.splitlines()
    got = [float(line.split(",")[1]) for line in lines if line.startswith("event,")]
    ref = [t for _, t in fmi2_events(name)]
    assert len(got) == len(ref)
    assert max(abs(a - b) for a, b in zip(got, ref)) <= 1e-12
    assert lines[-1] == f"end,{stop!r}" or float(lines[-1].split(",")[1]) == pytest.approx(stop, abs=1e-9)


def test_c_host_model_exchange_with_its_own_euler_integrator(c_host3, tmp_path):
    """Model exchange from C: explicit Euler (h = 1e-5 s) and sign changes of the indicators
    between steps; every event it meets is a jump (no spurious one), at the closed-form times to
    the first-order accuracy of Euler."""
    proc = run_c_host3(c_host3, tmp_path, "PogoStick", 2.0, 1e-5, 2)
    assert proc.returncode == 0, proc.stderr[-2000:]
    events = [line.split(",") for line in proc.stdout.splitlines() if line.startswith("event,")]
    ref = [r["time"] for r in reference_events() if r["time"] < 2.0]
    assert len(events) == len(ref) == 4
    assert all(changed == "1" for _, _, changed in events)
    assert max(abs(float(t) - r) for (_, t, _), r in zip(events, ref)) < 1e-3
    assert proc.stdout.splitlines()[-1] == "end,2"


def test_c_host_bad_parameter_is_refused_with_its_name(c_host3, tmp_path):
    m = next(v for v in md3("PogoStick").modelVariables if v.name == "m")
    proc = run_c_host3(c_host3, tmp_path, "PogoStick", 1.0, 0.1, True, [f"{m.valueReference}=-1"])
    assert proc.returncode == 1
    assert "parameter m = -1.0 violates the rule: m > 0" in proc.stderr, proc.stderr


# ---------------------------------------------------------------------------------------------
# conformance
# ---------------------------------------------------------------------------------------------

def cs_instance(name, messages, event_mode=False):
    from fmpy import extract
    from fmpy.fmi3 import FMU3Slave

    md = md3(name)
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmu3_path(name))),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="cs")

    def logger(env, status, category, message):
        messages.append((status, category.decode() if category else "", message.decode()))

    fmu.instantiate(loggingOn=True, eventModeUsed=event_mode, earlyReturnAllowed=event_mode, logMessage=logger)
    return fmu


@pytest.mark.parametrize("interface", ["CoSimulation", "ModelExchange"])
@pytest.mark.parametrize("name", WITH_EVENTS)
def test_bad_parameter_is_an_error_naming_it_and_reset_recovers(name, interface):
    from fmpy import extract
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi3 import FMU3Model

    messages = []
    if interface == "CoSimulation":
        fmu = cs_instance(name, messages)
    else:
        md = md3(name)
        fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(str(fmu3_path(name))),
                        modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
        fmu.instantiate(loggingOn=True, logMessage=lambda env, st, cat, msg: messages.append((st, cat, msg.decode())))
    vr = next(v.valueReference for v in md3(name).modelVariables if v.name == "rel_tol")
    fmu.enterInitializationMode(startTime=0.0)
    fmu.setFloat64([vr], [2.0])
    with pytest.raises(FMICallException) as exc:
        fmu.exitInitializationMode()
    assert "(error)" in str(exc.value)
    assert any("parameter rel_tol = 2.0 violates the rule: 1e-14 <= rel_tol <= " in m[2] for m in messages), messages
    fmu.reset()
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    fmu.freeInstance()


def test_unsupported_functions_are_errors_naming_the_function(backend):
    """(The native FMUs provide directional derivatives, with respect to the inputs in
    co-simulation: y there is refused as a known, naming it; tests/test_native_derivatives.py.)"""
    from fmpy.fmi1 import FMICallException

    messages = []
    fmu = cs_instance("PogoStick", messages)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    y = next(v.valueReference for v in md3("PogoStick").modelVariables if v.name == "y")
    with pytest.raises(FMICallException) as exc:
        fmu.getDirectionalDerivative([y], [y], [1.0])
    assert "(error)" in str(exc.value)
    why = "y (value reference" if backend == "native" else "not supported"
    assert "fmi3GetDirectionalDerivative" in messages[-1][2] and why in messages[-1][2]
    with pytest.raises(FMICallException):
        fmu.getInt8([y])
    assert "fmi3GetInt8: value reference" in messages[-1][2]
    assert fmu.getFloat64([y]) == [1.5]  # the instance is still usable
    fmu.freeInstance()


def cs_start(name, messages):
    """A co-simulation instance with event mode and early return, initialized, in Step Mode."""
    fmu = cs_instance(name, messages, event_mode=True)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    fmu.updateDiscreteStates()
    fmu.enterStepMode()
    return fmu


def cs_run(fmu, name, t, t_end, h=0.05, stop_at_first_event=False):
    """Step on the grid k*h from t to t_end (early returns in between); return (t, event times,
    outputs)."""
    outs = [v.valueReference for v in md3(name).modelVariables if v.causality == "output" and v.type == "Float64"]
    seen = []
    while t < t_end - 1e-12:
        target = min(t_end, (math.floor(t / h + 1e-9) + 1) * h)
        handle, _, early, last = fmu.doStep(currentCommunicationPoint=t, communicationStepSize=target - t)
        t = last if early else target
        if handle:
            seen.append(last)
            if stop_at_first_event:
                break  # paused at the event, before its jump (Event Mode not entered yet)
            fmu.enterEventMode()
            fmu.updateDiscreteStates()
            fmu.enterStepMode()
    return t, seen, fmu.getFloat64(outs)


@pytest.mark.parametrize("name", WITH_EVENTS)
def test_cs_fmu_state_round_trip_with_event_mode(name):
    """Save between events, run on, restore: the same event times and outputs again."""
    fmu = cs_start(name, [])
    t, _, _ = cs_run(fmu, name, 0.0, 0.2)
    state = fmu.getFMUState()
    first = cs_run(fmu, name, t, 2.0)
    fmu.setFMUState(state)
    second = cs_run(fmu, name, t, 2.0)
    assert first[1] and first == second
    fmu.freeFMUState(state)
    fmu.freeInstance()


@pytest.mark.parametrize("name", WITH_EVENTS)
def test_cs_serialized_state_at_an_event_restores_in_a_fresh_instance(name):
    """Paused at the first event, before its jump: the serialized state, deserialized into a
    fresh instance, applies the same jump and runs on bit for bit."""
    a, b = cs_start(name, []), cs_start(name, [])
    t, seen, _ = cs_run(a, name, 0.0, 5.0, stop_at_first_event=True)
    assert seen and t == seen[0]
    blob = a.serializeFMUState(a.getFMUState())
    b.setFMUState(b.deserializeFMUState(blob))
    for fmu in (a, b):
        fmu.enterEventMode()
        fmu.updateDiscreteStates()
        fmu.enterStepMode()
    assert cs_run(a, name, t, 3.0) == cs_run(b, name, t, 3.0)
    a.freeInstance()
    b.freeInstance()


def test_me_fmu_state_round_trip():
    inst = MEInstance("PogoStick")
    x0 = inst.states()
    state = inst.fmu.getFMUState()
    x = x0.copy()
    x[4] = -1e-3
    inst.fmu.setTime(0.33)
    inst.set_states(x)
    assert inst.update() == (True, False) and inst.get("s") == 1
    blob = inst.fmu.serializeFMUState(inst.fmu.getFMUState())  # in contact, one event done
    inst.fmu.setFMUState(state)
    assert np.array_equal(inst.states(), x0) and inst.get("s") == 0 and inst.get("n_events") == 0
    assert inst.get("time") == 0.0
    inst.fmu.freeFMUState(state)
    fresh = MEInstance("PogoStick")
    fresh.fmu.setFMUState(fresh.fmu.deserializeFMUState(blob))
    expected = x.copy()
    expected[1], expected[4] = x[3], 0.0  # the touchdown's jump: xdot <- ydot, z <- 0
    assert np.array_equal(fresh.states(), expected) and fresh.get("s") == 1 and fresh.get("n_events") == 1
    assert fresh.get("time") == 0.33
    fresh.fmu.freeInstance()
    inst.fmu.freeInstance()


SEVERAL = r"""
import importlib.util, json, sys
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
dist = sys.argv[1]
out = {"project_importable": [m for m in ("pogofmu", "pythonfmu") if importlib.util.find_spec(m)]}
# 1. one after the other: FMI 2.0 and 3.0, model exchange and co-simulation, several models
out["cs3"] = simulate_fmu(dist + "/fmi3/PogoStick.fmu", stop_time=2.0, output_interval=1e-2,
                          use_event_mode=True, early_return_allowed=True)["y"][-1]
out["me3"] = simulate_fmu(dist + "/fmi3/Penetrator.fmu", stop_time=2.0, output_interval=1e-2,
                          fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10)["y"][-1]
out["cs2"] = simulate_fmu(dist + "/PogoStick.fmu", stop_time=2.0, output_interval=1e-2)["y"][-1]
out["sma3"] = simulate_fmu(dist + "/fmi3/PogoStickSMA.fmu", stop_time=2.0, output_interval=1e-2)["y"][-1]


# 2. alive at once, stepped in turn: FMI 2.0 PogoStick, FMI 3.0 PogoStick (event mode), FMI 3.0 Penetrator
def open_fmu(path, fmi3, name):
    md = read_model_description(path)
    cls = FMU3Slave if fmi3 else FMU2Slave
    fmu = cls(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
              instanceName=name)
    if fmi3:
        fmu.instantiate(eventModeUsed=True, earlyReturnAllowed=True)
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        fmu.updateDiscreteStates()
        fmu.enterStepMode()
    else:
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
    y = next(v.valueReference for v in md.modelVariables if v.name == "y")
    return fmu, y


live = [(open_fmu(dist + "/PogoStick.fmu", False, "a"), False), (open_fmu(dist + "/fmi3/PogoStick.fmu", True, "b"), True),
        (open_fmu(dist + "/fmi3/Penetrator.fmu", True, "c"), True)]
times = [0.0] * len(live)
for k in range(1, 2001):
    for i, ((fmu, _), fmi3) in enumerate(live):
        while times[i] < k * 1e-3:
            if fmi3:
                handle, _, early, last = fmu.doStep(times[i], k * 1e-3 - times[i])
                times[i] = last if early else k * 1e-3
                if handle:
                    fmu.enterEventMode()
                    fmu.updateDiscreteStates()
                    fmu.enterStepMode()
            else:
                fmu.doStep(times[i], k * 1e-3 - times[i])
                times[i] = k * 1e-3
out["live"] = [(fmu.getReal if not fmi3 else fmu.getFloat64)([y])[0] for (fmu, y), fmi3 in live]
for (fmu, _), _ in live:
    fmu.terminate()
    fmu.freeInstance()
print(json.dumps(out))
"""


def test_several_fmi2_and_fmi3_fmus_in_one_fresh_process():
    """In a venv holding only fmpy and numpy (test_portability's), one after the other and alive at
    once: every result equals the one of the same FMU run alone."""
    import json

    from test_portability import _clean_venv

    proc = subprocess.run([str(_clean_venv()), "-c", SEVERAL, str(DIST)], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["project_importable"] == []
    # co-simulation: FMI 3.0 == FMI 2.0 exactly (same engine, same step sequence)
    ref_stick = simulate("PogoStick", stop_time=2.0, output_interval=1e-2)["y"][-1]
    assert got["cs3"] == got["cs2"] == ref_stick
    assert got["sma3"] == simulate("PogoStickSMA", stop_time=2.0, output_interval=1e-2)["y"][-1]
    ref_pen = simulate("Penetrator", stop_time=2.0, output_interval=1e-2)["y"][-1]
    assert got["me3"] == pytest.approx(ref_pen, abs=1e-6)
    assert got["live"][0] == got["live"][1] == ref_stick
    assert got["live"][2] == ref_pen


def test_a_getter_of_the_wrong_type_names_the_fmi3_types():
    """FMI 3.0 names its types Float64 and Int32: so does the refusal (FMI 2.0's Real/Integer before)."""
    from fmpy.fmi1 import FMICallException

    messages = []
    fmu = cs_instance("PogoStick", messages)
    try:
        fmu.enterInitializationMode()
        s = next(v.valueReference for v in md3("PogoStick").modelVariables if v.name == "s")
        y = next(v.valueReference for v in md3("PogoStick").modelVariables if v.name == "y")
        with pytest.raises(FMICallException):
            fmu.getFloat64([s])
        assert "variable s (value reference" in messages[-1][2] and "is of type Int32, not Float64: use the Int32 " \
            "getter/setter" in messages[-1][2], messages[-1]
        with pytest.raises(FMICallException):
            fmu.getInt32([y])
        assert "is of type Float64, not Int32" in messages[-1][2], messages[-1]
    finally:
        fmu.freeInstance()
