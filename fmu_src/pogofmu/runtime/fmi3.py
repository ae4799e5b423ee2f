"""FMI 3.0 for any :class:`~pogofmu.runtime.model.HybridModel`: model exchange and co-simulation with
event mode, on top of the FMI 2.0 adapter (:class:`~pogofmu.runtime.fmi2.HybridSlave`).

Nothing here is specific to a model, and no equation is written twice: flows, guards, jumps,
outputs, parameter rules and the engine are the model's and :mod:`pogofmu.runtime.engine`'s.  The same
slave files (``fmu_src/slave_*.py``) make both generations: for an FMI 3.0 FMU the boot code
(``pogofmu_boot.py``, ``fmi=3`` in ``resources/pogofmu_launch.txt``) wraps the slave class with
:func:`fmi3_class`.  The C side is the FMI 3.0 entry file ``fmu_src/native/fmi3/pg_fmi3.c`` with the bridge to
Python ``fmu_src/native/python/pg_bridge.c``.

Variables (:func:`fmi3_variables`): those of the FMI 2.0 FMU (same names, units, descriptions,
value references), then

* every continuous state that is not already an output of the same name, as a ``local``;
* ``der(<state>)`` for every state (``ContinuousStateDerivative``);
* ``guard_<event>`` for every event of the model (``EventIndicator``): the event's guard while the
  event is active in the current mode, ``1`` while it is inactive (a value that cannot cross zero);
* ``time``, the independent variable FMI 3.0 requires.

Model exchange (``fmi3InstantiateModelExchange``): the importer integrates the states and locates
the sign changes of the indicators.  ``fmi3UpdateDiscreteStates`` applies the jump of the first
event (in the model's priority order) whose guard has crossed *in its direction*: a falling guard
fires when it is ``<= 0`` and was ``> 0`` at some indicator evaluation since the latest event
(a rising one: ``>= 0`` after ``< 0``).  A guard exactly zero after a jump is disarmed until it
leaves zero, the engine's restart rule.  A sign change in the wrong direction applies nothing.
``valuesOfContinuousStatesChanged`` is true exactly when the jump changed a state;
``nominalsOfContinuousStatesChanged`` is always false (nominals are 1).  The domain of the model
is checked in ``fmi3CompletedIntegratorStep`` (which asks for Event Mode instead when an armed
guard has crossed: a state a step past an event may lie outside the domain until the jump),
event storms and domain at each event.

Co-simulation (``fmi3InstantiateCoSimulation``): the engine inside, as in FMI 2.0.  With
``earlyReturnAllowed`` ``fmi3DoStep`` stops at the first event of the step, at its exact time
(``lastSuccessfulTime``, ``earlyReturn`` when it lies before the end of the step):

* with ``eventModeUsed`` it stops *before* the jump (outputs: the left limit) and sets
  ``eventHandlingNeeded``; ``fmi3UpdateDiscreteStates`` in Event Mode applies the jump;
* without, it applies the jump itself and returns right after it.

Without ``earlyReturnAllowed`` it behaves like the FMI 2.0 FMU (every event handled inside the
step).  The step sequence of the engine, hence every event time, does not depend on where the
steps stop.
"""
from __future__ import annotations

import math
from typing import Tuple

from .fmi2 import FMUError, FmiVariable, HybridSlave, fmi2_variables
from .model import FALLING, HybridModel, ModelError
from .status import ERROR

__all__ = ["fmi3_variables", "fmi3_class", "Fmi3Slave", "rate_unit", "indicator_name"]

# the unit of d(state)/dt for the units of pogofmu.runtime.units
_RATE_UNITS = {"m": "m/s", "m/s": "m/s2", "m.s": "m", "s": "", "J": "W", "": ""}


def rate_unit(unit: str) -> str:
    """The unit of the time derivative of a state in ``unit`` (the SI names of the common ones,
    ``<unit>/s`` for any other: ``degC`` -> ``degC/s``, ``N.m`` -> ``(N.m)/s``)."""
    if unit in _RATE_UNITS:
        return _RATE_UNITS[unit]
    return f"{unit}/s" if unit.replace("_", "").isalnum() else f"({unit})/s"


def indicator_name(event) -> str:
    return f"guard_{event.name}"


def fmi3_variables(model: HybridModel) -> Tuple[FmiVariable, ...]:
    """FMI 2.0 variables, then state locals, derivatives and event indicators (module docstring).

    Outputs, state locals and time have the role ``("output", name)`` (``outputs[name]`` of the
    adapter, refreshed once per step and served from the launcher's buffers); derivatives and
    indicators ``("derived", name)``, computed only when asked for."""
    out = list(fmi2_variables(model))
    names = {v.name for v in out}
    for var in model.states:
        if var.name not in names:
            out.append(FmiVariable(var.name, len(out), "Real", "local", "continuous",
                                   f"continuous state: {var.description}", var.unit, None, ("output", var.name)))
    for var in model.states:
        out.append(FmiVariable(f"der({var.name})", len(out), "Real", "local", "continuous",
                               f"time derivative of {var.name} ({var.description})", rate_unit(var.unit), None,
                               ("derived", f"der({var.name})")))
    for ev in model.events:
        way = "falling: fires at > 0 -> <= 0" if ev.direction == FALLING else "rising: fires at < 0 -> >= 0"
        out.append(FmiVariable(indicator_name(ev), len(out), "Real", "local", "continuous",
                               f"event indicator of {ev.name}: its guard ({way}) while active, 1 while inactive",
                               "", None, ("derived", indicator_name(ev))))
    out.append(FmiVariable("time", len(out), "Real", "independent", "continuous", "simulation time", "s", None,
                           ("output", "time")))
    return tuple(out)


def check_state_outputs(model: HybridModel):
    """An output that shares its name with a state is that state's variable in FMI 3.0: its value
    must be the state's (checked at the default initial state).  Returns a problem or None."""
    p = model.params()
    x, q = model.initial(p)
    u = tuple(float(v.start) for v in model.inputs)
    out = model.output_fn(0.0, x, q, u, p)
    for i, var in enumerate(model.states):
        if var.name in out and out[var.name] != x[i]:
            return (f"{model.name}: output {var.name} = {out[var.name]!r} differs from the state {var.name} = "
                    f"{x[i]!r}: an FMI 3.0 state variable must carry the state's value")
    return None


_INTERFACES = {"me": "model-exchange", "cs": "co-simulation"}


def _before_side(falling, g):
    return g > 0.0 if falling else g < 0.0


def _indicators(events, x, q, u, p):
    """Each event's guard where the event is active in mode ``q``, 1 (cannot cross zero) elsewhere."""
    return [ev.guard(x, q, u, p) if ev.active(q) else 1.0 for ev in events]


class Fmi3Slave(HybridSlave):
    """The FMI 3.0 adapter; use :func:`fmi3_class` to derive it for a slave class."""

    _tables = None
    _api = "fmi3"

    @classmethod
    def _variable_tables(cls):
        if cls.__dict__.get("_tables") is None:
            variables = fmi3_variables(cls.model)
            served = [v for v in variables if v.role[0] == "output"]
            cls._tables = (variables, {v.vr: v for v in variables},
                           [v for v in served if v.type == "Real"], [v for v in served if v.type == "Integer"])
        return cls._tables

    def _reset_state(self):
        super()._reset_state()
        if not hasattr(self, "_mode"):
            self._mode, self._event_mode_used, self._early_return_allowed = "cs", False, False
        self._me_t = 0.0
        self._me_x = None
        self._armed = [False] * len(type(self).model.events)
        self._me_stale = False
        self._cs_stale = False  # co-simulation: inputs set in Event Mode, outputs not yet refreshed
        self._event_mode = False
        self._stop = None

    def _launcher_attach(self, mode="cs", event_mode_used=False, early_return_allowed=False):
        if mode not in ("cs", "me"):
            raise FMUError(f"interface type {mode!r} is not provided (model exchange or co-simulation)")
        self._mode = mode
        self._event_mode_used, self._early_return_allowed = bool(event_mode_used), bool(early_return_allowed)
        return super()._launcher_attach(mode, event_mode_used, early_return_allowed)

    # ---- variables --------------------------------------------------------------------------
    def _complete_outputs(self, t, x, q, u, p, out):
        out["time"] = t
        for var, v in zip(type(self).model.states, x):
            out[var.name] = v

    def _derived(self):
        """Derivatives and event indicators at the point the outputs describe."""
        model = type(self).model
        sim = self._sim
        if sim is None:
            try:
                p = self._model_params()
                x, q = model.initial(p)
            except (ModelError, ArithmeticError, ValueError, TypeError):
                return {v.role[1]: 0.0 for v in type(self).variables() if v.role[0] == "derived"}
            t, u = self._t_start, tuple(self._u)
        elif self._mode == "me":
            t, x, q, u, p = self._me_t, self._me_x, sim.q, sim.u, sim.p
        else:
            t, x, q, u, p = sim.t_out, sim.x_out, sim.q_out, sim.u, sim.p
        f = model.flow(t, x, q, u, p) if model.states else []
        out = {f"der({var.name})": v for var, v in zip(model.states, f)}
        out.update(zip(map(indicator_name, model.events), _indicators(model.events, x, q, u, p)))
        return out

    def _initial_outputs(self):
        out = super()._initial_outputs()
        for var in type(self).variables():  # zeros where the start values break a rule
            if var.role[0] == "output":
                out.setdefault(var.role[1], 0)
        return out

    def _set(self, vrs, values, type_):
        result = super()._set(vrs, values, type_)
        if self._inputs_changed and self._sim is not None:
            if self._mode == "me":
                self._stale()  # outputs, derivatives and indicators may feed through from the inputs
            elif self._event_mode:
                # co-simulation in Event Mode: the outputs that feed through from the inputs follow
                # them at this instant (superdense time), refreshed when next read or updated
                self._cs_stale = True
                self._ctl[0] = 0
        return result

    def _get(self, vrs, type_, convert):
        if self._me_stale:
            self._me_refresh()
        elif self._cs_stale:
            self._cs_event_inputs()
        derived = None
        values = []
        for vr in vrs:
            var = self._variable(vr, type_)
            if var.role[0] == "derived":
                if derived is None:
                    derived = self._derived()
                values.append(convert(derived[var.role[1]]))
            else:
                values += super()._get((vr,), type_, convert)
        return values

    # ---- initialization ---------------------------------------------------------------------
    def exit_initialization_mode(self):
        super().exit_initialization_mode()
        # FMI 3.0: model exchange, and co-simulation with eventModeUsed, go on in Event Mode
        self._event_mode = self._mode == "me" or self._event_mode_used
        sim = self._sim
        self._me_t, self._me_x = sim.t_out, list(sim.x_out)
        self._arm()

    def _require_mode(self, mode, what):
        """Refuse ``what`` (a function of interface ``mode``) on an instance of the other interface."""
        if self._mode != mode:
            this, other = (_INTERFACES[mode], _INTERFACES["cs" if mode == "me" else "me"])
            raise FMUError(f"{what} is a {this} function: this instance is a {other} instance")

    def _me_instance(self, what):
        self._require_mode("me", what)
        if self._failed is not None:
            raise FMUError(self._stopped(what, self._me_t))
        if self._sim is None:
            raise FMUError(f"{what} called before fmi3ExitInitializationMode")
        if self._inputs_changed:
            self._me_inputs()
        return self._sim

    def _me_inputs(self):
        problem = self._input_problem()
        if problem is not None:
            raise FMUError(problem)
        self._sim.restart_at(self._me_t, self._me_x, self._u)
        self._inputs_changed = False
        self._stale()

    def _stale(self):
        self._me_stale = True
        self._ctl[0] = 0

    def _me_refresh(self):
        self._me_stale = False
        sim = self._sim
        if sim is None:
            return
        if self._inputs_changed:
            self._me_inputs()
            self._me_stale = False
        self._update_outputs((self._me_t, self._me_x, sim.q))

    def _arm(self):
        """After initialization and after each event: a guard is armed if it lies strictly on the
        side before its crossing (a guard exactly zero waits until it leaves zero)."""
        sim = self._sim
        q, u, p, x = sim.q, sim.u, sim.p, self._me_x
        self._armed = [ev.active(q) and _before_side(ev.direction == FALLING, ev.guard(x, q, u, p))
                       for ev in type(self).model.events]

    # ---- model exchange ---------------------------------------------------------------------
    def set_time(self, t):
        self._require_mode("me", "fmi3SetTime")
        t = float(t)
        if not math.isfinite(t):
            raise FMUError(f"time = {t!r} violates the rule: a finite number")
        self._me_t = t
        self._stale()

    def set_continuous_states(self, x):
        self._require_mode("me", "fmi3SetContinuousStates")
        n = len(type(self).model.states)
        if len(x) != n:
            raise FMUError(f"{len(x)} continuous states given, {type(self).model.name} has {n}")
        if self._sim is None:
            raise FMUError("fmi3SetContinuousStates called before fmi3ExitInitializationMode")
        self._me_x = [float(v) for v in x]
        self._stale()

    def get_continuous_states(self):
        if self._sim is None:
            model = type(self).model
            try:
                return list(model.initial(self._model_params())[0])
            except (ModelError, ArithmeticError, ValueError, TypeError) as exc:
                raise FMUError(f"{model.name}: no initial state: {exc}") from None
        return list(self._me_x)

    def number_of_continuous_states(self):
        return len(type(self).model.states)

    def number_of_event_indicators(self):
        return len(type(self).model.events)

    def get_nominals(self):
        return [1.0] * len(type(self).model.states)

    def _initial_point(self, what):
        """Initialization Mode (no engine yet): the initial state and mode from the parameters set so
        far, ``(t, x, q, u, p)``; a parameter that breaks a rule is refused naming it."""
        model = type(self).model
        try:
            p = self._model_params()
            x, q = model.initial(p)
        except (ModelError, ArithmeticError, ValueError, TypeError) as exc:
            raise FMUError(f"{what} refused: no initial state with these parameters: {exc}") from None
        return self._t_start, [float(v) for v in x], q, tuple(self._u), p

    def get_derivatives(self):
        if self._sim is None and self._mode == "me":
            t, x, q, u, p = self._initial_point("fmi3GetContinuousStateDerivatives")
            return type(self).model.flow(t, x, q, u, p) if x else []
        sim = self._me_instance("fmi3GetContinuousStateDerivatives")
        return sim.fun(self._me_t, self._me_x) if self._me_x else []

    def get_event_indicators(self):
        if self._sim is None and self._mode == "me":
            t, x, q, u, p = self._initial_point("fmi3GetEventIndicators")
            return _indicators(type(self).model.events, x, q, u, p)
        sim = self._me_instance("fmi3GetEventIndicators")
        q, u, p, x = sim.q, sim.u, sim.p, self._me_x
        armed = self._armed
        events = type(self).model.events
        z = _indicators(events, x, q, u, p)
        for k, (ev, g) in enumerate(zip(events, z)):
            if not armed[k] and ev.active(q) and _before_side(ev.direction == FALLING, g):
                armed[k] = True  # seen on the side before its crossing: may fire
        return z

    def completed_integrator_step(self):
        """(enterEventMode, terminateSimulation).  An armed guard on its after side asks for Event
        Mode (the importer's step ended past an event; the state may lie a step beyond the guard,
        outside the domain, until the jump); otherwise the model's domain is checked."""
        sim = self._me_instance("fmi3CompletedIntegratorStep")
        events = type(self).model.events
        pending = False
        for k, (ev, g) in enumerate(zip(events, self.get_event_indicators())):
            pending |= self._armed[k] and ev.active(sim.q) and not _before_side(ev.direction == FALLING, g)
        if pending:
            return (True, False)
        msg = sim.domain_problem(self._me_t, self._me_x)
        if msg is not None or not all(map(math.isfinite, self._me_x)):
            self._failed = (f"{type(self).model.name}: the trajectory left the model's domain at t = "
                            f"{self._me_t:.10g} s: {msg or 'the state became non-finite'}")
            raise FMUError(self._failed, ERROR)
        return (False, False)

    def _me_update(self):
        sim = self._me_instance("fmi3UpdateDiscreteStates")
        model = type(self).model
        t, x = self._me_t, self._me_x
        q, u, p = sim.q, sim.u, sim.p
        fired = None
        for k, ev in enumerate(model.events):  # priority order
            if self._armed[k] and ev.active(q) and not _before_side(ev.direction == FALLING, ev.guard(x, q, u, p)):
                fired = k
                break
        changed = False
        if fired is not None:
            try:
                x_new = sim.apply_event(fired, t, x)
            except ModelError as exc:
                raise self._model_failed(exc) from None
            changed = x_new != x
            self._me_x = list(x_new)
            self._drain_engine()
            self._stale()
        self._arm()
        return changed

    # ---- co-simulation ----------------------------------------------------------------------
    def _advance_engine(self, sim, t_end):
        if sim.event_due:
            sim.advance(sim.t)  # an event the importer left unhandled: its jump first
        self._stop = None
        if not self._early_return_allowed:
            sim.advance(t_end)
        elif sim.advance_to_event(t_end):
            self._stop = sim.t_out
            if not self._event_mode_used:
                sim.advance(sim.t_out)  # handled here: return right after its jump

    def do_step3(self, current_time, step_size):
        """fmi3DoStep: (eventHandlingNeeded, terminateSimulation, earlyReturn, lastSuccessfulTime)."""
        self._require_mode("cs", "fmi3DoStep")
        self._stop = None
        self.do_step(current_time, step_size)
        stop = self._stop
        end = current_time + step_size
        return (stop is not None and self._event_mode_used, False, stop is not None and stop < end, self._t_ok)

    def _cs_event_inputs(self):
        """Co-simulation, Event Mode: the inputs set at this instant take effect now (the engine goes
        on from here with them; the outputs are refreshed)."""
        self._cs_stale = False
        sim = self._sim
        problem = self._input_problem()
        if problem is not None:
            raise FMUError(problem)
        try:
            sim.set_input(self._u)
        except ModelError as exc:
            raise self._model_failed(exc) from None
        self._inputs_changed = False
        self._update_outputs()

    def _cs_update(self):
        sim = self._sim
        if sim is None:
            raise FMUError("fmi3UpdateDiscreteStates called before fmi3ExitInitializationMode")
        if self._cs_stale:
            self._cs_event_inputs()
        if sim.event_due:
            try:
                sim.advance(sim.t)
            except ModelError as exc:
                raise self._model_failed(exc) from None
            self._drain_engine()
            self._update_outputs()
        return False

    # ---- both -------------------------------------------------------------------------------
    def enter_event_mode(self):
        self._event_mode = True

    def enter_continuous_time_mode(self):
        self._event_mode = False

    def enter_step_mode(self):
        self._event_mode = False

    def update_discrete_states(self):
        """(discreteStatesNeedUpdate, terminateSimulation, nominalsOfContinuousStatesChanged,
        valuesOfContinuousStatesChanged, nextEventTimeDefined, nextEventTime)"""
        changed = self._me_update() if self._mode == "me" else self._cs_update()
        return (False, False, False, changed, False, 0.0)

    def _get_fmu_state(self):
        state = super()._get_fmu_state()
        state["fmi3"] = {"t": self._me_t, "x": None if self._me_x is None else list(self._me_x),
                         "armed": list(self._armed)}
        return state

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        extra = state["fmi3"]
        self._me_t, self._armed = extra["t"], list(extra["armed"])
        self._me_x = None if extra["x"] is None else list(extra["x"])
        self._stop = None
        if self._mode == "me" and self._sim is not None:
            self._stale()


_CLASSES = {}


def fmi3_class(slave_cls):
    """The FMI 3.0 slave class for a slave file's class (same name and model), made once."""
    cls = _CLASSES.get(slave_cls)
    if cls is None:
        cls = _CLASSES[slave_cls] = type(slave_cls.__name__, (Fmi3Slave, slave_cls),
                                         {"__module__": slave_cls.__module__, "_tables": None})
    return cls
