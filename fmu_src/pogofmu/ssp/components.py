"""The components of a running system: one FMU instance each, behind one interface whatever its FMI
version and interface type, so that the master algorithms (:mod:`.algorithms`) read in the
terms of the system — set inputs, step, save and restore, handle events — not of fmpy.

* :class:`Fmi2CoSimulation` — FMI 2.0 co-simulation; it can take part in event
  synchronization by *rollback* when it can get and set its state: a step that holds an event
  is redone up to just before the event.  For this project's FMUs the event time is exact (the
  outputs ``n_events`` and ``t_last_event``); for any other FMU a change of a discrete output is
  located by bisection to the tolerance the user sets.
* :class:`Fmi3CoSimulation` — FMI 3.0 co-simulation, instantiated with ``earlyReturnAllowed``
  (and ``eventModeUsed`` where the FMU has Event Mode): a step returns early at an event.
* :class:`Fmi3ModelExchange` — FMI 3.0 model exchange, for the strongly coupled algorithm.

Host-side code (fmpy); never imported inside an FMU.
"""
from __future__ import annotations

import ctypes
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional
from xml.etree import ElementTree as ET

from pogofmu.fmpy_raw import Fmi2Callbacks, raw_function
from pogofmu.runtime.status import status_name

from .package import SSPError

REAL_TYPES = ("Real", "Float64", "Float32")
REPLAY_STEPS = 16  # Component.save: the FMU state itself saved at most every this many steps
INTEGER_TYPES = ("Integer", "Int32", "Enumeration", "Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64",
                 "UInt64")


@dataclass(slots=True)
class StepResult:
    """What one step of a component did.

    ``t_end``: the time the component reached (the end of the step, or earlier);
    ``event_at``: an event lies at this time (``t_end`` itself for an FMI 3.0 early return; just
    after ``t_end`` for a rollback, whose component stops a rounding unit before its event);
    ``event_mode``: the component waits in front of its event for Event Mode (FMI 3.0);
    ``terminate``: the component asks to end the simulation."""

    t_end: float
    event_at: Optional[float] = None
    event_mode: bool = False
    terminate: bool = False


def pogofmu_events(unzipdir: str) -> Optional[List[str]]:
    """The events a co-simulation step of a pogofmu FMU can contain (from the modelDescription's
    pogofmu annotation), or None for an FMU of another tool."""
    try:
        root = ET.parse(Path(unzipdir) / "modelDescription.xml").getroot()
    except (OSError, ET.ParseError):
        return None
    if not (root.get("generationTool") or "").startswith("pogofmu"):
        return None
    for el in root.iter("Events"):
        return (el.get("cosimulation") or "").split()
    return None


def _unpacked(comp, workdir: Path, extract) -> str:
    """The folder of the component's FMU, unpacked once per FMU file of the package and shared by
    its instances: one copy of its binary loaded for all, as FMI allows unless the FMU says
    ``canBeInstantiatedOnlyOncePerProcess`` (such an FMU keeps a copy per component, as before)."""
    md = comp.model_description
    once = any(getattr(getattr(md, kind, None), "canBeInstantiatedOnlyOncePerProcess", False)
               for kind in ("coSimulation", "modelExchange", "scheduledExecution"))
    if once:
        return extract(str(comp.model_description_path), unzipdir=str(workdir / comp.name))
    folder = workdir / "fmus" / str(comp.source).replace("/", "_").replace("\\", "_")
    if not folder.exists():
        extract(str(comp.model_description_path), unzipdir=str(folder))
    return str(folder)


class Component:
    """One FMU instance of the system, with its log kept (warnings and errors echoed)."""

    fmi = 2
    interface = "cs"
    _journal = None  # calls since the FMU state was last really saved (None: none saved since)
    _mark = 0  # how many of them lie before saved_at

    def __init__(self, comp, workdir: Path, echo: bool):
        from fmpy import extract

        self.comp = comp
        self.name = comp.name
        self.messages = []
        self.dead = False
        self.initialized = False  # exitInitializationMode returned
        self.echo = echo
        self.md = comp.model_description
        self.dir = _unpacked(comp, workdir, extract)
        self.variables = comp.variables
        self.events = pogofmu_events(self.dir)  # None: not a pogofmu FMU
        self.t = None  # the time the component has reached
        self._state = None
        self.saved_at = None
        self._plans = {}
        self._sizes = {}  # value reference -> number of values (an FMI 3.0 array's elements)
        self._arrays = {}  # value reference of an FMI 3.0 array input -> the values it was last set to

    # ---- logging ------------------------------------------------------------------------------
    def _log(self, status, message):
        text = message.decode(errors="replace") if isinstance(message, bytes) else (message or "")
        self.messages.append((int(status), text))
        if status >= 1 and self.echo:
            print(f"[{status_name(status)}] {self.name}: {text}", file=sys.stderr, flush=True)

    def last_error(self):
        for status, text in reversed(self.messages):
            if status >= 2:
                return text
        return "no message from the FMU"

    def fail(self, what: str, exc: Exception) -> SSPError:
        """The error that ends the run: the component, the call, the FMU's own message."""
        self.dead = self.dead or "fatal" in str(exc).lower()
        return SSPError(f"Component {self.name}: {what} failed ({exc}): {self.last_error()}")

    # ---- variables ----------------------------------------------------------------------------
    def vr(self, name):
        return self.variables[name].valueReference

    def type_of(self, name) -> str:
        return self.variables[name].type

    def _plan(self, names):
        """``[(kind, value references, slots, fast call or None)]``: one FMI call per kind (cached
        with its ctypes buffers: the master's calls cost no fmpy wrapper). ``slots[i]`` is where the
        value of ``names[i]`` lies among the call's values (an FMI 3.0 array is one value reference
        whose elements are consecutive values; a name is one element, ``z[2]``)."""
        key = tuple(names)
        plan = self._plans.get(key)
        if plan is None:
            groups: Dict[str, tuple] = {}
            for pos, n in enumerate(key):
                t = self.type_of(n)
                kind = "real" if t in REAL_TYPES else "int" if t in INTEGER_TYPES else t.lower()
                vrs, where, slots, base = groups.setdefault(kind, ([], [], [], {}))
                _, index, size = self.comp.elements.get(n, (None, 1, 1))
                vr = self.vr(n)
                if vr not in base:  # its values follow those of the value references before it
                    self._sizes[vr] = size
                    base[vr] = sum(map(self._size, vrs))
                    vrs.append(vr)
                where.append(pos)
                slots.append(base[vr] + index - 1)
            plan = self._plans[key] = [(kind, vrs, (where, slots), self._fast(kind, vrs))
                                       for kind, (vrs, where, slots, _) in groups.items()]
        return plan

    def _size(self, vr):
        return self._sizes.get(vr, 1)

    def _fast(self, kind, vrs):
        """``(get(), set(slots, values))`` calling the FMU's own functions with prebuilt buffers, for
        reals and integers; None for the other types (fmpy's wrappers). The values of an array not
        given are its last set ones (``_arrays``: an FMI 3.0 array is set whole)."""
        names = self.FAST.get(kind)
        if names is None:
            return None
        ctype = ctypes.c_double if kind == "real" else ctypes.c_int32
        n = len(vrs)
        n_values = sum(map(self._size, vrs))
        arrays = [(vr, sum(map(self._size, vrs[:k]))) for k, vr in enumerate(vrs) if self._size(vr) > 1]
        vr_arr = (ctypes.c_uint32 * n)(*vrs)
        buf = (ctype * n_values)()
        fget, fset = raw_function(self.fmu, names[0]), raw_function(self.fmu, names[1])
        comp, fmi3 = self.fmu.component, self.fmi == 3

        def get():
            status = fget(comp, vr_arr, n, buf, n_values) if fmi3 else fget(comp, vr_arr, n, buf)
            if status > 1:
                raise _call_failed(names[0], status)
            return buf[:]

        def set_(slots, values):
            for vr, at in arrays:
                buf[at:at + self._size(vr)] = self._array_values(vr, kind)
            for slot, v in zip(slots, values):
                buf[slot] = v
            status = fset(comp, vr_arr, n, buf, n_values) if fmi3 else fset(comp, vr_arr, n, buf)
            if status > 1:
                raise _call_failed(names[1], status)
            for vr, at in arrays:
                self._arrays[vr] = buf[at:at + self._size(vr)]
        return get, set_

    def _array_values(self, vr, kind):
        """The values an array input was last set to (its start values before)."""
        values = self._arrays.get(vr)
        if values is None:
            var = next(v for v in self.variables.values() if v.valueReference == vr)
            start = str(var.start or "0").split()
            conv = float if kind == "real" else int
            values = [conv(start[min(i, len(start) - 1)]) for i in range(self._size(vr))]
        return values

    def set_values(self, names, values):
        """Set variables by name (reals, integers, booleans, strings each in one call)."""
        if self._journal is not None:
            self._journal.append((False, tuple(names), tuple(values)))
        self._set_values(names, values)

    def _set_values(self, names, values):
        for kind, vrs, (where, slots), fast in self._plan(names):
            vals = [values[i] for i in where]
            if fast is not None:
                fast[1](slots, [float(v) for v in vals] if kind == "real" else [int(v) for v in vals])
            else:
                self._set(kind, vrs, vals)

    def get_values(self, names) -> list:
        out = [None] * len(names)
        for kind, vrs, (where, slots), fast in self._plan(names):
            got = fast[0]() if fast is not None else self._get(kind, vrs)
            for i, slot in zip(where, slots):
                out[i] = got[slot]
        return out

    @property
    def discrete_outputs(self) -> List[str]:
        """Outputs whose change marks an event of an FMU of another tool (integers, booleans,
        discrete reals)."""
        return [n for n, v in self.variables.items() if v.causality == "output"
                and (v.type not in REAL_TYPES or v.variability == "discrete")
                and (not getattr(v, "dimensions", None) or n in self.comp.elements)]

    # ---- states -------------------------------------------------------------------------------
    def do_step(self, t, h) -> StepResult:
        """One communication step from ``t`` of length ``h`` (journaled, see :meth:`save`)."""
        if self._journal is not None:
            self._journal.append((True, t, h))
        return self._do_step_call(t, h)

    def _changed_otherwise(self):
        """A call other than a step or a set changed the instance (Event Mode ...): the next
        :meth:`save` saves the FMU state itself."""
        self._journal = None

    def save(self):
        """Remember the state at ``self.t`` for :meth:`restore`.

        The FMU state itself is saved only every REPLAY_STEPS communication steps: in between,
        the calls made since that save (input values and steps) are kept, and a restore restores
        the saved FMU state and makes those calls again — the same calls from the same state, so
        the same state to the bit (the standard's promise for fmi2SetFMUstate/fmi3SetFMUState).
        A master that may have to go back saves before every step, and goes back only at events
        (saving only what is needed: a save of a Python-hosted FMU costs ~20 µs)."""
        j = self._journal
        if j is not None and len(j) < 2 * REPLAY_STEPS:
            self._mark = len(j)
            self.saved_at = self.t
            return
        try:
            self._save()
        except Exception as exc:  # noqa: BLE001 - fmpy raises FMICallException on an error status
            raise self.fail("saving its state", exc) from None
        self._journal, self._mark = [], 0
        self.saved_at = self.t

    # ---- stepped by the master's C level (pogofmu.ssp.native_level) ---------------------------
    @property
    def journaling(self) -> bool:
        """Whether the calls since the FMU state was last really saved are kept (see :meth:`save`):
        the C level steps such a component only where it saves it itself."""
        return self._journal is not None

    def state_address(self) -> int:
        """The address of the FMU state object the C level saves into (made here once)."""
        if self._state is None:
            try:
                self._save()
            except Exception as exc:  # noqa: BLE001
                raise self.fail("saving its state", exc) from None
        return ctypes.addressof(self._state)

    def saved_in_c(self, step):
        """The C level saved the FMU state at :attr:`t` (into :meth:`state_address`), then made
        ``step``, a journal entry ``(True, t, h)``: :meth:`restore` goes back to that save."""
        j = self._journal
        if j is not None and len(j) == 1:  # (the list of the previous step's C save: reused)
            j[0] = step
        else:
            self._journal = [step]
        self._mark = 0
        self.saved_at = self.t

    def restore(self):
        """Back to the state remembered by the latest :meth:`save` (the FMU state saved, then the
        journaled calls up to that save made again; the state there is then saved itself, so a
        bisection restores it many times at the cost of one)."""
        try:
            self._restore()
        except Exception as exc:  # noqa: BLE001
            raise self.fail("restoring its state", exc) from None
        j, mark = self._journal or [], self._mark
        self._journal, self._mark = [], 0
        if mark:
            for is_step, a, b in j[:mark]:
                if is_step:
                    self._do_step_call(a, b)
                elif is_step is None:
                    self._set_slopes(a, b)
                else:
                    self._set_values(a, b)
            try:
                self._save()
            except Exception as exc:  # noqa: BLE001
                raise self.fail("saving its state", exc) from None
        self.t = self.saved_at

    def close(self):
        if self.dead:  # nothing may be called on an instance after a fatal error
            return
        try:
            if self._state is not None:
                self._free_state()
            if self.initialized:  # (fmi*Terminate is not allowed before initialization has ended)
                self.fmu.terminate()
        finally:
            self.fmu.freeInstance()


# =============================================================================================
# FMI 2.0 co-simulation
# =============================================================================================

def _call_failed(function, status):
    from fmpy.fmi1 import FMICallException

    return FMICallException(function=function, status=status)


class Fmi2CoSimulation(Component):
    fmi = 2
    FAST = {"real": ("fmi2GetReal", "fmi2SetReal"), "int": ("fmi2GetInteger", "fmi2SetInteger")}

    def __init__(self, comp, workdir, echo):
        super().__init__(comp, workdir, echo)
        from fmpy.fmi2 import FMU2Slave

        md = self.md
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=self.dir, modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=self.name)
        self._cb = Fmi2Callbacks(lambda status, category, text: self._log(status, text))  # kept with the instance
        self.fmu.instantiate(loggingOn=True, callbacks=self._cb.struct)
        self.can_save = bool(md.coSimulation.canGetAndSetFMUstate)
        self.counts_events = self.events is not None and "n_events" in self.variables \
            and "t_last_event" in self.variables
        self._do_step = raw_function(self.fmu, "fmi2DoStep")
        self._get_state = raw_function(self.fmu, "fmi2GetFMUstate") if self.can_save else None
        # it takes its real inputs as lines over a step (fmi2SetRealInputDerivatives, order 1);
        # the master decides whether to use that (``interpolates``, --inputs interpolate)
        self.can_interpolate = bool(getattr(md.coSimulation, "canInterpolateInputs", False))
        self._slope_calls = {}

    def set_input_slopes(self, names, slopes):
        """The first derivatives of these real inputs from the current communication point
        (after their values: an fmi2SetReal of an input sets its derivative back to 0); journaled
        with the values, so a restore makes them again."""
        if self._journal is not None:
            self._journal.append((None, tuple(names), tuple(slopes)))
        self._set_slopes(names, slopes)

    def _set_slopes(self, names, slopes):
        key = tuple(names)
        call = self._slope_calls.get(key)
        if call is None:
            n = len(key)
            vrs = (ctypes.c_uint32 * n)(*(self.vr(x) for x in key))
            orders = (ctypes.c_int32 * n)(*([1] * n))
            buf = (ctypes.c_double * n)()
            f = raw_function(self.fmu, "fmi2SetRealInputDerivatives")
            call = self._slope_calls[key] = (f, vrs, orders, buf, n)
        f, vrs, orders, buf, n = call
        buf[:] = [float(v) for v in slopes]
        status = f(self.fmu.component, vrs, n, orders, buf)
        if status > 1:
            raise _call_failed("fmi2SetRealInputDerivatives", status)

    def _set(self, kind, vrs, values):
        f = {"real": self.fmu.setReal, "int": self.fmu.setInteger, "boolean": self.fmu.setBoolean,
             "string": self.fmu.setString}[kind]
        conv = {"real": float, "int": int, "boolean": bool, "string": str}[kind]
        f(vrs, [conv(v) for v in values])

    def _get(self, kind, vrs):
        return {"real": self.fmu.getReal, "int": self.fmu.getInteger, "boolean": self.fmu.getBoolean,
                "string": self.fmu.getString}[kind](vrs)

    def enter_initialization(self, t0):
        # no stop time for the FMUs (stopTimeDefined = false): an input change within ~1e-14 s of a
        # defined stop time ended in a 'step size collapsed' error (README "Known issues")
        self.fmu.setupExperiment(startTime=t0)
        self.fmu.enterInitializationMode()

    def exit_initialization(self, t0):
        self.fmu.exitInitializationMode()
        self.t = t0
        self.initialized = True

    def _do_step_call(self, t, h) -> StepResult:
        status = self._do_step(self.fmu.component, t, h, 1)
        if status > 1:
            raise self.fail(f"fmi2DoStep from t = {t:.10g} s (step {h:g} s)",
                            _call_failed("fmi2DoStep", status)) from None
        self.t = t + h
        return StepResult(self.t)

    def _save(self):
        if self._state is None:
            self._state = self.fmu.getFMUstate()
            self._state_ref = ctypes.byref(self._state)
        else:
            status = self._get_state(self.fmu.component, self._state_ref)
            if status > 1:
                raise _call_failed("fmi2GetFMUstate", status)

    def _restore(self):
        self.fmu.setFMUstate(self._state)

    def _free_state(self):
        self.fmu.freeFMUstate(self._state)
        self._state = None



# =============================================================================================
# FMI 3.0
# =============================================================================================

class _Fmi3(Component):
    fmi = 3
    FAST = {"real": ("fmi3GetFloat64", "fmi3SetFloat64"), "int": ("fmi3GetInt32", "fmi3SetInt32")}

    def _logger(self):
        from fmpy.fmi3 import fmi3LogMessageCallback  # noqa: F401 (fmpy wraps the callable itself)

        return lambda env, status, category, message: self._log(status, message)

    def _set(self, kind, vrs, values):
        f = {"real": self.fmu.setFloat64, "int": self.fmu.setInt32, "boolean": self.fmu.setBoolean,
             "string": self.fmu.setString}[kind]
        conv = {"real": float, "int": int, "boolean": bool, "string": str}[kind]
        f(vrs, [conv(v) for v in values])

    def _get(self, kind, vrs):
        return {"real": self.fmu.getFloat64, "int": self.fmu.getInt32, "boolean": self.fmu.getBoolean,
                "string": self.fmu.getString}[kind](vrs)

    def enter_initialization(self, t0):
        self.fmu.enterInitializationMode(startTime=t0)

    def enter_event_mode(self):
        self._changed_otherwise()
        try:
            self.fmu.enterEventMode()
        except Exception as exc:  # noqa: BLE001
            raise self.fail(f"fmi3EnterEventMode at t = {self.t:.15g} s", exc) from None

    def update_discrete_states(self):
        """(discreteStatesNeedUpdate, terminateSimulation, nextEventTime or None)."""
        self._changed_otherwise()
        try:
            need, terminate, _, _, defined, t_next = self.fmu.updateDiscreteStates()
        except Exception as exc:  # noqa: BLE001
            raise self.fail(f"fmi3UpdateDiscreteStates at t = {self.t:.15g} s", exc) from None
        return bool(need), bool(terminate), (t_next if defined else None)

    def _save(self):
        if self._state is None:
            self._state = self.fmu.getFMUState()
            self._state_ref = ctypes.byref(self._state)
        else:
            status = raw_function(self.fmu, "fmi3GetFMUState")(self.fmu.component, self._state_ref)
            if status > 1:
                raise _call_failed("fmi3GetFMUState", status)

    def _restore(self):
        self.fmu.setFMUState(self._state)

    def _free_state(self):
        self.fmu.freeFMUState(self._state)
        self._state = None


class Fmi3CoSimulation(_Fmi3):
    """FMI 3.0 co-simulation; with ``events`` it may return early at an event (and then, if it
    has Event Mode, waits in front of the event for the master's event handling)."""

    def __init__(self, comp, workdir, echo, events=True):
        super().__init__(comp, workdir, echo)
        from fmpy.fmi3 import FMU3Slave

        md = self.md
        cs = md.coSimulation
        self.fmu = FMU3Slave(guid=md.guid, unzipDirectory=self.dir, modelIdentifier=cs.modelIdentifier,
                             instanceName=self.name)
        self.event_mode_used = bool(events and cs.hasEventMode)
        self.early_return = bool(events)
        self.fmu.instantiate(loggingOn=True, eventModeUsed=self.event_mode_used,
                             earlyReturnAllowed=self.early_return, logMessage=self._logger())
        self.can_save = bool(cs.canGetAndSetFMUstate)
        # fmi3DoStep called directly, its four results in buffers made once
        self._flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
        self._flag_refs = [ctypes.byref(f) for f in self._flags]
        self._do_step = raw_function(self.fmu, "fmi3DoStep")

    def exit_initialization(self, t0):
        self.fmu.exitInitializationMode()  # then in Event Mode when eventModeUsed (the master iterates)
        self.t = t0
        self.initialized = True

    def enter_step_mode(self):
        self._changed_otherwise()
        try:
            self.fmu.enterStepMode()
        except Exception as exc:  # noqa: BLE001
            raise self.fail(f"fmi3EnterStepMode at t = {self.t:.15g} s", exc) from None

    def _do_step_call(self, t, h) -> StepResult:
        e, m, r, l_ = self._flag_refs
        status = self._do_step(self.fmu.component, t, h, True, e, m, r, l_)
        if status > 1:
            raise self.fail(f"fmi3DoStep from t = {t:.10g} s (step {h:g} s)",
                            _call_failed("fmi3DoStep", status)) from None
        event, terminate, early, last = (f.value for f in self._flags)
        end = t + h
        if early:
            if not (last >= t) or not math.isfinite(last):
                raise SSPError(f"Component {self.name}: fmi3DoStep from t = {t:.15g} s returned early at "
                               f"lastSuccessfulTime = {last!r} s, before the start of the step")
            if last > end:
                raise SSPError(f"Component {self.name}: fmi3DoStep from t = {t:.15g} s (step {h:g} s) returned "
                               f"early at lastSuccessfulTime = {last!r} s, after the end of the step")
            self.t = last
        else:
            self.t = end
        if event or early:
            return StepResult(self.t, event_at=self.t, event_mode=bool(event and self.event_mode_used),
                              terminate=bool(terminate))
        return StepResult(self.t, terminate=bool(terminate))


class Fmi3ModelExchange(_Fmi3):
    """FMI 3.0 model exchange: the master integrates the states (:mod:`.algorithms`)."""

    interface = "me"

    def __init__(self, comp, workdir, echo):
        super().__init__(comp, workdir, echo)
        from fmpy.fmi3 import FMU3Model

        md = self.md
        me = md.modelExchange
        if me is None:
            raise SSPError(f"Component {self.name}: {comp.source} does not support model exchange "
                           f"(--algorithm model-exchange needs FMI 3.0 model exchange in every FMU)")
        self.fmu = FMU3Model(guid=md.guid, unzipDirectory=self.dir, modelIdentifier=me.modelIdentifier,
                             instanceName=self.name)
        self.fmu.instantiate(loggingOn=True, logMessage=self._logger())
        self.can_save = bool(me.canGetAndSetFMUstate)
        self.nx = len(md.derivatives)
        self.nz = len(md.eventIndicators)
        self._x = (ctypes.c_double * max(self.nx, 1))()
        self._dx = (ctypes.c_double * max(self.nx, 1))()
        self._z = (ctypes.c_double * max(self.nz, 1))()

    def exit_initialization(self, t0):
        self.fmu.exitInitializationMode()  # then in Event Mode
        self.t = t0
        self.initialized = True

    def enter_continuous_time_mode(self):
        self.fmu.enterContinuousTimeMode()

    def set_time(self, t):
        self.fmu.setTime(t)
        self.t = t

    def get_states(self, out, offset):
        if self.nx:
            self.fmu.getContinuousStates(self._x, self.nx)
            out[offset:offset + self.nx] = self._x[:self.nx]

    def set_states(self, x, offset):
        if self.nx:
            self._x[:self.nx] = x[offset:offset + self.nx]
            self.fmu.setContinuousStates(self._x, self.nx)

    def get_derivatives(self, out, offset):
        if self.nx:
            self.fmu.getContinuousStateDerivatives(self._dx, self.nx)
            out[offset:offset + self.nx] = self._dx[:self.nx]

    def get_indicators(self, out, offset):
        if self.nz:
            self.fmu.getEventIndicators(self._z, self.nz)
            out[offset:offset + self.nz] = self._z[:self.nz]

    def completed_integrator_step(self):
        """(enterEventMode, terminateSimulation)."""
        enter, terminate = self.fmu.completedIntegratorStep()
        return bool(enter), bool(terminate)
