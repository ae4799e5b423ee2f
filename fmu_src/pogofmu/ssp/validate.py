"""Validating a system against itself and its FMUs, before anything is loaded: every problem is
reported with the element it concerns."""
from __future__ import annotations

from pathlib import Path
from typing import Dict, Optional

from .package import REAL, WHOLE, Parameter, ParameterSet, SSPError, System, _problem_text, same_type

def _fmu_unit(var):
    unit = getattr(var, "unit", None)
    if unit is None and getattr(var, "declaredType", None) is not None:
        unit = getattr(var.declaredType, "unit", None)
    return unit or None


def _units_differ(a: Optional[str], b: Optional[str]) -> bool:
    """Two units that cannot be connected: both declared and different. In SSP a connector's
    unit is optional and a variable without a unit has none to convert: it connects to any unit
    as it is, with no conversion (as libcosim and OMSimulator do)."""
    return bool(a) and bool(b) and a != b


def _connector_unit(comp, con) -> Optional[str]:
    """The unit a connector carries: its own, else its FMU variable's (None: no unit)."""
    var = comp.variables.get(con.name) if comp.variables else None
    return con.unit or (_fmu_unit(var) if var is not None else None)


def _dimensions(var) -> list:
    """The sizes of an FMI 3.0 array variable (fmpy's ``dimensions``), [] for a scalar or none."""
    return [None if d.start is None else int(d.start) for d in getattr(var, "dimensions", None) or ()] \
        if var is not None else []


def validate(system: System, parameters: Optional[str] = None) -> Dict[str, Optional[ParameterSet]]:
    """Check the system against itself and its FMUs; return the parameter set of every component.

    Raises :class:`SSPError` listing every problem found, each naming its element.
    """
    from fmpy import read_model_description

    problems = []
    # ---- components and their FMUs ----
    for comp in system.components.values():
        if not comp.source:
            problems.append(f"Component {comp.name}: no source attribute")
            continue
        fmu = system.root / comp.source
        if not fmu.is_file():
            problems.append(f"Component {comp.name}: source {comp.source} is not in the package")
            continue
        try:
            md = read_model_description(str(fmu), validate=False)
        except Exception as exc:  # noqa: BLE001 - any unreadable FMU is a problem of the package
            problems.append(f"Component {comp.name}: source {comp.source} is not a readable FMU ({exc})")
            continue
        if md.coSimulation is None:
            problems.append(f"Component {comp.name}: {comp.source} does not support co-simulation")
            continue
        comp.model_description = md
        comp.variables = {v.name: v for v in md.modelVariables}
        for con in comp.connectors.values():
            where = f"Connector {comp.name}.{con.name}"
            if con.kind not in ("input", "output", "parameter", "calculatedParameter", "inout"):
                problems.append(f"{where}: kind {con.kind!r} is not an SSP connector kind")
            if con.type is None:
                problems.append(f"{where}: no type (ssc:Real, ssc:Integer, ...)")
            var = comp.variables.get(con.name)
            dims = _dimensions(var)
            if con.element and var is None:  # an element of an FMI 3.0 array: the array is the variable
                array, i, size = con.element
                var = comp.variables.get(array)
                dims = _dimensions(var)
                if var is None:
                    problems.append(f"Connector {comp.name}.{array}: {comp.source} has no variable {array!r}")
                    continue
                if dims != [size]:
                    problems.append(f"Connector {comp.name}.{array}: ssc:Dimension size={size} but the FMU's "
                                    f"variable {array} has the dimensions {dims or 'of a scalar'}")
                    continue
                comp.variables[con.name] = var
                comp.elements[con.name] = con.element
            elif var is None:
                problems.append(f"{where}: {comp.source} has no variable {con.name!r}")
                continue
            elif dims:
                problems.append(f"{where}: the FMU's variable {con.name} is an array of {dims}: declare the "
                                f"connector with <ssc:Dimension size=\"{dims[0]}\"/> (SSP 2.0)")
                continue
            if con.type is not None and not same_type(var.type, con.type):
                problems.append(f"{where}: type {con.type} but the FMU's variable is {var.type}")
            if con.kind in ("input", "output") and var.causality != con.kind:
                problems.append(f"{where}: kind {con.kind} but the FMU's variable has causality {var.causality}")
            fu = _fmu_unit(var)
            if con.type in REAL and _units_differ(con.unit, fu):
                problems.append(f"{where}: unit mismatch: connector unit {con.unit!r}, FMU unit {fu!r}")
    # ---- connections ----
    fed = {}
    for c in system.connections:
        ok = True
        for role, el, cn in (("start", c.start_element, c.start_connector), ("end", c.end_element, c.end_connector)):
            if not el:
                problems.append(f"{c}: {role}Element missing (connections to the system's own connectors are "
                                f"not supported)")
                ok = False
            elif el not in system.components:
                problems.append(f"{c}: unknown component {el!r} (not in ssd:Elements)")
                ok = False
            elif cn not in system.components[el].connectors:
                problems.append(f"{c}: dangling: component {el} declares no connector {cn!r}")
                ok = False
        if not ok:
            continue
        a = system.components[c.start_element].connectors[c.start_connector]
        b = system.components[c.end_element].connectors[c.end_connector]
        if a.kind not in ("output", "inout", "parameter", "calculatedParameter"):
            problems.append(f"{c}: start connector {c.start_element}.{a.name} is an {a.kind}, not an output")
        if b.kind not in ("input", "inout"):
            problems.append(f"{c}: end connector {c.end_element}.{b.name} is an {b.kind}, not an input")
        if not same_type(a.type, b.type):
            problems.append(f"{c}: type mismatch: {a.type} -> {b.type}")
        else:
            ua = _connector_unit(system.components[c.start_element], a)
            ub = _connector_unit(system.components[c.end_element], b)
            if _units_differ(ua, ub):
                problems.append(f"{c}: unit mismatch: {c.start_element}.{a.name} is in {ua!r}, "
                                f"{c.end_element}.{b.name} in {ub!r} (no unit conversion)")
        key = (c.end_element, c.end_connector)
        if key in fed:
            problems.append(f"{c}: input {c.end_element}.{c.end_connector} is already fed by Connection {fed[key]}")
        fed[key] = c.index
    # ---- parameter sets ----
    for comp in system.components.values():
        for source in comp.bindings:
            if source not in system.parameter_sets:
                problems.append(f"Component {comp.name}: ParameterBinding source {source} is missing from the package")
    chosen = None
    if parameters is not None:
        matches = [ps for ps in system.parameter_sets.values()
                   if ps.source == f"resources/{parameters}.ssv" or ps.name == parameters]
        if not matches:
            avail = ", ".join(selectable_sets(system)) or "none"
            problems.append(f"parameter set {parameters!r}: no resources/{parameters}.ssv in the package "
                            f"(available: {avail})")
        else:
            chosen = matches[0]
    selected = {}
    for comp in system.components.values():
        if chosen is not None:
            selected[comp.name] = chosen if comp.bindings else None
        else:
            sets = [system.parameter_sets[s] for s in comp.bindings if s in system.parameter_sets]
            # SSP: bindings apply in order, later values win
            merged = {}
            for ps in sets:
                for p in ps.parameters:
                    merged[p.name] = p
            selected[comp.name] = (ParameterSet("+".join(ps.name for ps in sets), "+".join(ps.source for ps in sets),
                                                list(merged.values())) if sets else None)
    used = {}
    for comp in system.components.values():
        ps = selected.get(comp.name)
        if ps is None or not comp.variables:
            continue
        for p in ps.parameters:
            var = comp.variables.get(p.name)
            if var is None:
                used.setdefault((ps.source, p.name), False)
                continue
            used[(ps.source, p.name)] = True
            where = f"parameter {p.name} of {ps.source} applied to {comp.name}"
            if var.causality not in ("parameter", "input") and var.variability != "tunable":
                problems.append(f"{where}: the FMU's variable has causality {var.causality}")
            if not same_type(p.type, var.type) and not (p.type in REAL and var.type in WHOLE
                                                        and float(p.value).is_integer()):
                problems.append(f"{where}: type {p.type} but the FMU's variable is {var.type}")
            fu = _fmu_unit(var)
            if _units_differ(p.unit, fu):
                problems.append(f"{where}: unit mismatch: {p.unit!r} in the .ssv, {fu!r} in the FMU")
    for (source, name), applied in used.items():
        if not applied:
            problems.append(f"parameter {name} of {source}: no component bound to this set has a variable {name!r}")
    if problems:
        raise SSPError(_problem_text(system, problems))
    return selected


def apply_overrides(system: System, selected, overrides) -> Dict[str, Optional[ParameterSet]]:
    """The selected parameter sets with ``overrides`` (``{"Component.parameter": value}``, what
    ``--set`` and a system sweep give) put over them: a value replaces the set's value of that
    parameter in its place, or comes after the set's values. Each name must be a real or integer
    parameter of a component's FMU; an integer takes integral values only."""
    if not overrides:
        return selected
    out = dict(selected)
    for key, value in overrides.items():
        comp_name, dot, name = str(key).partition(".")
        comp = system.components.get(comp_name) if dot else None
        if comp is None:
            raise SSPError(f"--set {key}={value!r}: {comp_name!r} is not a component of system {system.name!r} "
                           f"(give Component.parameter; components: {', '.join(system.components)})")
        var = (comp.variables or {}).get(name)
        if var is None or var.causality != "parameter":
            params = sorted(n for n, v in (comp.variables or {}).items() if v.causality == "parameter")
            raise SSPError(f"--set {key}={value!r}: {name!r} is not a parameter of Component {comp_name} "
                           f"({comp.source}; parameters: {', '.join(params)})")
        if var.type not in REAL + WHOLE or var.type == "Enumeration":
            raise SSPError(f"--set {key}={value!r}: parameter {name} of Component {comp_name} is {var.type}; only "
                           f"reals and integers can be set")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value \
                or value in (float("inf"), float("-inf")):
            raise SSPError(f"--set {key}={value!r}: the value must be a finite number")
        if var.type in WHOLE:
            if float(value) != int(value):
                raise SSPError(f"--set {key}={value!r}: parameter {name} of Component {comp_name} is an "
                               f"{var.type}: the value must be integral")
            value = int(value)
        else:
            value = float(value)
        ps = out.get(comp_name)
        given = Parameter(name, var.type, value, None)
        if ps is None:
            out[comp_name] = ParameterSet("--set", "--set", [given])
            continue
        params = [given if p.name == name else p for p in ps.parameters]
        if not any(p.name == name for p in ps.parameters):
            params.append(given)
        out[comp_name] = ParameterSet(ps.name, ps.source, params)
    return out


def selectable_sets(system) -> list:
    """The names ``--parameters`` offers: every .ssv but a component's part of another set
    (``moon.PogoStick.ssv``, packed beside ``moon.ssv`` so that each binding names only its own)."""
    stems = [Path(s).stem for s in system.parameter_sets]
    return [s for s in stems if not (s.rpartition(".")[0] in stems and s.rpartition(".")[2] in system.components)]
