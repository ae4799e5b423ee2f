"""One adapter from any :class:`~pogofmu.model.HybridModel` to an FMI 2.0 co-simulation slave.

A slave file is a few lines (pythonfmu's loader looks for the literal ``class <Name>(Fmi2Slave):``
and a second instance in one process crashes unless the class body holds a method)::

    from pogofmu.fmi import HybridSlave as Fmi2Slave
    from pogofmu.models.pogo_stick import MODEL

    class PogoStick(Fmi2Slave):
        model = MODEL

        def __init__(self, **kwargs):
            super().__init__(**kwargs)

Behaviour (FMI 2.0 co-simulation, on pythonfmu 0.7):

* parameters are ``fixed``: set them before ``fmi2ExitInitializationMode``; they are all checked
  there and the initial state is derived from them;
* every ``fmi2DoStep`` holds the inputs over the step, lets the engine run to the end of the step
  (handling every event inside it) and caches all outputs;
* errors name the variable, its value and the rule, and never take the host process down:

  - a broken parameter rule (checked in ``fmi2ExitInitializationMode``) raises
    :class:`FMUError`: pythonfmu returns ``fmi2Fatal`` and logs the message (FMI 2.0: call
    nothing more on that instance; a new instance works);
  - a non-finite input, a negative step size or a wrong communication point make
    ``fmi2DoStep`` return ``fmi2Discard`` with the reason logged at status ``fmi2Error``: the
    instance stays usable, the master can correct the input and step again;
  - the trajectory leaving the model's domain (e.g. the leg bottoming out) or an event storm
    raise :class:`FMUError` (``fmi2Fatal``, message naming the condition and the time): a
    truncated run must not pass for a result (fmpy's ``simulate_fmu`` would stop quietly on
    fmi2Discard);
* pythonfmu forwards log messages only when the instance was created with ``loggingOn``
  (fmpy: ``debug_logging=True``);
* with the parameter ``log_events = 1`` every event is reported through the FMI logger
  (category ``logEvents``): kind, exact time and the state before the jump;
* ``fmi2GetFMUstate`` / ``fmi2SetFMUstate`` save and restore the whole engine: continuous and
  discrete state (mode, element memories), the integrator's step size and current step, the
  event history and the inputs.
"""
from __future__ import annotations

import math

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status

from .engine import Simulator
from .model import HybridModel, ModelError, Params

__all__ = ["HybridSlave", "FMUError"]


class FMUError(Exception):
    """An FMI call cannot be carried out; the message says why."""


class HybridSlave(Fmi2Slave):
    """Generic FMI 2.0 co-simulation slave for a :class:`HybridModel` (set ``model`` in a subclass)."""

    model: HybridModel = None
    author = "pogofmu"
    license = "MIT"
    version = "0.1.0"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        model = type(self).model
        if model is None:
            raise FMUError(f"{type(self).__name__} defines no model")
        self.description = model.description
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=model.default_stop_time,
                                                    step_size=model.default_step)
        self._par = model.defaults()
        self._u = [float(v.start) for v in model.inputs]
        self._sim = None
        self._out = None
        self._t_start = 0.0
        self._t_stop = math.inf
        self.log_categories = dict(self.log_categories, logEvents="every state event: kind, time, state")
        for par in model.parameters:
            cls = Integer if par.integer else Real
            self.register_variable(cls(
                par.name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                description=par.description,
                getter=(lambda n=par.name: self._par[n]),
                setter=(lambda v, n=par.name: self._set_parameter(n, v))))
        for i, var in enumerate(model.inputs):
            if var.name in model.integer_inputs:
                cls, variability = Integer, Fmi2Variability.discrete
            else:
                cls, variability = Real, Fmi2Variability.continuous
            self.register_variable(cls(
                var.name, causality=Fmi2Causality.input, variability=variability,
                description=var.description,
                getter=(lambda i=i: self._u[i]),
                setter=(lambda v, i=i, n=var.name: self._set_input(i, n, v))))
        integers = model.all_integer_outputs()
        self._real_outputs, self._integer_outputs = {}, {}  # value reference -> name
        for var in model.all_outputs():
            if var.name in integers:
                cls, variability, table = Integer, Fmi2Variability.discrete, self._integer_outputs
            else:
                cls, variability, table = Real, Fmi2Variability.continuous, self._real_outputs
            table[len(self.vars)] = var.name
            self.register_variable(cls(
                var.name, causality=Fmi2Causality.output, variability=variability,
                description=var.description,
                getter=(lambda n=var.name: self._output(n))))
        self._inputs_changed = True

    # ---- variable access ----------------------------------------------------------------------
    def _set_parameter(self, name, value):
        if self._sim is not None:
            raise FMUError(f"parameter {name} is fixed: it cannot be changed after initialization "
                           f"(tried {value!r})")
        # all rules (finite, signs, consistency) are checked in fmi2ExitInitializationMode
        self._par[name] = value

    def _set_input(self, i, name, value):
        # checked in fmi2DoStep, which can refuse the step without destroying the instance
        self._u[i] = float(value)
        self._inputs_changed = True

    def get_real(self, vrs):
        return self._read_outputs(vrs, self._real_outputs, float) or super().get_real(vrs)

    def get_integer(self, vrs):
        return self._read_outputs(vrs, self._integer_outputs, int) or super().get_integer(vrs)

    def _read_outputs(self, vrs, names, convert):
        """Fast path for the common call, a master reading outputs after each step: the values
        from the cached outputs, or None (parameters, inputs, a wrong type, an empty request, no
        outputs yet) for pythonfmu's generic getters."""
        out = self._out
        if out is None or not vrs:
            return None
        try:
            return [convert(out[names[vr]]) for vr in vrs]
        except KeyError:
            return None

    def _output(self, name):
        if self._out is None:
            self._out = self._initial_outputs()
        return self._out[name]

    def _initial_outputs(self):
        model = type(self).model
        try:
            p = Params(self._par)
            x, q = model.initial(p)
        except ModelError:
            return {v.name: 0 for v in model.all_outputs()}
        out = model.output_fn(self._t_start, x, q, tuple(self._u), p)
        out.update(n_events=0, t_last_event=self._t_start, last_event=0)
        return out

    def _update_outputs(self):
        sim = self._sim
        ev = sim.events
        x, q = sim.x_out, sim.q_out
        out = type(self).model.output_fn(sim.t_out, x, q, sim.u, sim.p)
        out["n_events"] = len(ev)
        out["t_last_event"] = ev[-1].time if ev else self._t_start
        out["last_event"] = ev[-1].index + 1 if ev else 0
        self._out = out

    # ---- FMI calls ----------------------------------------------------------------------------
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self._t_start = float(start_time)
        self._t_stop = math.inf if stop_time is None else float(stop_time)

    def exit_initialization_mode(self):
        model = type(self).model
        try:
            self._sim = Simulator(model, Params(self._par), u=tuple(self._u), t0=self._t_start,
                                  t_stop=self._t_stop)
        except (ModelError, ValueError) as exc:
            raise FMUError(f"{model.name}: initialization failed: {exc}") from None
        self._sim.advance(self._t_start)
        self._update_outputs()

    def do_step(self, current_time, step_size):
        problem = self._step_problem(current_time, step_size)
        if problem is not None:
            # pythonfmu can only return fmi2Discard (or fmi2Fatal by raising, which destroys the
            # instance): refuse the step with the reason logged at status fmi2Error; the master
            # can correct the input or the step and go on with the same instance.
            self.log(problem, Fmi2Status.error)
            return False
        sim = self._sim
        n_before = len(sim.events)
        try:
            if self._inputs_changed:
                sim.set_input(self._u)
                self._inputs_changed = False
            sim.advance(max(current_time + step_size, sim.t_out))
        except ModelError as exc:
            # the model cannot go on: fmi2Fatal (raise), so that no master mistakes a truncated
            # run for a result.  Nothing is logged in this call: pythonfmu would drop the message.
            raise FMUError(f"{type(self).model.name}: {exc}") from None
        if len(sim.events) != n_before:
            self._log_events(n_before)
        self._update_outputs()
        return True

    def _log_events(self, start):
        if not self._par.get("log_events"):
            return
        names = [v.name for v in type(self).model.states]
        for k, ev in enumerate(self._sim.events[start:], start=start + 1):
            state = ", ".join(f"{n}={v!r}" for n, v in zip(names, ev.x_before))
            self.log(f"event {k} {ev.name} at t = {ev.time!r} s; state before jump: {state}",
                     Fmi2Status.ok, "logEvents")

    def _step_problem(self, current_time, step_size):
        sim = self._sim
        if sim is None:
            return "fmi2DoStep called before fmi2ExitInitializationMode"
        if not (math.isfinite(step_size) and step_size >= 0):
            return (f"communication step size step_size = {step_size!r} violates the rule: "
                    f"0 <= step_size < inf")
        if abs(current_time - sim.t_out) > 1e-9 * max(1.0, abs(current_time)):
            return (f"currentCommunicationPoint = {current_time!r} violates the rule: it must equal "
                    f"the end of the previous step ({sim.t_out!r})")
        if self._inputs_changed:
            for var, v in zip(type(self).model.inputs, self._u):
                if not math.isfinite(v):
                    return f"input {var.name} = {v!r} violates the rule: {var.name} must be a finite number"
        return None

    def terminate(self):
        pass

    # ---- FMU state ----------------------------------------------------------------------------
    def _get_fmu_state(self):
        return {
            "sim": None if self._sim is None else self._sim.snapshot(),
            "par": dict(self._par), "u": list(self._u),
            "out": None if self._out is None else dict(self._out),
            "t_start": self._t_start, "t_stop": self._t_stop,
        }

    def _set_fmu_state(self, state):
        self._par = dict(state["par"])
        self._u = list(state["u"])
        self._inputs_changed = True
        self._out = None if state["out"] is None else dict(state["out"])
        self._t_start, self._t_stop = state["t_start"], state["t_stop"]
        if state["sim"] is None:
            self._sim = None
        else:
            if self._sim is None:
                self._sim = Simulator.__new__(Simulator)
            self._sim.restore(state["sim"])
