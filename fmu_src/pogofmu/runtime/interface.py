"""What an FMU exposes, said once for both generators (the Python-hosted FMUs' adapters,
:mod:`.fmi2` and :mod:`.fmi3`, and the native FMUs' C generator, :mod:`pogofmu.codegen`): its
variables in FMI 2.0 and FMI 3.0 (names, value references, types, causalities, units, roles),
the FMI 3.0 arrays, the layout of the discrete state ``q``, and the log categories.

Standard library only: it goes into every FMU with the rest of the runtime.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

from .model import FALLING, HybridModel

__all__ = ["FmiVariable", "fmi2_variables", "fmi3_variables", "array_table", "discrete_layout", "LOG_CATEGORIES",
           "rate_unit", "indicator_name", "variable_rows"]

LOG_CATEGORIES = {
    "logStatusWarning": "messages with status Warning",
    "logStatusDiscard": "messages with status Discard",
    "logStatusError": "messages with status Error",
    "logStatusFatal": "messages with status Fatal",
    "logAll": "all other messages",
    "logEvents": "every state event: kind, exact time, state before the jump (parameter log_events = 1)",
    "logSolver": "the solver's method switches (method = 0): time, methods, stiffness estimate; the Jacobian "
                 "taken by differences (a model flow that does not run on dual numbers)",
}


@dataclass(frozen=True)
class FmiVariable:
    name: str
    vr: int
    type: str  # "Real" or "Integer"
    causality: str  # parameter | input | output
    variability: str  # fixed | continuous | discrete
    description: str
    unit: str = ""
    start: Optional[float] = None
    role: tuple = ()  # ("parameter", name) | ("input", index) | ("output", name)
    element: tuple = ()  # an element of an array input or output: (array name, 1-based index, size)


def fmi2_variables(model: HybridModel) -> Tuple[FmiVariable, ...]:
    """The FMU's variables in value-reference order: the model's parameters, the solver's settings
    (every FMU has them, after the model's own), inputs, outputs."""
    from .solver.settings import SOLVER_PARAMETERS  # (here: the engine's package imports this module)

    out = []
    for par in model.parameters + SOLVER_PARAMETERS:
        out.append(FmiVariable(par.name, len(out), "Integer" if par.integer else "Real", "parameter", "fixed",
                               par.description, par.unit, par.default, ("parameter", par.name)))
    for i, var in enumerate(model.inputs):
        integer = var.name in model.integer_inputs
        out.append(FmiVariable(var.name, len(out), "Integer" if integer else "Real", "input",
                               "discrete" if integer else "continuous", var.description, var.unit,
                               int(var.start) if integer else float(var.start), ("input", i), var.element))
    integers = model.all_integer_outputs()
    for var in model.all_outputs():
        integer = var.name in integers
        out.append(FmiVariable(var.name, len(out), "Integer" if integer else "Real", "output",
                               "discrete" if integer else "continuous", var.description, var.unit,
                               None, ("output", var.name), var.element))
    return tuple(out)


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
    """FMI 2.0 variables, then state locals, derivatives and event indicators (:mod:`.fmi3`).

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


def array_table(variables) -> Tuple[int, ...]:
    """The FMI 3.0 arrays among ``variables``: ``(value reference, number of elements)`` pairs, flat.
    An array variable has the value reference of its first element; its elements' own value
    references (consecutive, after it) are not FMI 3.0 variables: the entry file (pg_fmi3.c) expands
    an array's value reference into them, so that the backends see scalars only."""
    out = []
    for v in variables:
        if v.element and v.element[1] == 1:
            out += [v.vr, v.element[2]]
    return tuple(out)


def discrete_layout(model: HybridModel, p=None):
    """The slots of the discrete state ``q``: ``(key, 'i' or 'f')`` in the order of the model's initial
    ``q`` (the engine's layout, for the binding and the native generator alike)."""
    _, q = model.initial(model.params() if p is None else p)
    return tuple((k, "i" if isinstance(v, int) and not isinstance(v, (bool, float)) else "f") for k, v in q.items())


# a variable's causality as the C adapter's PgVar says it (fmu_src/native/adapter/pg_instance.h)
CAUSALITY = {"parameter": "p", "input": "i", "output": "o", "local": "l", "independent": "t"}


def variable_rows(model: HybridModel, variables) -> list:
    """The C adapter's variable table (``PgVar`` of pg_instance.h): ``(name, vr, type, causality,
    role, index, start)`` of each variable, the role naming the array of the adapter the value lives
    in ('m' model parameter, 's' solver setting, 'u' input, 'y' model output, 'e' engine output,
    'x' state, 'd' a state's derivative, 'g' event indicator, 't' time). One mapping for the
    native FMUs' generated C (:mod:`pogofmu.codegen.cfmu`) and the Python-hosted FMUs' table built
    at run time (:mod:`.hosted`)."""
    from .solver.settings import SOLVER_PARAMETERS  # (here: the engine's package imports this module)

    params = [p.name for p in model.parameters]
    settings = [p.name for p in SOLVER_PARAMETERS]
    outputs = [v.name for v in model.outputs]
    engine = [v.name for v in model.engine_outputs()]
    states = [v.name for v in model.states]
    events = [indicator_name(ev) for ev in model.events]
    rows = []
    for v in variables:
        kind, key = v.role
        if kind == "parameter":
            role, index = ("m", params.index(key)) if key in params else ("s", settings.index(key))
        elif kind == "input":
            role, index = "u", key
        elif kind == "output" and key in outputs:
            role, index = "y", outputs.index(key)
        elif kind == "output" and key in engine:
            role, index = "e", engine.index(key)
        elif kind == "output" and key in states:
            role, index = "x", states.index(key)
        elif kind == "output" and key == "time":
            role, index = "t", 0
        elif kind == "derived" and key.startswith("der("):
            role, index = "d", states.index(key[4:-1])
        elif kind == "derived" and key in events:
            role, index = "g", events.index(key)
        else:
            raise ValueError(f"{model.name}: variable {v.name} has a role {v.role} the C adapter does not know")
        rows.append((v.name, v.vr, "I" if v.type == "Integer" else "R", CAUSALITY[v.causality], role, index,
                     0.0 if v.start is None else v.start))
    return rows
