"""One adapter from any :class:`~pogofmu.runtime.model.HybridModel` to an FMI 2.0 co-simulation slave.

A slave file is a few lines (``pogofmu export`` writes it into the FMU's resources)::

    from pogofmu.runtime.fmi2 import HybridSlave as Fmi2Slave
    from pogofmu.runtime.models.pogo_stick import MODEL

    class PogoStick(Fmi2Slave):
        model = MODEL

        def __init__(self, **kwargs):
            super().__init__(**kwargs)

The adapter needs the standard library only. It is driven by the project's launcher, the binary of
every Python-hosted FMU: the FMI entry files ``fmu_src/native/fmi2/pg_fmi2.c`` / ``fmi3/pg_fmi3.c``
(the call states, the ones the native FMUs are built from) with the bridge
``fmu_src/native/python/pg_bridge.c``. The bridge calls :meth:`HybridSlave._launcher_attach`
first, and then

* serves outputs from buffers filled once per step (no Python call per ``fmi2GetReal``);
* maps an :class:`FMUError` to its ``fmi_status``: a refused call (bad input, a parameter rule, a
  step that cannot be taken, a model that stopped) returns ``fmi2Error`` with the message logged,
  and the instance stays usable (``fmi2Reset``, ``fmi2SetFMUstate``, a corrected input); any
  other exception is ``fmi2Fatal``;
* forwards warnings and errors to the importer's logger even with logging off.

Behaviour (FMI 2.0 co-simulation):

* parameters are ``fixed``: set them before ``fmi2ExitInitializationMode``, where they are all
  checked and the initial state is derived from them;
* every ``fmi2DoStep`` holds the inputs over the step, lets the engine run to the end of the step
  (handling every event inside it) and refreshes all outputs;
* errors name the variable, its value and the rule (or the physical condition and the time);
* with the parameter ``log_events = 1`` every event is reported through the logger (category
  ``logEvents``): kind, exact time and the state before the jump;
* ``fmi2GetFMUstate`` / ``fmi2SetFMUstate`` save and restore the whole engine; the serialized
  form is JSON (exact floats), checked against the model and build it came from.

The native FMUs' adapter, ``fmu_src/native/adapter/pg_instance.c``, keeps the same rules in C
(issue 47: one adapter for both backends is not done yet; the tests hold the two to the same
bits, statuses and messages).
"""
from __future__ import annotations

import hashlib
import json
import math
import struct
from array import array
from operator import itemgetter
from dataclasses import dataclass
from typing import NamedTuple, Optional, Tuple

from .solver import SOLVER_PARAMETERS, Simulator, snapshot_from_data, snapshot_to_data, solver_defaults, \
    split_parameters
from .solver.settings import REL_TOL_MAX, REL_TOL_MIN
from .eventlog import CATEGORY as EVENT_CATEGORY, event_message
from .interface import LOG_CATEGORIES, FmiVariable, fmi2_variables  # (what the FMU exposes: one module)
from .model import DomainError, HybridModel, ModelError, Params
from .status import ERROR, FATAL, OK, WARNING, log_category

__all__ = ["HybridSlave", "FMUError", "FmiVariable", "fmi2_variables", "LOG_CATEGORIES"]

_STATE_FORMAT = "pogofmu-fmu-state-4"  # 4: the input derivatives ("du")
# the package this module was imported as: "_pogofmu_<Model>_<hash>" inside an FMU (one name per
# build of one model, see build_fmu.py), "pogofmu" from the source tree
_BUILD = __name__.rpartition(".")[0]



class LogMsg(NamedTuple):
    """One queued log message (the launcher reads it as a tuple)."""

    status: int
    category: str
    msg: str
    debug: bool = False


class FMUError(Exception):
    """An FMI call cannot be carried out; the message says why, ``fmi_status`` is the FMI status
    the launcher returns (Error: the instance can be reset, restored or freed)."""

    def __init__(self, message: str, status: int = ERROR):
        super().__init__(message)
        self.fmi_status = status


def _values_getter(names):
    """``out -> tuple of out[name] for names`` (itemgetter returns a bare value for one name)."""
    if len(names) == 1:
        name = names[0]
        return lambda out: (out[name],)
    return itemgetter(*names) if names else (lambda out: ())


class HybridSlave:
    """Generic FMI 2.0 co-simulation slave for a :class:`HybridModel` (set ``model`` in a subclass)."""

    model: HybridModel = None
    author = "pogofmu"
    license = "MIT"
    version = None  # the project version, written into modelDescription.xml by build_fmu.py
    log_categories = LOG_CATEGORIES
    _api = "fmi2"  # prefix of the FMI function names in messages (fmi3 in the FMI 3.0 adapter)
    _tables = None  # per class: (variables, by vr, real output names/vrs, integer output names/vrs)

    def __init__(self, **kwargs):
        model = type(self).model
        if model is None:
            raise FMUError(f"{type(self).__name__} defines no model", FATAL)
        self.instance_name = kwargs.get("instance_name", "")
        self.resources = kwargs.get("resources")
        self.visible = kwargs.get("visible", False)
        self.log_queue = []
        variables, by_vr, real_out, int_out = self._variable_tables()
        self._vars = by_vr
        self._output_fn = model.output_fn
        self._model_outputs = tuple(v.name for v in model.outputs)  # (checked finite after each step)
        # the hooks below, called only where a subclass (FMI 3.0) overrides them: the common step
        # then costs no extra call
        cls = type(self)
        self._completes_outputs = cls._complete_outputs is not HybridSlave._complete_outputs
        self._own_advance = cls._advance_engine is not HybridSlave._advance_engine
        # one output buffer: the real outputs (doubles), then the integer ones (int32), filled by
        # one struct call per step in this order
        nr, ni = len(real_out), len(int_out)
        self._out_values = _values_getter([v.name for v in (*real_out, *int_out)])
        self._real_out_vrs = tuple(v.vr for v in real_out)
        self._int_out_vrs = tuple(v.vr for v in int_out)
        self._obuf = array("d", bytes(8 * (nr + (ni + 1) // 2)))
        self._oview = memoryview(self._obuf).cast("B")
        self._ctl = array("i", [0])  # _ctl[0] = 1: the buffer holds the current outputs
        self._pack_outputs = struct.Struct(f"={nr}d{ni}i").pack_into
        self._reset_state()

    @classmethod
    def _variable_tables(cls):
        if cls.__dict__.get("_tables") is None:
            variables = fmi2_variables(cls.model)
            outputs = [v for v in variables if v.causality == "output"]
            cls._tables = (variables, {v.vr: v for v in variables},
                           [v for v in outputs if v.type == "Real"], [v for v in outputs if v.type == "Integer"])
        return cls._tables

    @classmethod
    def variables(cls) -> Tuple[FmiVariable, ...]:
        return cls._variable_tables()[0]

    def _reset_state(self):
        model = type(self).model
        self._par = {**model.defaults(), **solver_defaults()}
        self._rel_tol_set = False  # set by the user: the importer's tolerance no longer applies
        self._u = [float(v.start) for v in model.inputs]
        # the inputs' first derivatives (fmi2SetRealInputDerivatives) from the communication point
        # the step starts at; fmi2SetReal of an input sets its derivative back to 0
        self._du = [0.0] * len(model.inputs)
        self._sim = None
        self._out = None
        self._t_start = 0.0
        self._t_stop = math.inf
        self._t_ok = 0.0  # end of the latest completed step
        self._failed = None  # why the instance cannot step on (after an error in the model)
        self._inputs_changed = True
        self._h_fast = -1.0  # steps up to this size need no detailed check (set at initialization)
        self._ctl[0] = 0

    # ---- launcher --------------------------------------------------------------------
    def _fn(self, name):
        """The FMI 2.0 function ``fmi2<name>`` as this FMU's FMI version spells it (for messages)."""
        if self._api == "fmi2":
            return "fmi2" + name
        return "fmi3" + name.replace("FMUstate", "FMUState").replace("DeSerialize", "Deserialize")

    def _launcher_attach(self, mode="cs", event_mode_used=False, early_return_allowed=False):
        """Called by the launcher right after construction: errors become FMI statuses,
        and the outputs are served from the returned buffer (the reals as doubles, then the
        integers as int32, in the order of the value references given)."""
        return (self._real_out_vrs, self._int_out_vrs, self._obuf, self._ctl)

    @property
    def log_category_names(self):
        """The FMU's log categories (the launcher checks fmi2SetDebugLogging against them)."""
        return tuple(self.log_categories)

    def log(self, msg: str, status: int = OK, category: Optional[str] = None):
        if category is None:
            category = log_category(status)
        self.log_queue.append(LogMsg(int(status), category, msg))

    def _refuse(self, message, status=ERROR):
        """A call that cannot be carried out but leaves the instance usable: fmi2Error (the
        launcher logs the message)."""
        raise FMUError(message, status)

    # ---- variable access ----------------------------------------------------------------------
    def _variable(self, vr, type_):
        var = self._vars.get(vr)
        if var is None:
            raise FMUError(f"value reference {vr} is not a variable of {type(self).model.name}")
        if var.type != type_:
            have, want = self._type_name(var.type), self._type_name(type_)
            raise FMUError(f"variable {var.name} (value reference {vr}) is of type {have}, "
                           f"not {want}: use the {have} getter/setter")
        return var

    _TYPE_NAMES = {"fmi3": {"Real": "Float64", "Integer": "Int32"}}

    def _type_name(self, type_):
        """A type's name in this FMU's FMI version (FMI 3.0: Float64 and Int32)."""
        return self._TYPE_NAMES.get(self._api, {}).get(type_, type_)

    def _get(self, vrs, type_, convert):
        out = self._out
        values = []
        for vr in vrs:
            var = self._variable(vr, type_)
            kind, key = var.role
            if kind == "output":
                if out is None:
                    out = self._out = self._initial_outputs()
                values.append(convert(out[key]))
            elif kind == "parameter":
                values.append(convert(self._par[key]))
            else:
                values.append(convert(self._u[key]))
        return values

    def _set(self, vrs, values, type_):
        for vr, value in zip(vrs, values):
            var = self._variable(vr, type_)
            kind, key = var.role
            if kind == "parameter":
                if self._sim is not None:
                    return self._refuse(f"parameter {key} is fixed: it cannot be changed after initialization "
                                        f"(tried {value!r})")
                # all rules (finite, signs, consistency) are checked in fmi2ExitInitializationMode
                self._par[key] = value
                self._rel_tol_set = self._rel_tol_set or key == "rel_tol"
                self._out = None
                self._ctl[0] = 0
            elif kind == "input":
                # checked in fmi2DoStep, which can refuse the step without ending the instance
                self._u[key] = float(value)
                self._du[key] = 0.0  # a value set without a derivative is held
                self._inputs_changed = True
                if self._sim is None:
                    self._out = None
                    self._ctl[0] = 0
            else:
                return self._refuse(f"variable {var.name} is an output: it cannot be set")
        return None

    def get_real(self, vrs):
        return self._get(vrs, "Real", float)

    def get_integer(self, vrs):
        return self._get(vrs, "Integer", int)

    def get_boolean(self, vrs):
        return [self._variable(vr, "Boolean") for vr in vrs]  # there are none: names the problem

    def get_string(self, vrs):
        return [self._variable(vr, "String") for vr in vrs]

    def set_real(self, vrs, values):
        self._set(vrs, values, "Real")

    def set_integer(self, vrs, values):
        self._set(vrs, values, "Integer")

    def set_real_input_derivatives(self, vrs, orders, values):
        """fmi2SetRealInputDerivatives: the first derivatives of Real inputs at the current
        communication point; over the next step the model sees ``u(t) = u + du (t - t_c)``. Every
        value reference, order and value is checked before any is set."""
        fn = "fmi2SetRealInputDerivatives"
        keys = []
        for vr, order, value in zip(vrs, orders, values):
            var = self._variable(vr, "Real")
            kind, key = var.role
            if kind != "input":
                what = {"parameter": "a parameter", "output": "an output"}.get(kind, "not an input")
                return self._refuse(f"{fn} refused: variable {var.name} is {what}, not an input: only a continuous "
                                    f"Real input has a derivative to set")
            if order != 1:
                return self._refuse(f"{fn} refused: order = {int(order)} for input {var.name} violates the rule: "
                                    f"order = 1 (this FMU interpolates its inputs linearly, u(t) = u + du (t - t_c) "
                                    f"over a step; it takes no derivative of order 0 or 2 and higher)")
            value = float(value)
            if not math.isfinite(value):
                return self._refuse(f"{fn} refused: the derivative of input {var.name} = {value!r} violates the "
                                    f"rule: it must be a finite number")
            keys.append((key, value))
        for key, value in keys:
            self._du[key] = value
        if keys:
            self._inputs_changed = True
        return None

    def set_boolean(self, vrs, values):
        self._set(vrs, values, "Boolean")

    def set_string(self, vrs, values):
        self._set(vrs, values, "String")

    # ---- outputs ----------------------------------------------------------------------------
    def _model_params(self) -> Params:
        """The model's own parameters as set so far (the solver's settings left out)."""
        return split_parameters(type(self).model, self._par)[0]

    def _initial_outputs(self):
        """Outputs before initialization, from the start values (zeros if they break a rule:
        the rule is reported where it is checked, in fmi2ExitInitializationMode)."""
        model = type(self).model
        try:
            p = self._model_params()
            x, q = model.initial(p)
            out = model.output_fn(self._t_start, x, q, tuple(self._u), p)
        except (ModelError, ArithmeticError, ValueError, TypeError):
            return {v.name: 0 for v in model.all_outputs()}
        out.update(n_events=0, t_last_event=self._t_start, last_event=0)
        self._complete_outputs(self._t_start, x, q, tuple(self._u), p, out)
        return out

    def _update_outputs(self, point=None):
        """Outputs at the point served last, or at ``point = (t, x, q)`` (FMI 3.0 model exchange:
        the importer's time and states)."""
        sim = self._sim
        t, x, q = (sim.t_out, sim.x_out, sim.q_out) if point is None else point
        out = self._output_fn(t, x, q, sim.inputs_at(t) if sim.sloped else sim.u, sim.p)
        if point is None and not all(map(math.isfinite, [out[n] for n in self._model_outputs])):
            raise self._model_failed(DomainError(self._output_failure(t, x, out)))
        last = sim.last_event
        if last is None:
            out["n_events"], out["t_last_event"], out["last_event"] = sim.n_events, self._t_start, 0
        else:
            out["n_events"], out["t_last_event"], out["last_event"] = sim.n_events, last.time, last.index + 1
        if self._completes_outputs:
            self._complete_outputs(t, x, q, sim.u, sim.p, out)
        self._out = out
        self._pack_outputs(self._oview, 0, *self._out_values(out))
        self._ctl[0] = 1

    def _output_failure(self, t, x, out) -> str:
        """The engine's text (pg_engine.c, model_call) for an output function that returned a
        non-finite value: the function, the time, the state, the first such output."""
        model = type(self).model
        name = next(n for n in self._model_outputs if not math.isfinite(out[n]))
        state = ", ".join(f"{v.name} = {float(xi)!r}" for v, xi in zip(model.states, x))
        return (f"the outputs failed at t = {float(t)!r} s{f' (state {state})' if state else ''}: it returned "
                f"{name} = {float(out[name])!r} (a model function must return finite numbers)")

    def _complete_outputs(self, t, x, q, u, p, out):
        """Hook: add further variables to ``out`` (FMI 3.0: states, derivatives, event indicators)."""

    def _advance_engine(self, sim, t_end):
        """Hook: how a communication step runs the engine (FMI 3.0: stop at events)."""
        sim.advance(t_end)

    # ---- FMI calls ----------------------------------------------------------------------------
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        start_time = float(start_time)
        if not math.isfinite(start_time):
            return self._refuse(f"startTime = {start_time!r} violates the rule: a finite number")
        if stop_time is not None and not (float(stop_time) >= start_time):
            return self._refuse(f"stopTime = {stop_time!r} violates the rule: stopTime >= startTime "
                                f"= {start_time!r}")
        self._t_start = self._t_ok = start_time
        self._t_stop = math.inf if stop_time is None else float(stop_time)
        # the importer's tolerance is the solver's relative tolerance, unless the user set rel_tol
        # (before or after this call); a hint outside rel_tol's rule is brought into it, with a warning
        if tolerance is not None and not self._rel_tol_set:
            tol = float(tolerance)
            rel_tol = min(max(tol, REL_TOL_MIN), REL_TOL_MAX)
            if rel_tol != tol:
                self.log(f"{type(self).model.name}: the importer's tolerance = {tol!r} lies outside the rule of "
                         f"rel_tol, {REL_TOL_MIN:g} <= rel_tol <= {REL_TOL_MAX:g}: the solver takes rel_tol = "
                         f"{rel_tol!r}", WARNING)
            self._par["rel_tol"] = rel_tol
        return None

    def enter_initialization_mode(self):
        pass

    def exit_initialization_mode(self):
        model = type(self).model
        try:
            self._sim = Simulator(model, self._par, u=tuple(self._u), t0=self._t_start,
                                  t_stop=self._t_stop)
            self._sim.advance(self._t_start)
        except (ModelError, ValueError, ArithmeticError) as exc:
            self._sim = None
            raise FMUError(f"{model.name}: initialization failed: {exc}",
                           ERROR) from None
        self._inputs_changed = any(self._du)  # derivatives set before: the first step takes them
        self._h_fast = self._fast_step_limit()
        self._drain_engine()
        self._update_outputs()

    def do_step(self, current_time, step_size):
        sim = self._sim
        end = current_time + step_size
        # fast path, the common call: the next step of a healthy instance with unchanged inputs
        # (NaN fails every comparison and takes the detailed path)
        if not (self._failed is None and sim is not None and not self._inputs_changed
                and current_time == sim.t_out and 0.0 <= step_size <= self._h_fast
                and end <= self._t_stop):
            problem = self._step_problem(current_time, step_size)
            if problem is not None:
                return self._refuse(problem)
            if end < sim.t_out:  # within the tolerance of _step_problem
                end = sim.t_out
        try:
            if self._inputs_changed:
                sim.set_inputs(self._u, self._du)
                self._inputs_changed = False
            if self._own_advance:
                self._advance_engine(sim, end)
            else:
                sim.advance(end)
        except ModelError as exc:
            raise self._model_failed(exc) from None
        if sim.new_events or sim.new_warnings or sim.new_switches:
            self._drain_engine()
        self._update_outputs()
        self._t_ok = sim.t_out
        return True

    def _model_failed(self, exc):
        """The model cannot go on (the leg bottomed out, an event storm, ...): remember why, so that
        later steps are refused and no master mistakes a truncated run for a result, report what
        the engine noted, and return the error to raise (Error: the state saved before stays
        usable)."""
        self._failed = f"{type(self).model.name}: {exc}"
        self._drain_engine(failed=True)
        return FMUError(self._failed, ERROR)

    def _stopped(self, call, t):
        """Why ``call`` is refused after the model stopped at ``t``."""
        return (f"{call} refused: the instance stopped at t = {t!r} s ({self._failed}); "
                f"restore a saved state ({self._fn('SetFMUstate')}) or reset the instance")

    def _input_problem(self):
        """The first input that is not a finite number, as a message (None if all are)."""
        for var, v in zip(type(self).model.inputs, self._u):
            if not math.isfinite(v):
                return f"input {var.name} = {v!r} violates the rule: {var.name} must be a finite number"
        return None

    def _fast_step_limit(self):
        """Largest step the fast path of do_step takes without the detailed checks: one that surely
        needs no more than max_steps_per_call internal steps of max_step (and is finite)."""
        if type(self).model.states:
            limit = self._sim.solver.max_steps_per_call * self._sim.max_step
            return limit if limit < math.inf else -1.0  # unbounded max_step: always the detailed check
        return 1e300

    def _drain_engine(self, failed=False):
        """Report what the engine noted during the call: its warnings, and every event when the
        parameter log_events is 1. ``failed``: the call ended in an error, so the engine's counters
        were not read back after it (they count the events reported before the call)."""
        sim = self._sim
        for text in sim.new_warnings:
            self.log(f"{type(self).model.name}: {text}", WARNING)
        sim.new_warnings.clear()
        for text in sim.new_switches:
            self.log(text, OK, "logSolver")
        sim.new_switches.clear()
        new = list(sim.new_events)  # filled only with log_events = 1 (the engine keeps the history then)
        sim.new_events.clear()
        first = sim.n_events + 1 if failed else sim.n_events - len(new) + 1
        if new:
            names = [v.name for v in type(self).model.states]
            for k, ev in enumerate(new, start=first):
                self.log(event_message(k, ev.name, ev.time, names, ev.x_before), OK, EVENT_CATEGORY)

    def _step_problem(self, current_time, step_size):
        sim = self._sim
        if self._failed is not None:
            return self._stopped(f"{self._api}DoStep", self._t_ok)
        if sim is None:
            return f"{self._api}DoStep called before {self._api}ExitInitializationMode"
        if not math.isfinite(current_time):
            return (f"currentCommunicationPoint = {current_time!r} violates the rule: a finite number "
                    f"equal to the end of the previous step ({sim.t_out!r})")
        if not (math.isfinite(step_size) and step_size >= 0):
            return (f"communication step size step_size = {step_size!r} violates the rule: "
                    f"0 <= step_size < inf")
        if abs(current_time - sim.t_out) > 1e-9 * max(1.0, abs(current_time)):
            return (f"currentCommunicationPoint = {current_time!r} violates the rule: it must equal "
                    f"the end of the previous step ({sim.t_out!r})")
        end = current_time + step_size
        if not math.isfinite(end):
            return (f"communication step size step_size = {step_size!r} violates the rule: the end of "
                    f"the step, currentCommunicationPoint + step_size, must be finite")
        min_steps = step_size / sim.max_step if type(self).model.states else 0.0
        budget = sim.solver.max_steps_per_call
        if min_steps > budget:
            return (f"communication step size step_size = {step_size!r} violates the rule: one step may "
                    f"take at most max_steps_per_call = {budget:g} internal steps, and this one needs at "
                    f"least step_size/max_step = {min_steps:.3g} (max_step = {sim.max_step!r} s); use "
                    f"shorter communication steps, or raise the parameter max_steps_per_call")
        if end > self._t_stop * (1 + 1e-12) + 1e-12:
            return (f"communication step size step_size = {step_size!r} violates the rule: the step must "
                    f"end at or before stopTime = {self._t_stop!r} (it ends at {end!r})")
        if self._inputs_changed:
            return self._input_problem()
        return None

    def terminate(self):
        pass

    def reset(self):
        self._reset_state()

    def get_status(self, kind):
        if kind == "last_successful_time":
            return self._t_ok
        if kind == "terminated":
            return False
        raise FMUError(f"status kind {kind!r} is not provided")

    # ---- FMU state ----------------------------------------------------------------------------
    def _get_fmu_state(self):
        # after initialization the parameters are fixed (a set is refused) and every output dict is
        # a new one: both are shared, not copied (a master that rolls back saves once per step)
        sim = self._sim
        return {
            "owner": self._owner(),
            "sim": None if sim is None else sim.snapshot(),
            "par": dict(self._par) if sim is None else self._par, "u": list(self._u), "du": list(self._du),
            "out": self._out,
            "t_start": self._t_start, "t_stop": self._t_stop, "t_ok": self._t_ok, "failed": self._failed,
        }

    def _owner(self):
        """Whose state this is: the model, the build (the private package name, one per build of
        one model) and the FMI version; a state is restored only into an instance of the same."""
        return (type(self).model.name, _BUILD, self._api)

    def _owner_text(self, owner):
        model, build, api = owner
        return f"model {model!r}, build {build!r}, FMI {'3.0' if api == 'fmi3' else '2.0'}"

    def _check_owner(self, state, call):
        owner = state.get("owner") if isinstance(state, dict) else None
        if not (isinstance(owner, (tuple, list)) and len(owner) == 3):
            raise FMUError(f"{self._fn(call)} refused: not an FMU state of a pogofmu FMU")
        if tuple(owner) != self._owner():
            raise FMUError(f"{self._fn(call)} refused: the state belongs to {self._owner_text(tuple(owner))}; "
                           f"this instance is {self._owner_text(self._owner())}")

    def _set_fmu_state(self, state):
        self._check_owner(state, "SetFMUstate")
        self._par = dict(state["par"])
        self._u = list(state["u"])
        self._du = list(state["du"])
        self._inputs_changed = True
        self._t_start, self._t_stop = state["t_start"], state["t_stop"]
        self._t_ok, self._failed = state["t_ok"], state["failed"]
        if state["sim"] is None:
            self._sim = None
        else:
            if self._sim is None:
                self._sim = Simulator.__new__(Simulator)
            self._sim.restore(state["sim"])
            self._h_fast = self._fast_step_limit()
        if state["out"] is None:
            self._out = None
            self._ctl[0] = 0
        elif self._sim is not None:
            self._update_outputs()
        else:
            self._out = dict(state["out"])

    def _fmu_state_to_bytes(self, state, call_state=0):
        """fmi2SerializeFMUstate: the state as JSON (floats exact through repr), tagged with the
        model, the build and the FMI version it belongs to and with the call state it was taken in
        (the FMI entry file's number: the launcher keeps it with the state and checks it on
        restore), sealed with the SHA-256 of the rest (a changed byte is found, not restored)."""
        self._check_owner(state, "SerializeFMUstate")
        try:
            data = dict(state, sim=None if state["sim"] is None else snapshot_to_data(state["sim"]))
            data.pop("call_state", None)  # (a deserialized state's: the one given is the handle's)
            data["owner"] = list(data["owner"])
            body = json.dumps({"format": _STATE_FORMAT, "owner": data.pop("owner"), "state": data,
                               "taken_in": int(call_state)}, separators=(",", ":"), sort_keys=True)
        except (TypeError, ValueError) as exc:
            raise FMUError(f"{self._fn('SerializeFMUstate')}: the state cannot be serialized ({exc})") from None
        return (body + "\n" + hashlib.sha256(body.encode()).hexdigest()).encode()

    def _fmu_state_from_bytes(self, data):
        """fmi2DeSerializeFMUstate: the inverse of :meth:`_fmu_state_to_bytes`, the call state the
        state was taken in given back as its ``"call_state"``. Refused, naming the cause: bytes
        that are no pogofmu state, a state whose seal does not match (damaged), one of another
        model, build or FMI version (both named)."""
        call = self._fn("DeSerializeFMUstate")
        raw = bytes(data)
        body, sep, seal = raw.rpartition(b"\n")
        if not sep or not body.startswith(b'{"format":"pogofmu-fmu-state-'):
            raise FMUError(f"{call} refused: the {len(raw)} bytes are not a serialized pogofmu FMU state")
        if hashlib.sha256(body).hexdigest().encode() != seal.strip():
            raise FMUError(f"{call} refused: the serialized state is damaged (its SHA-256 seal does not match "
                           f"its {len(body)} bytes)")
        try:
            doc = json.loads(body.decode())
        except ValueError as exc:  # (sealed, so written so: a state of an incompatible writer)
            raise FMUError(f"{call} refused: the sealed state cannot be read ({exc})") from None
        if not isinstance(doc, dict) or doc.get("format") != _STATE_FORMAT:
            fmt = doc.get("format") if isinstance(doc, dict) else None
            raise FMUError(f"{call} refused: a pogofmu FMU state of format {fmt!r}; this FMU reads {_STATE_FORMAT!r}")
        owner = doc.get("owner")
        state = doc.get("state")
        if not isinstance(state, dict) or not isinstance(doc.get("taken_in"), int):
            raise FMUError(f"{call} refused: the sealed state has no state record or no call state")
        state["call_state"] = doc["taken_in"]
        state["owner"] = tuple(owner) if isinstance(owner, list) else owner
        try:
            self._check_owner(state, "DeSerializeFMUstate")
        except FMUError as exc:
            raise FMUError(str(exc).replace(self._fn("DeSerializeFMUstate") + " refused:", call + " refused:")) from None
        try:
            if state["sim"] is not None:
                state["sim"] = snapshot_from_data(type(self).model, state["sim"])
            for key in ("par", "u", "du", "out", "t_start", "t_stop", "t_ok", "failed"):
                state[key]  # noqa: B018 - every record is there
        except (ValueError, KeyError, TypeError, IndexError, AttributeError) as exc:
            raise FMUError(f"{call} refused: the state record is incomplete ({type(exc).__name__}: {exc})") from None
        return state
