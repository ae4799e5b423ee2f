"""Helpers shared by the tests: build once, simulate through fmpy, read logs, run libcosimpy.

Everything here drives the *built* FMUs in dist/, as an importer would.
"""
from __future__ import annotations

import ctypes
import json
import math
import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

from pogofmu.fmpy_raw import raw_call
from pogofmu.runtime.eventlog import parse_event_log  # noqa: F401  (the tests read the FMUs' event log with it)

ROOT = Path(__file__).resolve().parents[1]
DIST = Path(os.environ.get("POGOFMU_DIST", ROOT / "dist")).resolve()  # build target of the session


IN_CI = os.environ.get("CI", "").lower() == "true"


def needs(available: bool, what: str):
    """A decorator for a test whose prerequisite a registry has (a Debian or PyPI package): skipped,
    naming it, on a machine without it; under ``CI=true`` (where .ci/run installs it) a missing
    prerequisite fails the test instead of hiding it."""
    import functools

    import pytest

    def deco(fn):
        if available:
            return fn

        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            if IN_CI:
                pytest.fail(f"missing under CI=true: {what} (.ci/run installs it)")
            pytest.skip(f"no {what}")
        return wrapper
    return deco


def require(available: bool, what: str):
    """Inside a test or a fixture: :func:`needs`' rule (skipped naming ``what`` where it is missing,
    failed under ``CI=true``)."""
    import pytest

    if not available:
        if IN_CI:
            pytest.fail(f"missing under CI=true: {what} (.ci/run installs it)")
        pytest.skip(f"no {what}")


def needs_mark(available: bool, what: str):
    """:func:`needs` as a mark, for a module (``pytestmark``) or a parametrized test: the conftest
    applies the rule before each test it marks."""
    import pytest

    return pytest.mark.needs(bool(available), what)


EXAMPLES = ROOT / "examples"


def example_files():
    """The model files of examples/ (the files there that define a HybridModel)."""
    return sorted(p for p in EXAMPLES.glob("*/*.py") if "HybridModel(" in p.read_text())


def example_models():
    """``{FMU name: model}`` of the example files, as the exporter loads them."""
    from pogofmu.exporter import load_model_file

    return {s.model.name: s.model for f in example_files() for s in load_model_file(f)}


def model_of(name: str):
    """The model behind an FMU name of the session's dist/: ``[native/][fmi3/]<Model>`` (the project's
    five) or ``examples/[native/][fmi3/]<Model>`` (the example files, exported as a user does)."""
    from pogofmu.runtime.models import all_models

    model = name.rpartition("/")[2]
    if name.startswith("examples/"):
        return example_models()[model]
    return all_models()[model]


def fmu_path(name: str) -> Path:
    path = DIST / f"{name}.fmu"
    assert path.exists(), f"{path} missing: the session fixture builds every FMU first"
    return path


def all_fmus():
    return sorted(p.stem for p in DIST.glob("*.fmu"))


def _message(status, category, message):
    decode = lambda b: b.decode(errors="replace") if b else ""  # noqa: E731 (None for some messages)
    return status, decode(category), decode(message)


@dataclass
class Run:
    res: object
    messages: list = field(default_factory=list)  # (status, category, text)

    def __getitem__(self, name):
        return self.res[name]

    @property
    def errors(self):
        return [m for m in self.messages if m[0] >= 3]

    def events(self):
        """Events reported through the logEvents category (needs log_events=1)."""
        return parse_event_log(self.messages)


def simulate(name, start_values=None, stop_time=None, output_interval=None, input=None,
             check_complete=True, **kwargs) -> Run:
    """fmpy simulate_fmu with every log message collected; by default assert the run completed."""
    from fmpy import read_model_description, simulate_fmu

    path = fmu_path(name)
    md = read_model_description(str(path))
    stop = float(md.defaultExperiment.stopTime) if stop_time is None else stop_time
    messages = []

    def logger(component, instance, status, category, message):
        messages.append(_message(status, category, message))

    res = simulate_fmu(str(path), start_values=start_values or {}, stop_time=stop,
                       output_interval=output_interval or float(md.defaultExperiment.stepSize),
                       input=input, debug_logging=True, logger=logger, **kwargs)
    run = Run(res, messages)
    if check_complete:
        assert math.isclose(res["time"][-1], stop, abs_tol=1e-9 * max(1, stop)), (
            f"{name} stopped at t = {res['time'][-1]} < {stop}: {run.errors}")
    return run


def reference_events(params=None):
    """The basic stick's events in closed form (40-digit roots, pogofmu.references.closed_form), default drop
    unless ``params`` says otherwise: dicts with index, name, time, y, ydot."""
    from pogofmu.references.closed_form import events_as_floats

    return events_as_floats(params)


class Instance:
    """One FMU instance stepped by hand through fmpy's FMU2Slave, with its log collected."""

    def __init__(self, name, instance_name="test", unzip_dir=None):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        path = fmu_path(name)
        self.md = read_model_description(str(path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.dir = extract(str(path)) if unzip_dir is None else unzip_dir  # reuse one extraction
        self.messages = []

        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=instance_name)
        self._callbacks = fmi2_callbacks(self.messages)
        self.fmu.instantiate(loggingOn=True, callbacks=self._callbacks.struct)
        self.t = 0.0

    def set(self, **values):
        for name, value in values.items():
            v = self.vars[name]
            if v.type == "Real":
                self.fmu.setReal([v.valueReference], [float(value)])
            else:
                self.fmu.setInteger([v.valueReference], [int(value)])

    def get(self, *names):
        out = []
        for name in names:
            v = self.vars[name]
            if v.type == "Real":
                out.append(self.fmu.getReal([v.valueReference])[0])
            else:
                out.append(self.fmu.getInteger([v.valueReference])[0])
        return out if len(out) > 1 else out[0]

    def outputs(self):
        return {n: self.get(n) for n, v in self.vars.items() if v.causality == "output"}

    def init(self, start_time=0.0, stop_time=None, **params):
        self.fmu.setupExperiment(startTime=start_time, stopTime=stop_time)
        self.fmu.enterInitializationMode()
        self.set(**params)
        self.fmu.exitInitializationMode()
        self.t = start_time
        return self

    def step(self, h):
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
        self.t += h

    def run_to(self, t_end, h):
        n = int(round((t_end - self.t) / h))
        for _ in range(n):
            self.step(h)

    def close(self):
        """Terminate (where the standard allows it: not after a failed initialization, which the
        FMU refuses with Error) and free."""
        from fmpy.fmi1 import FMICallException

        try:
            self.fmu.terminate()
        except FMICallException:
            pass
        finally:
            self.fmu.freeInstance()


def run_pogofmu(*args, cwd, timeout):
    """The ``pogofmu`` command of the project's venv (``python -m pogofmu.cli``), run in ``cwd`` as a
    user runs it in their folder: the finished process, its output captured. It runs this checkout's
    code, as the tests' own imports do (conftest.py), whichever checkout the venv has installed: a
    test run from a second worktree exports with that worktree's engine, not the installed one."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT / "fmu_src"), os.environ.get("PYTHONPATH")])))
    return subprocess.run([sys.executable, "-m", "pogofmu.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=env)


def fmi2_callbacks(messages):
    """FMI 2.0 callbacks (:class:`pogofmu.fmpy_raw.Fmi2Callbacks`) whose messages are appended to
    ``messages`` as ``(status, category, text)``; pass ``.struct`` to the instantiation and keep the
    returned object as long as the instance lives."""
    from pogofmu.fmpy_raw import Fmi2Callbacks

    return Fmi2Callbacks(lambda status, category, text: messages.append((status, category, text)))


def init_failure_text(name, **params):
    """Initialize a fresh instance with ``params``; assert it is refused with fmi2Error and a message,
    that the same instance works again after fmi2Reset with the default parameters (fmi2Error leaves
    it usable), and return the logged messages as one text."""
    import pytest
    from fmpy.fmi1 import FMICallException

    inst = Instance(name)
    try:
        with pytest.raises(FMICallException) as exc:
            inst.init(**params)
        assert "(error)" in str(exc.value), exc.value
        text = "\n".join(m[2] for m in inst.messages)
        inst.fmu.reset()
        inst.init().run_to(0.01, 1e-3)
    finally:
        inst.close()
    return text


def assert_parameter_rejected(name, params, param, rule):
    """A bad parameter ends initialization with a message naming it, its value and the rule."""
    text = init_failure_text(name, **params)
    assert f"parameter {param} = {params[param]!r}" in text and rule in text, text


def run_libcosim(name, stop_time, step, outputs, initial=None, timeout=120):
    """Run one FMU under libcosimpy in a separate process; return {output: final value}."""
    script = ROOT / "tests" / "_libcosim_runner.py"
    payload = json.dumps({"fmu": str(fmu_path(name)), "stop_time": stop_time, "step": step,
                          "outputs": outputs, "initial": initial or {}})
    proc = subprocess.run([sys.executable, str(script), payload], capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"libcosimpy run failed ({proc.returncode}): {proc.stderr[-2000:]}"
    return json.loads(proc.stdout.strip().splitlines()[-1])


# The C hosts' flags.  -ffp-contract=off as the FMUs' own: a host computes the communication points
# and step sizes it passes to the FMU (fmi2_host.c's ``t - (k - 1) * h``, fmi3_host.c's Euler step
# ``x[i] += h * dx[i]``), and a compiler for a target with fused multiply-add (aarch64; gcc on any
# target with FMA) contracts those by default: the aarch64 host, built by zig's clang, gave
# fmi2DoStep a step 1 ulp off x86-64's (an fmsub), and the FMU's outputs differed by 1 ulp from
# t = 0.019 on (issue 44).
HOST_CFLAGS = ("-O1", "-Wall", "-ffp-contract=off")


def compile_c_host(source, exe):
    """Compile a C importer of tests/c_host/ with the resolved C compiler against fmpy's FMI headers;
    assert it links no libpython (it must bring nothing but dlopen)."""
    from pogofmu import exporter as build
    from pogofmu.codegen.build import c_compiler

    cc = c_compiler()  # the system's, else zig cc (the ziglang package): never missing
    subprocess.run([*cc, *HOST_CFLAGS, f"-I{build.fmi_headers()}", str(source), "-o", str(exe), "-ldl"],
                   check=True)
    needed = subprocess.run(["readelf", "-d", str(exe)], capture_output=True, text=True, check=True).stdout
    assert "libpython" not in needed
    return exe


def clean_venv():
    """A venv with fmpy and numpy only (the versions of the project's venv), cached in build/."""
    import shutil

    import fmpy
    import numpy

    venv = ROOT / "build" / f"venv-fmpy-{fmpy.__version__}-numpy-{numpy.__version__}"
    python = venv / "bin" / "python"
    if not (venv / ".complete").exists():
        shutil.rmtree(venv, ignore_errors=True)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        # from the wheels tasks.py keeps in the project's venv (no package index at test time)
        wheels = Path(sys.prefix) / "wheels"
        source = ["--no-index", "--find-links", str(wheels)] if wheels.is_dir() else []
        if IN_CI:
            assert source, f"{wheels} missing: tasks.py downloads fmpy's and numpy's wheels when it sets up the venv"
        subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", *source,
                        f"fmpy=={fmpy.__version__}", f"numpy=={numpy.__version__}"], check=True)
        (venv / ".complete").write_text("ok")
    return python


# ---- one instance driven through the FMU's own functions ---------------------------------------

BACKENDS = ["", "native/"]  # the Python-hosted FMUs dist/*.fmu, dist/fmi3/*.fmu; the native dist/native/...
D, B = ctypes.c_double, ctypes.c_bool
OK, ERROR = 0, 3
# the call states as test_call_states models them, and the names the FMUs give them
I, INIT, STEP, EVENT, CONT, TERM = "Instantiated", "Initialization", "Step", "Event", "ContinuousTime", "Terminated"
STATE_NAMES = {I: "Instantiated", INIT: "Initialization Mode", STEP: None, EVENT: "Event Mode",
               CONT: "Continuous-Time Mode", TERM: "Terminated"}


class RawInstance:
    """One instance of a built FMU driven through its own functions (statuses returned, the log
    collected), FMI 2.0 co-simulation or FMI 3.0 co-simulation (with or without event mode) or
    model exchange."""

    def __init__(self, backend, fmi, interface="cs", event_mode=False, name="PogoStick", unzip_dir=None):
        from fmpy import extract, read_model_description

        self.fmi, self.interface, self.event_mode = fmi, interface, event_mode
        self.messages = []
        path = DIST / backend / ("fmi3/" if fmi == 3 else "") / f"{name}.fmu"
        md = read_model_description(str(path))
        self.vars = {v.name: v for v in md.modelVariables}
        unzipped = extract(str(path)) if unzip_dir is None else unzip_dir
        if fmi == 2:
            from fmpy.fmi2 import FMU2Slave

            from pogofmu.fmpy_raw import Fmi2Callbacks

            self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                                 instanceName="raw")
            self._callbacks = Fmi2Callbacks(lambda status, category, text: self.messages.append((status, text)))
            self._cb = self._callbacks.struct  # (the struct, for the tests that instantiate by hand)
            self.fmu.instantiate(loggingOn=True, callbacks=self._cb)
        else:
            from fmpy.fmi3 import FMU3Model, FMU3Slave

            log = lambda env, status, cat, msg: self.messages.append((status, msg.decode()))  # noqa: E731
            if interface == "cs":
                self.fmu = FMU3Slave(guid=md.guid, unzipDirectory=unzipped,
                                     modelIdentifier=md.coSimulation.modelIdentifier, instanceName="raw")
                self.fmu.instantiate(loggingOn=True, eventModeUsed=event_mode, earlyReturnAllowed=event_mode,
                                     logMessage=log)
            else:
                self.fmu = FMU3Model(guid=md.guid, unzipDirectory=unzipped,
                                     modelIdentifier=md.modelExchange.modelIdentifier, instanceName="raw")
                self.fmu.instantiate(loggingOn=True, logMessage=log)
            self.nx = len(md.derivatives)
        self.t = 0.0

    def raw(self, name, *args):
        return raw_call(self.fmu, name, *args)

    def last(self):
        return self.messages[-1][1] if self.messages else ""

    def step_name(self):
        return "Step Complete (initialized)" if self.fmi == 2 else "Step Mode"

    # ---- the transitions (each asserts OK) --------------------------------------------------
    def enter_initialization(self):
        if self.fmi == 2:
            assert self.raw("fmi2SetupExperiment", 0, D(0.0), D(0.0), 0, D(0.0)) == OK
            assert self.raw("fmi2EnterInitializationMode") == OK, self.last()
        else:
            assert self.raw("fmi3EnterInitializationMode", 0, D(0.0), D(0.0), 0, D(0.0)) == OK, self.last()

    def exit_initialization(self):
        assert self.raw(f"fmi{self.fmi}ExitInitializationMode") == OK, self.last()

    def do_step(self, h=1e-3):
        if self.fmi == 2:
            status = self.raw("fmi2DoStep", D(self.t), D(h), 1)
            self.t += h
            return status, False
        flags = [B(), B(), B(), D()]
        status = self.raw("fmi3DoStep", D(self.t), D(h), True, *[ctypes.byref(f) for f in flags])
        if status <= 1:
            self.t = flags[3].value
        return status, flags[0].value

    def reach(self, mode):
        """From Instantiated to `mode` by the standard's transitions."""
        if mode == I:
            return
        self.enter_initialization()
        self.t = 0.0
        if mode == INIT:
            return
        self.exit_initialization()  # FMI 2.0 and FMI 3.0 CS without event mode: Step; else Event Mode
        if mode == EVENT:
            return
        if self.interface == "me":
            assert self.raw("fmi3EnterContinuousTimeMode") == OK, self.last()
            if mode == CONT:
                return
        else:
            if self.fmi == 3 and self.event_mode:
                assert self.raw("fmi3EnterStepMode") == OK, self.last()
            assert self.do_step()[0] == OK, self.last()
            if mode == STEP:
                return
        assert self.raw(f"fmi{self.fmi}Terminate") == OK, self.last()

    def assert_in(self, mode):
        """The instance is in `mode`: a call the standard forbids there is refused naming it, and
        the call that goes on from it succeeds."""
        name = self.step_name() if mode == STEP else STATE_NAMES[mode]
        if self.interface == "me":
            probe = ("fmi3CompletedIntegratorStep", True, ctypes.byref(B()), ctypes.byref(B())) if mode != CONT else \
                ("fmi3EnterInitializationMode", 0, D(0.0), D(0.0), 0, D(0.0))
            assert self.raw(*probe) == ERROR
        elif mode == STEP:
            assert self.raw(f"fmi{self.fmi}EnterInitializationMode", *(() if self.fmi == 2 else
                                                                       (0, D(0.0), D(0.0), 0, D(0.0)))) == ERROR
        else:
            assert self.do_step()[0] == ERROR
        assert f"not allowed in {name}" in self.last(), (mode, self.last())
        if mode == I:
            self.enter_initialization()
        elif mode == INIT:
            self.exit_initialization()
        elif mode == STEP:
            assert self.do_step()[0] == OK, self.last()
        elif mode == EVENT:
            refs = [ctypes.byref(B()) for _ in range(5)] + [ctypes.byref(D())]
            assert self.raw("fmi3UpdateDiscreteStates", *refs) == OK, self.last()
        elif mode == CONT:
            assert self.raw("fmi3CompletedIntegratorStep", True, ctypes.byref(B()), ctypes.byref(B())) == OK, self.last()
        else:
            assert self.raw(f"fmi{self.fmi}Reset") == OK, self.last()

    def get_state(self):
        return self.fmu.getFMUstate() if self.fmi == 2 else self.fmu.getFMUState()

    def set_state(self, state):
        return self.raw("fmi2SetFMUstate" if self.fmi == 2 else "fmi3SetFMUState", state)

    def serialize(self, state):
        return bytes(self.fmu.serializeFMUstate(state) if self.fmi == 2 else self.fmu.serializeFMUState(state))

    def deserialize(self, blob):
        return self.fmu.deSerializeFMUstate(blob) if self.fmi == 2 else self.fmu.deserializeFMUState(blob)

    def free(self, state):
        self.raw("fmi2FreeFMUstate" if self.fmi == 2 else "fmi3FreeFMUState", ctypes.byref(state))

    def close(self):
        self.fmu.freeInstance()


# ---- FMUs driven through fmpy or a C host, for the tests that need the FMU's own functions --------

def fmi_function(inst, name, restype=None):
    """The FMU's function `name` of a :class:`RawInstance` as a fresh ctypes object (fmpy's argument
    types left alone)."""
    fn = inst.fmu.dll[name]
    if restype is not None:
        fn.restype = restype
    return fn


def fmi3_fmpy_instance(name, interface="cs", event_mode=False):
    """An FMI 3.0 instance of dist/fmi3/<name>.fmu through fmpy, instantiated with logging on:
    co-simulation (with or without event mode and early return) or model exchange (``"me"``).
    Returns the fmpy object and the list its messages are appended to as ``(status, text)``."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Model, FMU3Slave

    path = DIST / "fmi3" / f"{name}.fmu"
    md = read_model_description(str(path))
    messages = []
    log = lambda env, status, cat, msg: messages.append((status, msg.decode()))  # noqa: E731
    if interface == "cs":
        fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="calls3")
        fmu.instantiate(loggingOn=True, eventModeUsed=event_mode, earlyReturnAllowed=event_mode, logMessage=log)
    else:
        fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.modelExchange.modelIdentifier,
                        instanceName="calls3")
        fmu.instantiate(loggingOn=True, logMessage=log)
    return fmu, messages


def c_host_run(tmp_path, unzipdir, env=None):
    """The FMI 2.0 FMU unzipped in ``unzipdir`` run for 0.01 s in steps of 1 ms by the C host
    tests/c_host/fmi2_host.c (compiled into ``tmp_path``; no Python in it), in an empty environment
    unless ``env`` is given: the finished process, one line of ``y`` per communication point."""
    from fmpy import read_model_description

    host = compile_c_host(ROOT / "tests" / "c_host" / "fmi2_host.c", tmp_path / "fmi2_host")
    md = read_model_description(str(Path(unzipdir) / "modelDescription.xml"))
    y = next(v.valueReference for v in md.modelVariables if v.name == "y")
    return subprocess.run([str(host), str(unzipdir), md.coSimulation.modelIdentifier, md.guid, "0.01", "1e-3", str(y), "-"],
                          capture_output=True, text=True, timeout=120, env=env or {"PATH": "/usr/bin:/bin"})


# ---- interrupting a sweep at a point the test controls (tests/_sweep_gate.py) ------------------

def _stacks_of(proc) -> str:
    """What a process that did not get where the test waited for was doing: SIGABRT makes a
    process started with PYTHONFAULTHANDLER=1 write every thread's stack to its stderr."""
    import signal
    import subprocess

    if proc is None or proc.poll() is not None:
        return ""
    proc.send_signal(signal.SIGABRT)
    try:
        out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    return f"; the process's output: {(out or '')[-2000:]}\n{(err or '')[-8000:]}"


def wait_for(predicate, proc=None, timeout=600.0):
    """Poll ``predicate`` until it holds (the sweep process, if given, still running); the bound is
    only a guard against a hang, never what decides the outcome."""
    import time

    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            raise AssertionError("timed out waiting (the test would otherwise hang)" + _stacks_of(proc))
        if proc is not None and proc.poll() is not None:
            out, err = proc.communicate()
            raise AssertionError(f"the sweep ended (exit {proc.returncode}) before the test could interrupt it: "
                                 f"{out[-2000:]} {err[-3000:]}")
        time.sleep(0.02)


def saved_runs(parts: Path) -> dict:
    """``run_id -> row`` of the part files an unfinished sweep has saved in ``parts``."""
    import pyarrow.parquet as pq

    return {r["run_id"]: r for f in parts.glob("chunk-*.parquet") for r in pq.read_table(f).to_pylist()}
