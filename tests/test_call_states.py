"""Model-based testing of the FMI call sequence: hypothesis state machines drive each FMU through
random sequences of calls, legal and illegal, and check every status against the standard's state
machine, written out here from the standard's text (:func:`standard`; FMI 2.0 co-simulation; FMI
3.0 co-simulation with and without event mode; FMI 3.0 model exchange), independently of the
FMUs' own table (fmu_src/native/call_states.h): a legal call succeeds, an illegal one returns
Error naming the function, nothing is ever Fatal, and the instance stays usable after every Error
(the next legal call succeeds).  FMU states are taken, serialized, deserialized, damaged, restored
and freed in every call state, and restoring one puts the model back where the state was taken.
Written-out sequences besides: calls out of sequence in FMI 2.0 and FMI 3.0 (and a bad tolerance,
an unknown log category, a co-simulation function on a model-exchange instance) are refused with
Error naming the function and the state, and the instance goes on.

Both backends, on the project's PogoStick and HopController and on two user models drawn by the
event semantics' generator (tests/hybrid_draws.py); derandomized and short in CI (``POGOFMU_STATEFUL_EXAMPLES=500`` for a long run),
and the native FMUs once more with their sources compiled under AddressSanitizer and UBSan.
"""
import atexit
import ctypes
import functools
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, precondition, rule

from pogofmu.fmpy_raw import raw_call
from support import BACKENDS, DIST, Instance, RawInstance, require, ROOT
from support import fmi3_fmpy_instance as _fmi3_raw

EXAMPLES = int(os.environ.get("POGOFMU_STATEFUL_EXAMPLES", "10"))
SETTINGS = settings(max_examples=EXAMPLES, stateful_step_count=30, derandomize=True, deadline=None,
                    suppress_health_check=list(HealthCheck))
D, B = ctypes.c_double, ctypes.c_bool
OK, ERROR = 0, 3

# the standard's states (FMI 2.0 co-simulation; FMI 3.0), as the tests model them
I, INIT, STEP, EVENT, CONT, TERM = "Instantiated", "Initialization", "Step", "Event", "ContinuousTime", "Terminated"
ANY = frozenset({I, INIT, STEP, EVENT, CONT, TERM})
NONE = frozenset()
RESTORED = "the state's"  # a successful set/deserialize-and-set leads to the call state the FMU state holds


def standard(fmi, interface="cs", event_mode=False):
    """The standard's state machine of one kind of instance: for each function, the call states
    that allow it and the state a successful call leads to (None: it stays).

    FMI 2.0 co-simulation, §4.2.4 (the slave's state machine and the table of which function may
    be called where; Step Complete is "Step" here, stepInProgress never happens: no fmi2Pending).
    FMI 3.0, §3.2 (model exchange) and §4.2 (co-simulation): Initialization Mode leads to Event
    Mode in model exchange and in co-simulation with event mode, else to Step Mode; the FMU state
    functions and Reset are allowed in every state."""
    state_functions = ("GetFMUstate", "SetFMUstate", "FreeFMUstate", "SerializedFMUstateSize",
                       "SerializeFMUstate", "DeSerializeFMUstate") if fmi == 2 else \
        ("GetFMUState", "SetFMUState", "FreeFMUState", "SerializedFMUStateSize", "SerializeFMUState",
         "DeserializeFMUState")
    table = {f"fmi{fmi}{name}": (ANY, RESTORED if name.startswith("Set") else None) for name in state_functions}
    table.update({f"fmi{fmi}Reset": (ANY, I), f"fmi{fmi}SetDebugLogging": (ANY, None)})
    if fmi == 2:
        table.update({
            "fmi2SetupExperiment": ({I}, None),
            "fmi2EnterInitializationMode": ({I}, INIT),
            "fmi2ExitInitializationMode": ({INIT}, STEP),
            "fmi2DoStep": ({STEP}, None),
            "fmi2Terminate": ({STEP}, TERM),
            "fmi2GetReal": ({INIT, STEP, TERM}, None),
            "fmi2SetReal": ({I, INIT, STEP}, None),  # of an input
        })
        return table
    cs, me = interface == "cs", interface == "me"
    table.update({
        "fmi3EnterInitializationMode": ({I}, INIT),
        "fmi3ExitInitializationMode": ({INIT}, EVENT if me or event_mode else STEP),
        "fmi3EnterEventMode": ({STEP} if cs and event_mode else {CONT} if me else NONE, EVENT),
        "fmi3UpdateDiscreteStates": ({EVENT}, None),
        "fmi3EnterStepMode": ({EVENT} if cs else NONE, STEP),
        "fmi3EnterContinuousTimeMode": ({EVENT} if me else NONE, CONT),
        "fmi3DoStep": ({STEP} if cs else NONE, None),
        "fmi3Terminate": ({STEP, EVENT} if cs else {EVENT, CONT}, TERM),
        "fmi3SetTime": ({EVENT, CONT} if me else NONE, None),
        "fmi3GetContinuousStateDerivatives": ({INIT, EVENT, CONT, TERM} if me else NONE, None),
        "fmi3GetContinuousStates": ({INIT, EVENT, CONT, TERM} if me else NONE, None),
        "fmi3SetContinuousStates": ({CONT} if me else NONE, None),
        "fmi3CompletedIntegratorStep": ({CONT} if me else NONE, None),
        # §2.3.3 to §2.3.5, §3.2.1, §4.2.1, "Allowed Function Calls" of each state: fmi3Set{VariableType}
        # in Instantiated, Initialization Mode, Event Mode, Step Mode, Continuous-Time Mode (a
        # continuous input or state only); fmi3Get{VariableType} from Initialization Mode on.
        # Terminated lists getters only ("the final values of all variables ... can be retrieved")
        "fmi3SetFloat64": ({I, INIT, EVENT, CONT, STEP}, None),  # of a continuous input
        "fmi3SetInt32": ({I, INIT, EVENT, STEP}, None),  # of a discrete input or a parameter
        "fmi3GetFloat64": ({INIT, EVENT, CONT, STEP, TERM}, None),
        # §2.3.2, Instantiated; §4.2.1, Step Mode; §2.3.6, Event Mode (to Reconfiguration Mode "in
        # Model Exchange"): where fmi3EnterConfigurationMode may be called — and it "must not be
        # called if the FMU contains no structural parameter", as these FMUs do: never legal here.
        # fmi3ExitConfigurationMode: in Configuration Mode and Reconfiguration Mode only, which an
        # FMU without structural parameters never enters
        "fmi3EnterConfigurationMode": ({I, STEP} if cs else {I, EVENT}, None),
        "fmi3ExitConfigurationMode": (NONE, None),
    })
    return table


class Machine(RuleBasedStateMachine):
    """Common bookkeeping: the modelled state, the communication time, the saved FMU states; every
    call goes through :meth:`call`, which checks its status against :func:`standard`."""

    NAME = "PogoStick"
    FMI, INTERFACE, EVENT_MODE = 2, "cs", False

    def __init__(self):
        super().__init__()
        self.messages = []
        self.mode, self.t, self.saved = I, 0.0, []
        self.pending = False  # FMI 3.0 CS: the last step returned eventHandlingNeeded (Event Mode next)
        self.table = standard(self.FMI, self.INTERFACE, self.EVENT_MODE)
        self.fmu = self.make()

    def dist(self):
        """The folder the FMU comes from (laid out as dist/)."""
        return DIST

    def raw(self, name, *args):
        return raw_call(self.fmu, name, *args)

    def fn(self, name):
        return f"fmi{self.FMI}{name}"

    def call(self, name, *args, also=True, legal_args=True):
        """Call `name`; allowed if the standard allows it in the modelled state (and `also`, a
        rule of the standard beyond the state); True if it succeeded (the model then moves on)."""
        status = self.raw(name, *args)
        states, after = self.table[name]
        allowed = self.mode in states and also
        assert status != 4, f"{name}: Fatal ({self.messages[-1:]})"
        if allowed and legal_args:
            assert status in (OK, 1), f"{name} in {self.mode}: status {status} ({self.messages[-3:]})"
        elif not allowed:
            assert status == ERROR, f"{name} in {self.mode}: status {status}, expected Error"
            assert name in self.messages[-1][1] and "refused" in self.messages[-1][1], self.messages[-1]
        ok = status in (OK, 1)
        if ok and after not in (None, RESTORED):
            self.mode = after
        return ok

    # ---- FMU states: taken, serialized, damaged, restored and freed in every call state ----------
    @rule()
    def get_state(self):
        state = ctypes.c_void_p()
        if self.call(self.fn("GetFMUstate" if self.FMI == 2 else "GetFMUState"), ctypes.byref(state)):
            self.saved.append((state, self.mode, self.t, self.pending))

    @precondition(lambda self: self.saved)
    @rule(data=st.data())
    def set_state(self, data):
        state, mode, t, pending = data.draw(st.sampled_from(self.saved))
        if self.call(self.fn("SetFMUstate" if self.FMI == 2 else "SetFMUState"), state):
            self.mode, self.t, self.pending = mode, t, pending

    def _serialize(self, state):
        size = ctypes.c_size_t()
        names = ("SerializedFMUstateSize", "SerializeFMUstate") if self.FMI == 2 else \
            ("SerializedFMUStateSize", "SerializeFMUState")
        assert self.call(self.fn(names[0]), state, ctypes.byref(size))
        buf = (ctypes.c_char if self.FMI == 2 else ctypes.c_uint8) * size.value
        blob = buf()
        assert self.call(self.fn(names[1]), state, blob, size)
        return bytes(blob)

    def _deserialize(self, blob, legal=True):
        buf = ((ctypes.c_char if self.FMI == 2 else ctypes.c_uint8) * len(blob)).from_buffer_copy(blob)
        state = ctypes.c_void_p()
        name = self.fn("DeSerializeFMUstate" if self.FMI == 2 else "DeserializeFMUState")
        status = self.raw(name, buf, len(blob), ctypes.byref(state))
        if legal:
            assert status == OK, f"{name} in {self.mode}: status {status} ({self.messages[-3:]})"
        return status, state

    @precondition(lambda self: self.saved)
    @rule(data=st.data())
    def serialize_round_trip(self, data):
        """Serialized and deserialized in the current call state (any): a state like the original,
        restoring the call state it was taken in."""
        state, mode, t, pending = data.draw(st.sampled_from(self.saved))
        _, copy = self._deserialize(self._serialize(state))
        self.saved.append((copy, mode, t, pending))

    @precondition(lambda self: self.saved)
    @rule(data=st.data(), where=st.floats(0.0, 1.0), bit=st.integers(0, 7))
    def damaged_state_is_refused(self, data, where, bit):
        """A serialized state with one bit flipped anywhere is refused with Error; nothing changes."""
        state = data.draw(st.sampled_from(self.saved))[0]
        blob = bytearray(self._serialize(state))
        blob[min(int(where * len(blob)), len(blob) - 1)] ^= 1 << bit
        status, _ = self._deserialize(bytes(blob), legal=False)
        assert status == ERROR and "refused" in self.messages[-1][1], (status, self.messages[-1:])

    @precondition(lambda self: self.saved)
    @rule(data=st.data())
    def free_state(self, data):
        k = data.draw(st.integers(0, len(self.saved) - 1))
        state = self.saved.pop(k)[0]
        assert self.call(self.fn("FreeFMUstate" if self.FMI == 2 else "FreeFMUState"), ctypes.byref(state))

    @rule()
    def reset(self):
        if self.call(self.fn("Reset")):
            self.t, self.pending = 0.0, False

    @rule(known=st.booleans())
    def debug_logging(self, known):
        cats = (ctypes.c_char_p * 1)(b"logEvents" if known else b"logNoSuchCategory")
        status = self.raw(self.fn("SetDebugLogging"), 1, 1, cats)
        if known:
            assert status == OK, self.messages[-1:]
        else:
            assert status == ERROR and "not a log category" in self.messages[-1][1]

    def input_vr(self):
        """A Real input's value reference: the first input of the FMU's."""
        name = next(n for n, v in self.vars.items() if v.causality == "input" and v.type in ("Real", "Float64"))
        return (ctypes.c_uint32 * 1)(self.vars[name].valueReference)

    def teardown(self):
        for state, *_ in self.saved:
            self.raw(self.fn("FreeFMUstate" if self.FMI == 2 else "FreeFMUState"), ctypes.byref(state))
        self.fmu.freeInstance()


# =============================================================================================
# FMI 2.0 co-simulation
# =============================================================================================

class Fmi2CoSimulation(Machine):
    def make(self):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        from pogofmu.fmpy_raw import Fmi2Callbacks

        path = self.dist() / f"{self.NAME}.fmu"
        md = read_model_description(str(path))
        self.vars = {v.name: v for v in md.modelVariables}
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="machine")
        self._cb = Fmi2Callbacks(lambda status, category, text: self.messages.append((status, text)))
        fmu.instantiate(loggingOn=True, callbacks=self._cb.struct)
        return fmu

    @rule()
    def setup(self):
        self.call("fmi2SetupExperiment", 0, D(0.0), D(0.0), 0, D(0.0))

    @rule()
    def enter_initialization(self):
        self.call("fmi2EnterInitializationMode")

    @rule()
    def exit_initialization(self):
        if self.call("fmi2ExitInitializationMode"):
            self.t = 0.0

    @rule(h=st.sampled_from([1e-3, 4e-3]))
    def do_step(self, h):
        if self.call("fmi2DoStep", D(self.t), D(h), 1):
            self.t += h

    @rule(h=st.sampled_from([-1e-3, float("nan")]))
    def bad_step(self, h):
        """Any state: refused (by state, or by the argument), never worse."""
        status = self.raw("fmi2DoStep", D(self.t), D(h), 1)
        assert status == ERROR and not any(m[0] >= 4 for m in self.messages)

    @rule()
    def terminate(self):
        self.call("fmi2Terminate")

    @rule()
    def get_output(self):
        name = "y" if "y" in self.vars else next(n for n, v in self.vars.items()
                                                  if v.causality == "output" and v.type == "Real")
        vr = (ctypes.c_uint32 * 1)(self.vars[name].valueReference)
        self.call("fmi2GetReal", vr, 1, (D * 1)())

    @rule(value=st.floats(-2.0, 2.0))
    def set_input(self, value):
        self.call("fmi2SetReal", self.input_vr(), 1, (D * 1)(value))


class Fmi2Controller(Fmi2CoSimulation):
    NAME = "HopController"


# =============================================================================================
# FMI 3.0
# =============================================================================================

class Fmi3Machine(Machine):
    FMI, INTERFACE, EVENT_MODE = 3, "cs", True
    FOLDER = "fmi3"

    def make(self):
        from fmpy import extract, read_model_description
        from fmpy.fmi3 import FMU3Model, FMU3Slave

        path = self.dist() / self.FOLDER / f"{self.NAME}.fmu"
        md = read_model_description(str(path))
        self.vars = {v.name: v for v in md.modelVariables}
        self.nx, self.nz = len(md.derivatives), len(md.eventIndicators)
        log = lambda env, status, cat, msg: self.messages.append((status, msg.decode(errors="replace")))  # noqa: E731
        if self.INTERFACE == "cs":
            fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                            modelIdentifier=md.coSimulation.modelIdentifier, instanceName="machine")
            fmu.instantiate(loggingOn=True, eventModeUsed=self.EVENT_MODE, earlyReturnAllowed=self.EVENT_MODE,
                            logMessage=log)
        else:
            fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(str(path)),
                            modelIdentifier=md.modelExchange.modelIdentifier, instanceName="machine")
            fmu.instantiate(loggingOn=True, logMessage=log)
        return fmu

    @rule()
    def enter_initialization(self):
        self.call("fmi3EnterInitializationMode", 0, D(0.0), D(0.0), 0, D(0.0))

    @rule()
    def exit_initialization(self):
        if self.call("fmi3ExitInitializationMode"):
            self.t = 0.0

    @rule()
    def enter_event_mode(self):
        if self.call("fmi3EnterEventMode"):
            self.pending = False

    @rule()
    def update_discrete_states(self):
        refs = [ctypes.byref(B()) for _ in range(5)] + [ctypes.byref(D())]
        self.call("fmi3UpdateDiscreteStates", *refs)

    @rule()
    def enter_step_mode(self):
        self.call("fmi3EnterStepMode")

    @rule()
    def enter_continuous_time_mode(self):
        self.call("fmi3EnterContinuousTimeMode")

    @rule(h=st.sampled_from([1e-3, 4e-3]))
    def do_step(self, h):
        flags = [B(), B(), B(), D()]
        refs = [ctypes.byref(f) for f in flags]
        # FMI 3.0 §4.2.1: after eventHandlingNeeded the importer enters Event Mode before stepping on
        if self.call("fmi3DoStep", D(self.t), D(h), True, *refs, also=not self.pending):
            self.t, self.pending = flags[3].value, flags[0].value

    @rule()
    def terminate(self):
        if self.call("fmi3Terminate"):
            self.pending = False

    @rule(dt=st.sampled_from([0.0, 1e-3]))
    def set_time(self, dt):
        if self.call("fmi3SetTime", D(self.t + dt)):
            self.t += dt

    @rule()
    def derivatives(self):
        buf = (D * max(self.nx, 1))()
        self.call("fmi3GetContinuousStateDerivatives", buf, self.nx)

    @rule()
    def states_round_trip(self):
        buf = (D * max(self.nx, 1))()
        got = self.call("fmi3GetContinuousStates", buf, self.nx)
        self.call("fmi3SetContinuousStates", buf, self.nx, legal_args=got)

    @rule()
    def completed_integrator_step(self):
        refs = [ctypes.byref(B()), ctypes.byref(B())]
        self.call("fmi3CompletedIntegratorStep", True, *refs)

    @rule(value=st.floats(-2.0, 2.0))
    def set_input(self, value):
        self.call("fmi3SetFloat64", self.input_vr(), 1, (D * 1)(value), 1)

    @rule(value=st.integers(0, 1))
    def set_discrete(self, value):
        """An Int32: the controller's discrete input s (legal wherever the state allows it), else the
        fixed parameter log_events (legal by its variability in Instantiated and Initialization Mode
        only: elsewhere only a refusal by the call state is checked)."""
        var = self.vars["s"] if "s" in self.vars and self.vars["s"].causality == "input" else self.vars["log_events"]
        self.call("fmi3SetInt32", (ctypes.c_uint32 * 1)(var.valueReference), 1, (ctypes.c_int32 * 1)(value), 1,
                  legal_args=var.causality == "input" or self.mode in (I, INIT))

    @rule()
    def get_output(self):
        vr = next(v.valueReference for v in self.vars.values() if v.causality == "output" and v.type == "Float64")
        self.call("fmi3GetFloat64", (ctypes.c_uint32 * 1)(vr), 1, (D * 1)(), 1)

    @rule()
    def configuration_mode(self):
        """Never legal for an FMU without structural parameters: Error in every call state; where the
        state allows fmi3EnterConfigurationMode the refusal names the missing structural parameters,
        elsewhere the call state; fmi3ExitConfigurationMode is refused naming the call state."""
        for name in ("fmi3EnterConfigurationMode", "fmi3ExitConfigurationMode"):
            status = self.raw(name)
            text = self.messages[-1][1] if self.messages else ""
            assert status == ERROR and text.startswith(f"{name} refused"), (name, self.mode, status, text)
            allowed = self.mode in self.table[name][0]
            assert ("structural parameter" in text) == allowed and ("not allowed in" in text) != allowed, \
                (name, self.mode, text)


class Fmi3EventMode(Fmi3Machine):
    INTERFACE, EVENT_MODE = "cs", True


class Fmi3NoEventMode(Fmi3Machine):
    INTERFACE, EVENT_MODE = "cs", False


class Fmi3ModelExchange(Fmi3Machine):
    INTERFACE, EVENT_MODE = "me", False


class Fmi3ControllerME(Fmi3Machine):
    NAME, INTERFACE, EVENT_MODE = "HopController", "me", False


class NativeFmi2CoSimulation(Fmi2CoSimulation):
    """The native FMU (dist/native/): the same state machine, the same table."""
    NAME = "native/PogoStick"


class NativeFmi2Controller(Fmi2CoSimulation):
    NAME = "native/HopController"


class NativeFmi3EventMode(Fmi3EventMode):
    FOLDER = "native/fmi3"


class NativeFmi3NoEventMode(Fmi3NoEventMode):
    FOLDER = "native/fmi3"


class NativeFmi3ModelExchange(Fmi3ModelExchange):
    FOLDER = "native/fmi3"


class NativeFmi3ControllerME(Fmi3ControllerME):
    FOLDER = "native/fmi3"


# ---- two user models drawn by the event semantics' generator (tests/hybrid_draws.py) ----------------
DRAWN = ("DrawnA", "DrawnB")


@functools.lru_cache(maxsize=None)
def drawn_dist() -> Path:
    """The native FMUs of two drawn models (their files written in a temporary folder and exported by
    `pogofmu export`, as a user does); POGOFMU_DRAWN_DIST names an existing folder instead (the
    sanitizer run's instrumented copies)."""
    if os.environ.get("POGOFMU_DRAWN_DIST"):
        return Path(os.environ["POGOFMU_DRAWN_DIST"])
    from hybrid_draws import model_source, two_drawn_models
    from support import run_pogofmu

    folder = Path(tempfile.mkdtemp(prefix="pogofmu-drawn-machines-"))
    atexit.register(shutil.rmtree, folder, True)  # the FMUs live as long as the session that loads them
    files = []
    for name, d in zip(DRAWN, two_drawn_models()):
        files.append(f"{name.lower()}.py")
        (folder / files[-1]).write_text(model_source(d, name))
    proc = run_pogofmu("export", *files, "--out", "out", "--backend", "native", "--platforms", "x86_64-linux",
                       cwd=folder, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return folder / "out"


class _Drawn:
    def dist(self):
        return drawn_dist()


class DrawnAFmi2CoSimulation(_Drawn, Fmi2CoSimulation):
    NAME = "native/DrawnA"


class DrawnBFmi2CoSimulation(_Drawn, Fmi2CoSimulation):
    NAME = "native/DrawnB"


class DrawnAFmi3EventMode(_Drawn, Fmi3EventMode):
    NAME, FOLDER = "DrawnA", "native/fmi3"


class DrawnBFmi3ModelExchange(_Drawn, Fmi3ModelExchange):
    NAME, FOLDER = "DrawnB", "native/fmi3"


DRAWN_MACHINES = [DrawnAFmi2CoSimulation, DrawnBFmi2CoSimulation, DrawnAFmi3EventMode, DrawnBFmi3ModelExchange]
NATIVE = [NativeFmi2CoSimulation, NativeFmi2Controller, NativeFmi3EventMode, NativeFmi3NoEventMode,
          NativeFmi3ModelExchange, NativeFmi3ControllerME, *DRAWN_MACHINES]
MACHINES = [Fmi2CoSimulation, Fmi2Controller, *NATIVE, Fmi3EventMode, Fmi3NoEventMode, Fmi3ModelExchange,
            Fmi3ControllerME]


def run_machines(machines):
    from hypothesis.stateful import run_state_machine_as_test

    for machine in machines:
        run_state_machine_as_test(machine, settings=SETTINGS)


@pytest.mark.parametrize("machine", MACHINES, ids=[m.__name__ for m in MACHINES])
def test_random_call_sequences_follow_the_standard(machine):
    run_machines([machine])


# ---- the same sequences on the native FMUs compiled with AddressSanitizer and UBSan --------------

SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer", "-g", "-O1"]


def _sanitizer_runtime(cc, tmp_path):
    """libasan's path if `cc` compiles and links a shared library with the sanitizers, else None."""
    probe = tmp_path / "probe.c"
    probe.write_text("int probe(int x) { return x + 1; }\n")
    if subprocess.run([cc, *SANITIZE, "-shared", "-fPIC", str(probe), "-o", str(tmp_path / "probe.so")],
                      capture_output=True).returncode:
        return None
    lib = subprocess.run([cc, "-print-file-name=libasan.so"], capture_output=True, text=True).stdout.strip()
    return lib if os.path.isabs(lib) and os.path.exists(lib) else None


def _sanitized_copy(fmu, dest, cc):
    """`fmu` (a native FMU) with its Linux binary rebuilt from its own sources/ under the sanitizers."""
    unzipped = dest.with_suffix(".unzipped")
    with zipfile.ZipFile(fmu) as z:
        z.extractall(unzipped)
    binary = next(p for p in (unzipped / "binaries").glob("*linux*/*.so"))
    sources = sorted((unzipped / "sources").glob("*.c"))
    proc = subprocess.run([cc, "-std=c99", "-ffp-contract=off", "-fno-strict-aliasing", "-fPIC", "-shared",
                           "-fvisibility=hidden", *SANITIZE, f"-I{unzipped / 'sources'}", *map(str, sources),
                           "-o", str(binary), "-lm"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    needed = subprocess.run(["readelf", "-d", str(binary)], capture_output=True, text=True).stdout
    assert "libasan" in needed and "libubsan" in needed, needed  # instrumented, not the shipped binary
    dest.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(dest, "w") as z:
        for p in sorted(unzipped.rglob("*")):
            if p.is_file():
                z.write(p, p.relative_to(unzipped).as_posix())


def test_random_call_sequences_under_address_sanitizer(tmp_path):
    """The native machines once more, on FMUs whose C was compiled with -fsanitize=address,undefined
    (every out-of-bounds access, use after free or undefined behaviour aborts the run) — in a
    process of its own, with the runtime preloaded into the Python that hosts them (skipped only
    where the compiler cannot build with the sanitizers)."""
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    libasan = _sanitizer_runtime(cc, tmp_path) if cc else None
    require(libasan is not None, f"-fsanitize=address,undefined from {cc or 'a C compiler'} (Debian gcc)")
    dist = tmp_path / "dist"
    drawn = tmp_path / "drawn"
    for folder in ("native", "native/fmi3"):
        for name in ("PogoStick", "HopController"):
            _sanitized_copy(DIST / folder / f"{name}.fmu", dist / folder / f"{name}.fmu", cc)
        for name in DRAWN:
            _sanitized_copy(drawn_dist() / folder / f"{name}.fmu", drawn / folder / f"{name}.fmu", cc)
    env = dict(os.environ, POGOFMU_DIST=str(dist), POGOFMU_DRAWN_DIST=str(drawn), LD_PRELOAD=libasan,
               ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:halt_on_error=1",  # (CPython's own leaks: not ours)
               UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1")
    code = ("import sys; sys.path[:0] = sys.argv[1:]; import test_call_states as t; "
            "t.run_machines(t.NATIVE); print('sanitized run done')")
    proc = subprocess.run([sys.executable, "-c", code, str(ROOT / "tests"), str(ROOT / "fmu_src")],
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0 and "sanitized run done" in proc.stdout, (proc.stdout[-2000:], proc.stderr[-6000:])
    assert "runtime error" not in proc.stderr and "AddressSanitizer" not in proc.stderr, proc.stderr[-6000:]


def test_every_fmi_function_is_defined_once_for_both_backends():
    """The call-state machines above hold for both kinds of FMU because there is one entry file per
    FMI version: every fmi2*/fmi3* function is defined in exactly one C file of fmu_src/native —
    fmi2/pg_fmi2.c or fmi3/pg_fmi3.c, where each checks the call state from call_states.h — and
    that file is compiled into the Python-hosted FMUs' binary (with the adapter and the Python model source) and into
    the native FMUs' (with the adapter and their generated model) alike."""
    import re

    from pogofmu import exporter as build
    from pogofmu.codegen.build import FMI_ENTRY
    from support import ROOT

    native = ROOT / "fmu_src" / "native"
    definition = re.compile(r"^[A-Za-z_][\w \*]*?\b(fmi[23][A-Z]\w*)\s*\([^;]*?\)\s*\{", re.M | re.S)
    macro = re.compile(r"^NO_TYPE\((\w+),", re.M)  # fmi3Get<T> and fmi3Set<T> from one macro
    where = {}
    for path in sorted(native.rglob("*.c")):
        text = path.read_text()
        names = [m.group(1) for m in definition.finditer(text)]
        names += [f"fmi3{kind}{t}" for t in macro.findall(text) for kind in ("Get", "Set")]
        for name in names:
            where.setdefault(name, []).append(path.relative_to(native).as_posix())
    twice = {name: files for name, files in where.items() if len(files) > 1}
    assert not twice, f"FMI functions defined more than once: {twice}"
    files = {f for fs in where.values() for f in fs}
    assert files == {"fmi2/pg_fmi2.c", "fmi3/pg_fmi3.c"}, files
    for fmi in (2, 3):
        n = sum(1 for fs in where.values() if fs == [f"fmi{fmi}/pg_fmi{fmi}.c"])
        assert n >= (33 if fmi == 2 else 75), (fmi, n)  # the standard's (FMI 2.0 CS: 33; FMI 3.0: 75)
        entry = native / f"fmi{fmi}" / f"pg_fmi{fmi}.c"
        assert entry in build.launcher_sources(fmi) and entry == FMI_ENTRY[fmi][0]
        body = entry.read_text()
        assert '#include "call_states.h"' in body and "pg_backend.h" in body and "Py" not in re.sub(
            r"/\*.*?\*/", "", body, flags=re.S)


# =============================================================================================
# The call state is part of an FMU state, serialized or not
# =============================================================================================

# every state in which the standard allows getting an FMU state (and the FMUs can be: no Discard,
# no Pending), per interface
STATE_CASES = ([(2, "cs", False, m) for m in (I, INIT, STEP, TERM)]
               + [(3, "cs", False, m) for m in (I, INIT, STEP, TERM)]
               + [(3, "cs", True, m) for m in (I, INIT, EVENT, STEP, TERM)]
               + [(3, "me", False, m) for m in (I, INIT, EVENT, CONT, TERM)])


def _case_id(case):
    fmi, interface, event_mode, mode = case
    return f"fmi{fmi}-{interface}{'-event-mode' if event_mode else ''}-{mode}"


@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
@pytest.mark.parametrize("case", STATE_CASES, ids=[_case_id(c) for c in STATE_CASES])
def test_a_serialized_state_restores_the_call_state_it_was_taken_in(backend, case):
    """Get a state in a call state, serialize and deserialize it, move on to another call state,
    set the deserialized copy: the instance is back in the call state the state was taken in,
    exactly as with the in-memory state."""
    fmi, interface, event_mode, mode = case
    inst = RawInstance(backend, fmi, interface, event_mode)
    try:
        inst.reach(mode)
        t = inst.t
        original = inst.get_state()
        copy = inst.deserialize(inst.serialize(original))
        for state in (copy, original):
            assert inst.raw(f"fmi{fmi}Reset") == OK  # move on to another call state
            if mode == I:
                inst.reach(TERM if interface == "cs" else CONT)
            assert inst.set_state(state) == OK, inst.last()
            inst.t = t
            inst.assert_in(mode)
        inst.free(copy)
        inst.free(original)
    finally:
        inst.close()


@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
def test_a_state_is_restored_only_into_an_instance_that_can_be_in_its_call_state(backend):
    """A state of one FMU taken in a call state another instance of it cannot be in (Continuous-Time
    Mode of model exchange into a co-simulation instance; Event Mode into a co-simulation instance
    without event mode) is refused with Error naming the call state, in memory or serialized, and
    the instance goes on where it was."""
    me = RawInstance(backend, 3, "me")  # (one extraction: one loaded binary, one FMU)
    em = RawInstance(backend, 3, "cs", event_mode=True, unzip_dir=me.fmu.unzipDirectory)
    cs = RawInstance(backend, 3, "cs", unzip_dir=me.fmu.unzipDirectory)
    try:
        me.reach(CONT)
        em.reach(EVENT)
        cs.reach(STEP)
        for source, mode in ((me, "Continuous-Time Mode"), (em, "Event Mode")):
            state = source.get_state()
            blob = source.serialize(state)
            assert cs.set_state(state) == ERROR
            assert "refused" in cs.last() and mode in cs.last() and "co-simulation" in cs.last(), cs.last()
            buf = (ctypes.c_ubyte * len(blob)).from_buffer_copy(blob)
            assert cs.raw("fmi3DeserializeFMUState", buf, len(blob), ctypes.byref(ctypes.c_void_p())) == ERROR
            assert "refused" in cs.last() and mode in cs.last(), cs.last()
            source.free(state)
        cs.assert_in(STEP)
    finally:
        for inst in (me, em, cs):
            inst.close()

# =============================================================================================
# FMI 3.0 getters and setters follow the one table
# =============================================================================================

FMI3_TYPES = ["Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
              "Boolean", "String", "Binary"]


def _get_or_set(inst, kind, type_):
    """fmi3<kind><type_> of one value reference (the first variable of the FMU) and one value."""
    vr = (ctypes.c_uint32 * 1)(inst.vars["F_ext"].valueReference if "F_ext" in inst.vars else 0)
    fn = inst.fmu.dll[f"fmi3{kind}{type_}"]  # (a function object of its own: no argtypes of fmpy)
    buf = (ctypes.c_uint64 * 4)()  # room for one value of any type (a pointer for String and Binary)
    n = ctypes.c_size_t(1)
    if type_ == "Binary":
        sizes = (ctypes.c_size_t * 1)(1)
        return fn(ctypes.c_void_p(inst.fmu.component), vr, n, sizes, buf, n)
    return fn(ctypes.c_void_p(inst.fmu.component), vr, n, buf, n)


@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
def test_fmi3_getters_and_setters_are_checked_against_the_call_state_table(backend):
    """Every fmi3Get<T> is refused in Instantiated (the standard lists no getter there; start values
    come from the model description) naming the state, and allowed from Initialization Mode on;
    every discrete setter (integers, Boolean, String, Binary) is refused in Continuous-Time Mode,
    Float32/Float64 setters are not refused by state there."""
    cs = RawInstance(backend, 3, "cs")
    me = RawInstance(backend, 3, "me")
    try:
        for type_ in FMI3_TYPES:
            assert _get_or_set(cs, "Get", type_) == ERROR
            assert f"fmi3Get{type_} refused: not allowed in Instantiated" in cs.last(), cs.last()
        cs.reach(INIT)
        assert _get_or_set(cs, "Get", "Float64") == OK, cs.last()
        me.reach(CONT)
        for type_ in FMI3_TYPES:
            status = _get_or_set(me, "Set", type_)
            if type_ in ("Float32", "Float64"):
                assert "not allowed in" not in me.last() or status == OK, me.last()
            else:
                assert status == ERROR
                assert f"fmi3Set{type_} refused: not allowed in Continuous-Time Mode" in me.last(), me.last()
    finally:
        cs.close()
        me.close()


@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
@pytest.mark.parametrize("interface", ["cs", "me"])
def test_fmi3_terminated_allows_getters_and_reset_but_no_setter(backend, interface):
    """FMI 3.0 §2.3.9 (Terminated): "the final values of all variables ... can be retrieved" — its
    allowed calls are getters (and the FMU state functions, fmi3Reset, fmi3FreeInstance of the
    super state), no fmi3Set{VariableType}. After fmi3Terminate every setter is refused naming
    Terminated and nothing is set; the getters work; after fmi3Reset (Instantiated) the setters
    work again. The controller has a Float64 and an Int32 input."""
    inst = RawInstance(backend, 3, interface, name="HopController")
    try:
        vr = {name: (ctypes.c_uint32 * 1)(inst.vars[name].valueReference) for name in ("y", "s", "phase")}
        inst.reach(TERM)
        before = (D * 1)()
        assert inst.raw("fmi3GetFloat64", vr["y"], 1, before, 1) == OK, inst.last()
        assert inst.raw("fmi3SetFloat64", vr["y"], 1, (D * 1)(before[0] + 1.0), 1) == ERROR
        assert "fmi3SetFloat64 refused: not allowed in Terminated" in inst.last(), inst.last()
        assert inst.raw("fmi3SetInt32", vr["s"], 1, (ctypes.c_int32 * 1)(1), 1) == ERROR
        assert "fmi3SetInt32 refused: not allowed in Terminated" in inst.last(), inst.last()
        for type_ in FMI3_TYPES:
            assert _get_or_set(inst, "Set", type_) == ERROR
            assert f"fmi3Set{type_} refused: not allowed in Terminated" in inst.last(), inst.last()
        after = (D * 1)()
        assert inst.raw("fmi3GetFloat64", vr["y"], 1, after, 1) == OK and after[0] == before[0]
        assert inst.raw("fmi3GetInt32", vr["phase"], 1, (ctypes.c_int32 * 1)(), 1) == OK, inst.last()
        assert inst.raw("fmi3Reset") == OK, inst.last()
        assert inst.raw("fmi3SetFloat64", vr["y"], 1, (D * 1)(0.5), 1) == OK, inst.last()
        assert inst.raw("fmi3SetInt32", vr["s"], 1, (ctypes.c_int32 * 1)(1), 1) == OK, inst.last()
    finally:
        inst.close()

# =============================================================================================
# FMI 3.0 co-simulation: an event the FMU signalled is handled in Event Mode before the next step
# =============================================================================================

@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
def test_a_step_after_event_handling_needed_is_refused_until_event_mode(backend):
    """FMI 3.0 §4.2.1 (Step Mode: fmi3DoStep, fmi3EnterEventMode): after fmi3DoStep returned
    eventHandlingNeeded the importer has to enter Event Mode (the FMU stopped before the event's
    jump); another fmi3DoStep first is refused with Error naming the rule — also after restoring a
    state (in memory or serialized) taken at that point — and after Event Mode the stepping goes on."""
    inst = RawInstance(backend, 3, "cs", event_mode=True)
    try:
        inst.reach(EVENT)
        assert inst.raw("fmi3EnterStepMode") == OK
        for _ in range(2000):
            status, event = inst.do_step(1e-2)
            assert status == OK, inst.last()
            if event:
                break
        assert event, "no event within 20 s"
        pending, t_event = inst.get_state(), inst.t
        blob = inst.serialize(pending)
        for state in (None, pending, inst.deserialize(blob)):
            if state is not None:
                assert inst.set_state(state) == OK, inst.last()
                inst.t = t_event
            assert inst.do_step(1e-2)[0] == ERROR
            assert "fmi3DoStep refused" in inst.last() and "eventHandlingNeeded" in inst.last() and \
                "fmi3EnterEventMode" in inst.last(), inst.last()
            assert inst.raw("fmi3EnterEventMode") == OK, inst.last()
            refs = [ctypes.byref(B()) for _ in range(5)] + [ctypes.byref(D())]
            assert inst.raw("fmi3UpdateDiscreteStates", *refs) == OK, inst.last()
            assert inst.raw("fmi3EnterStepMode") == OK, inst.last()
            assert inst.do_step(1e-3)[0] == OK, inst.last()
    finally:
        inst.close()


# =============================================================================================
# Written-out sequences: refused with Error naming the function and the state
# =============================================================================================

def _raw(fmu, name, *args):
    """The FMU's own function, its status returned (fmpy's wrappers raise on Error)."""
    return raw_call(fmu, name, *args)


def _fmi2(name="PogoStick"):
    inst = Instance(name, "calls")
    return inst, inst.fmu


def _last(inst):
    return inst.messages[-1][2] if inst.messages else ""


def test_fmi2_calls_out_of_sequence_are_refused_and_the_instance_goes_on():
    import ctypes

    inst, fmu = _fmi2()
    try:
        F = ctypes.c_double
        # before initialization: no step, no exit, no terminate
        assert _raw(fmu, "fmi2ExitInitializationMode") == 3
        assert "fmi2ExitInitializationMode refused: not allowed in Instantiated" in _last(inst)
        assert _raw(fmu, "fmi2DoStep", F(0.0), F(1e-3), 1) == 3 and "fmi2DoStep refused" in _last(inst)
        # a bad tolerance, an unknown log category
        assert _raw(fmu, "fmi2SetupExperiment", 1, F(-1.0), F(0.0), 0, F(0.0)) == 3
        assert "tolerance = -1 violates the rule" in _last(inst)
        cats = (ctypes.c_char_p * 1)(b"logNoSuchThing")
        assert _raw(fmu, "fmi2SetDebugLogging", 1, 1, cats) == 3
        assert "'logNoSuchThing' is not a log category of this FMU" in _last(inst) and "logEvents" in _last(inst)
        # the legal sequence still works
        assert _raw(fmu, "fmi2SetupExperiment", 0, F(0.0), F(0.0), 0, F(0.0)) == 0
        assert _raw(fmu, "fmi2EnterInitializationMode") == 0
        assert _raw(fmu, "fmi2EnterInitializationMode") == 3  # a second one
        assert "not allowed in Initialization Mode" in _last(inst)
        assert _raw(fmu, "fmi2ExitInitializationMode") == 0
        assert _raw(fmu, "fmi2SetupExperiment", 0, F(0.0), F(0.0), 0, F(0.0)) == 3  # after initialization
        assert "fmi2SetupExperiment refused: not allowed in Step Complete" in _last(inst)
        assert _raw(fmu, "fmi2DoStep", F(0.0), F(1e-3), 1) == 0
        assert _raw(fmu, "fmi2Terminate") == 0
        assert _raw(fmu, "fmi2DoStep", F(1e-3), F(1e-3), 1) == 3  # after terminate
        assert "fmi2DoStep refused: not allowed in Terminated" in _last(inst)
        assert not [m for m in inst.messages if m[0] >= 4]  # nothing fatal
        assert _raw(fmu, "fmi2Reset") == 0
        inst.init().run_to(0.01, 1e-3)  # usable after every refusal
    finally:
        fmu.freeInstance()


def test_fmi3_calls_out_of_sequence_are_refused():
    import ctypes

    B = ctypes.c_bool
    flags = [B(), B(), B(), B(), B()]
    refs = [ctypes.byref(f) for f in flags] + [ctypes.byref(ctypes.c_double())]
    # co-simulation without event mode: no Event Mode at all
    fmu, messages = _fmi3_raw("PogoStick", "cs", event_mode=False)
    try:
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()  # -> Step Mode
        assert _raw(fmu, "fmi3UpdateDiscreteStates", *refs) == 3
        assert "fmi3UpdateDiscreteStates refused: not allowed in Step Mode" in messages[-1][1]
        assert _raw(fmu, "fmi3EnterEventMode") == 3 and "eventModeUsed = false" in messages[-1][1]
        assert _raw(fmu, "fmi3EnterStepMode") == 3 and "fmi3EnterStepMode refused: not allowed in Step Mode" in \
            messages[-1][1]
        fmu.doStep(0.0, 1e-3)  # still usable
    finally:
        fmu.terminate()
        fmu.freeInstance()
    # with event mode: Event Mode twice in a row
    fmu, messages = _fmi3_raw("PogoStick", "cs", event_mode=True)
    try:
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()  # -> Event Mode
        assert _raw(fmu, "fmi3EnterEventMode") == 3 and "not allowed in Event Mode" in messages[-1][1]
        fmu.updateDiscreteStates()
        fmu.enterStepMode()
        fmu.enterEventMode()
        assert _raw(fmu, "fmi3EnterEventMode") == 3 and "fmi3EnterEventMode refused" in messages[-1][1]
    finally:
        fmu.terminate()
        fmu.freeInstance()
    # a co-simulation function on a model-exchange instance
    fmu, messages = _fmi3_raw("PogoStick", "me")
    try:
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        assert _raw(fmu, "fmi3EnterStepMode") == 3
        assert "it is a co-simulation function, and this instance is a model-exchange instance" in messages[-1][1]
    finally:
        fmu.freeInstance()
