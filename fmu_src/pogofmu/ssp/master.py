"""Running a system: instantiate and initialize its FMUs in update order, then advance them with
the chosen master algorithm (:mod:`.algorithms`), recording every connector (:mod:`.record`)."""
from __future__ import annotations

import math
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Optional

from .algorithms import INPUTS, Exchange, Progress, fixed_step, grid_point, synchronized
from .components import Fmi2CoSimulation, Fmi3CoSimulation, Fmi3ModelExchange
from .graph import algebraic_loop, loop_text
from .package import SSPError, read_ssd, unpack
from .record import Result
from .validate import _fmu_unit, apply_overrides, validate

ALGORITHMS = ("gauss-seidel", "jacobi", "model-exchange")
DEFAULT_INPUTS = "interpolate"  # --inputs (docs/ssp-master.md, "Inputs over a step": why)
DEFAULT_EVENT_TOLERANCE = 1e-10  # s: bisection of a discrete output's change (FMUs of other tools)


def _warn(text):
    print(text, file=sys.stderr, flush=True)


def _seconds(md, var, value):
    """``value`` of ``var`` in seconds if its unit is a time (``s``, or a unit definition whose base
    unit is the second), else None."""
    unit = _fmu_unit(var)
    if unit == "s":
        return value
    for u in md.unitDefinitions or ():
        b = u.baseUnit
        if u.name == unit and b is not None and b.s == 1 and not any((b.kg, b.m, b.A, b.K, b.mol, b.cd, b.rad)):
            return value * (b.factor or 1.0) + (b.offset or 0.0)
    return None


def time_constants(system, selected):
    """``[(component, parameter, seconds)]``: the parameters the components state as time
    constants — a time (its unit) that its description calls a time constant; FMI has no
    attribute for one, so this is all a master can know of a component's dynamics. The value is
    the selected parameter set's, else the FMU's start value."""
    out = []
    for name, comp in system.components.items():
        ps = selected.get(name)
        given = {q.name: q.value for q in ps.parameters} if ps is not None else {}
        for var in comp.model_description.modelVariables:
            if var.causality != "parameter" or "time constant" not in (var.description or "").lower():
                continue
            try:
                value = float(given.get(var.name, var.start))
            except (TypeError, ValueError):
                continue
            tau = _seconds(comp.model_description, var, value)
            if tau is not None and tau > 0:
                out.append((name, var.name, tau))
    return out


def check_step_against_time_constants(system, selected, step, algorithm):
    """A warning for every stated time constant the communication step does not resolve: a lag of
    time constant tau whose output is sampled every h and held is stable for h < 2 tau with
    Gauss–Seidel (``e_{k+1} = (1 - h/tau) e_k``) and h < tau with Jacobi (one step later:
    ``e_{k+1} = e_k - (h/tau) e_{k-1}``). Model exchange has no communication step."""
    if algorithm == "model-exchange":
        return
    factor, rule = (1.0, "h < tau with Jacobi") if algorithm == "jacobi" else (2.0, "h < 2 tau with Gauss-Seidel")
    for name, var, tau in time_constants(system, selected):
        if step >= factor * tau:
            _warn(f"warning: the communication step {step:g} s does not resolve the time constant "
                  f"{name}.{var} = {tau:g} s: a loop through it, sampled and held at this step, is unstable "
                  f"({rule}; docs/ssp-master.md, \"Sampled loop\")")


def _check_interface(comp, algorithm):
    """The component's FMU offers what the algorithm needs (checked before anything is written)."""
    md = comp.model_description
    if algorithm == "model-exchange" and not (md.fmiVersion.startswith("3") and md.modelExchange is not None):
        raise SSPError(f"Component {comp.name}: --algorithm model-exchange needs FMI 3.0 model exchange, and "
                       f"{comp.source} is FMI {md.fmiVersion}" + ("" if md.modelExchange else " without model exchange"))


def _instantiate(comp, work, echo, algorithm, events):
    version = comp.model_description.fmiVersion
    if algorithm == "model-exchange":
        return Fmi3ModelExchange(comp, work, echo)
    if version.startswith("3"):
        return Fmi3CoSimulation(comp, work, echo, events=events)
    return Fmi2CoSimulation(comp, work, echo)


def initialize(ex: Exchange, t0, selected):
    """Initialize in update order: parameters from the selected set, inputs from the outputs of
    components initialized before (a later component already sees the initial outputs of the
    earlier ones); then the inputs fed by later components; then the discrete iteration of every
    component that is in Event Mode after initialization (FMI 3.0)."""
    for inst in ex.order:
        ps = selected.get(inst.name)
        try:
            inst.enter_initialization(t0)
            names = [p.name for p in (ps.parameters if ps is not None else []) if p.name in inst.variables]
            values = [p.value for p in ps.parameters if p.name in inst.variables] if ps is not None else []
            if names:
                inst.set_values(names, values)
            if ex.ready(inst):
                ex.feed(inst)
            inst.exit_initialization(t0)
        except SSPError:
            raise
        except Exception as exc:  # noqa: BLE001 - fmpy raises FMICallException on an error status
            inst.dead = "fatal" in str(exc).lower()
            raise SSPError(f"Component {inst.name}: initialization failed with "
                           f"{ps.source if ps else 'no parameter set'}: {inst.last_error()}") from None
        ex.read(inst)
    for inst in ex.order:  # inputs of earlier components fed by later ones
        ex.feed(inst)


def select_columns(system, order, record=None):
    """``[(component, connector)]`` recorded: every connector, or those matching a glob pattern
    of ``record`` (``component.connector``, e.g. ``Actuator_*.z``); a pattern that matches
    nothing is a mistake, not an empty column set."""
    cols = [(n, c) for n in order for c in system.components[n].connectors.values()]
    if record is None:
        return cols
    from fnmatch import fnmatchcase

    patterns = [p.strip() for p in (record.split(",") if isinstance(record, str) else record)]
    patterns = [p for p in patterns if p]
    if not patterns:
        raise SSPError("--record: no pattern given (glob patterns over component.connector, e.g. 'Actuator_*.z')")
    def match(name, pat):  # a name matches itself: an array element's brackets (B.z[3]) are no glob class
        return name == pat or fnmatchcase(name, pat)

    for pat in patterns:
        if not any(match(f"{n}.{c.name}", pat) for n, c in cols):
            raise SSPError(f"--record {pat!r} matches no connector of the system (patterns are globs over "
                           f"component.connector, e.g. 'Actuator_*.z,Reconstructor.piston_rms')")
    return [(n, c) for n, c in cols if any(match(f"{n}.{c.name}", p) for p in patterns)]


def check_options(step=1e-3, stop_time=None, start_time=None, algorithm="gauss-seidel", events=True,
                  event_tolerance=DEFAULT_EVENT_TOLERANCE, rel_tol=1e-10, abs_tol=1e-12, threads=1,
                  inputs=DEFAULT_INPUTS):
    """The run's options (those of :func:`simulate`), checked before anything is read."""
    if algorithm not in ALGORITHMS:
        raise SSPError(f"algorithm {algorithm!r} is not one of {', '.join(ALGORITHMS)}")
    if inputs not in INPUTS:
        raise SSPError(f"--inputs {inputs!r} is not one of {', '.join(INPUTS)}")
    for what, value in (("communication step (--step)", step), ("stop time (--stop-time)", stop_time),
                        ("start time", start_time), ("event tolerance (--event-tolerance)", event_tolerance),
                        ("relative tolerance (--rel-tol)", rel_tol), ("absolute tolerance (--abs-tol)", abs_tol)):
        if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise SSPError(f"{what} = {value!r} must be a finite number")
    if not step > 0:
        raise SSPError(f"communication step (--step) = {step!r} must be > 0")
    if not event_tolerance > 0:
        raise SSPError(f"event tolerance (--event-tolerance) = {event_tolerance!r} must be > 0")
    if algorithm == "model-exchange" and not events:
        raise SSPError("--events off is co-simulation with a fixed communication step; --algorithm model-exchange "
                       "has no communication step and always locates the events: give one or the other")
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise SSPError(f"--threads {threads!r} must be a whole number >= 1")
    if not (0 < rel_tol < 1 and abs_tol > 0):
        raise SSPError(f"model-exchange tolerances --rel-tol = {rel_tol!r}, --abs-tol = {abs_tol!r} must be "
                       f"0 < rel-tol < 1 and abs-tol > 0")


def time_span(system, start_time, stop_time, step):
    """``(t0, t_last)``: the run's start and its last communication point (the stop time given,
    else the system's default experiment's), which must be a whole number of steps after t0."""
    t0 = system.start_time if start_time is None else float(start_time)
    t_end = stop_time if stop_time is not None else system.stop_time
    if t_end is None:
        raise SSPError("no stop time: give one (--stop-time) or set ssd:DefaultExperiment stopTime")
    if not t_end > t0:
        raise SSPError(f"stop time {t_end!r} s must be later than the start time {t0!r} s")
    n_steps = int(round((t_end - t0) / step))
    if n_steps < 1 or not math.isclose(t0 + n_steps * step, t_end, rel_tol=1e-9, abs_tol=1e-12):
        raise SSPError(f"stop time {t_end} - start time {t0} is not a whole number of steps {step}")
    return t0, grid_point(t0, step, n_steps)  # (the last communication point)


def simulate(ssp, parameters: Optional[str] = None, stop_time: Optional[float] = None, step: float = 1e-3,
             start_time: Optional[float] = None, algorithm: str = "gauss-seidel", progress: bool = False,
             echo_log: bool = True, sink=None, events: bool = True, event_tolerance: float = DEFAULT_EVENT_TOLERANCE,
             rel_tol: float = 1e-10, abs_tol: float = 1e-12, threads: int = 1, record=None,
             inputs: str = DEFAULT_INPUTS, overrides=None):
    """Run an SSP package; return a :class:`~.record.Result` (see the package docstring).

    ``algorithm``: ``gauss-seidel`` or ``jacobi`` co-simulation, with every component brought to
    each event instant (``events=True``) or a fixed communication step (``events=False``); or
    ``model-exchange``, the strongly coupled solution (FMI 3.0 model exchange, ``rel_tol`` and
    ``abs_tol`` its integrator's tolerances). ``step`` is the communication step, the output grid.

    ``inputs``: ``interpolate`` (the default) — with Gauss–Seidel, a component whose FMU can
    interpolate its inputs (FMI 2.0 ``canInterpolateInputs``) gets every real input whose source has
    already stepped as the line between the source's values at the step's start and end
    (``fmi2SetRealInputDerivatives``); ``hold`` — every input held over a step. Jacobi and model
    exchange are not affected.

    ``threads``: the components of one level of the update order (none feeding another, e.g. the
    mirror's actuators) step in parallel on this many threads; the results are those of one
    thread, to the bit. ``record``: glob patterns over ``component.connector`` (a list, or one
    string with commas), the columns recorded (default: every connector). ``overrides``:
    ``{"Component.parameter": value}`` set over the selected parameter sets (``--set``).

    The returned recorder also gets ``warnings``: ``[(component, message)]``, every warning the
    components logged, and ``event_sources``: ``[(t, components)]``, one entry per
    event instant the master synchronized, naming the components whose event it was (empty for
    an event seen only through the integrator of ``model-exchange``).

    ``sink(names, types, units, span)``, if given, makes the recorder instead (an object with
    ``add(row)`` and ``close(complete)``, e.g. a :class:`~.record.CSVStream`): it is called once the
    package and every number are found valid, before any FMU is loaded, and what it returns is
    returned.
    """
    # no scipy import here: it would cost the master 50 MB of its memory budget
    check_options(step, stop_time, start_time, algorithm, events, event_tolerance, rel_tol, abs_tol, threads, inputs)
    work = Path(tempfile.mkdtemp(prefix="pogofmu_ssp_"))
    instances = {}
    res = ex = None
    try:
        root = unpack(Path(ssp), work / "package")
        system = read_ssd(root)
        selected = apply_overrides(system, validate(system, parameters), overrides)
        t0, t_last = time_span(system, start_time, stop_time, step)
        check_step_against_time_constants(system, selected, step, algorithm)
        loop = algebraic_loop(system)
        if loop is not None:
            text = (f"algebraic loop {loop_text(loop)}: every output in it depends directly on the input "
                    f"before it (the FMUs' declared dependencies)")
            if algorithm == "model-exchange":
                raise SSPError(f"{text}; the strongly coupled algorithm does not solve algebraic loops")
            _warn(f"warning: {text}; a communication step breaks it (the coupling delay), the initialization "
                  f"and the event iteration iterate it to a fixed point")
        order = system.update_order()
        for name in order:
            comp = system.components[name]
            comp.model_description_path = root / comp.source
            _check_interface(comp, algorithm)
        cols = select_columns(system, order, record)
        columns = (["event"] + [f"{n}.{c.name}" for n, c in cols], ["Integer"] + [c.type for _, c in cols],
                   [None] + [c.unit or _fmu_unit(system.components[n].variables[c.name]) for n, c in cols],
                   (t0, t_last))
        res = (sink or Result)(*columns)
        if hasattr(res, "plot_only"):  # the figure's envelope: only the signals it draws
            from .plot import plotted

            res.plot_only(plotted(columns[0], dict(zip(columns[0], columns[1])), system.connections))
        for name in order:
            instances[name] = _instantiate(system.components[name], work, echo_log, algorithm, events)
        ex = Exchange(system, instances, order, res, threads=threads, columns=cols)
        if inputs == "interpolate" and algorithm == "gauss-seidel":
            ex.interpolate_inputs()
        initialize(ex, t0, selected)
        prog = Progress(system.name, t0, t_last, progress)
        if algorithm == "model-exchange":
            from .coupled import model_exchange

            model_exchange(ex, t0, t_last, step, rel_tol, abs_tol, progress=prog)
        else:
            jacobi = algorithm == "jacobi"
            if events:
                synchronized(ex, t0, t_last, step, event_tolerance, jacobi, progress=prog, warn=_warn)
            else:
                ex.row(t0)
                fixed_step(ex, t0, t_last, step, jacobi, progress=prog)
        res.system = system.name
        res.parameter_set = ", ".join(sorted({ps.name for ps in selected.values() if ps is not None})) or "none"
        res.algorithm, res.events, res.step, res.connections = algorithm, events, step, list(system.connections)
        res.inputs = inputs
        res.event_sources = ex.event_sources
        # the components' warnings (status fmi2Warning), in the order they came: the last line of
        # `pogofmu ssp run` counts them, so that one printed amid the progress is not missed
        res.warnings = [(name, text) for name, inst in instances.items() for status, text in inst.messages
                        if status == 1]
        res.close(complete=True)
        res.last_time = t_last
        return res
    finally:
        if ex is not None:
            ex.close()  # the step threads (every call has ended)
        if res is not None:
            res.close(complete=False)  # a no-op once the run is complete
        for inst in instances.values():
            try:
                inst.close()
            except Exception:  # noqa: BLE001 - never mask the real error while cleaning up
                pass
        shutil.rmtree(work, ignore_errors=True)


__all__ = ["ALGORITHMS", "check_options", "time_span", "simulate", "initialize", "Fmi2CoSimulation", "Fmi3CoSimulation", "Fmi3ModelExchange"]
