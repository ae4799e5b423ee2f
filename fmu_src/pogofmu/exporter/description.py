"""``modelDescription.xml`` of an FMU (FMI 2.0 co-simulation, FMI 3.0 model exchange + co-simulation)
from the adapter's variable table, and the FMI 3.0 ``buildDescription.xml`` of a source FMU.

The same writer serves every model, the project's and a user's: units are the model's own
(:func:`pogofmu.exporter.checks.check_unit` checks their syntax), declared in ``<UnitDefinitions>``
with their base-unit exponents where :mod:`pogofmu.runtime.units` knows them, by name otherwise.
"""
from __future__ import annotations

import datetime
import os
from xml.etree import ElementTree as ET

from pogofmu.runtime.solver import solver_defaults

from .errors import BuildError

# the default rel_tol: an importer that passes the declared tolerance (fmpy does, given none) runs
# the FMU's own solver as one that passes none (the tolerance passed becomes rel_tol)
DEFAULT_EXPERIMENT_TOLERANCE = solver_defaults()["rel_tol"]


def project_version() -> str:
    from pogofmu import __version__

    return __version__


def _number(value, integer):
    return str(int(value)) if integer else repr(float(value))


def unit_definitions(used) -> ET.Element:
    from pogofmu.runtime.units import UNITS

    defs = ET.Element("UnitDefinitions")
    for unit in sorted(used):
        u = ET.SubElement(defs, "Unit", name=unit)
        if UNITS.get(unit) is not None:
            ET.SubElement(u, "BaseUnit", {k: str(v) for k, v in UNITS[unit].items()})
    return defs


def cosimulation_events(model):
    """The events a co-simulation step of this model can contain: its events if it has states (a
    model without states changes only with its inputs, which are held over a step)."""
    return [ev.name for ev in model.events] if model.states else []


def _pogofmu_annotation(parent, model):
    """What a master needs to know beyond the standard: the events a step may contain (the SSP
    master saves and restores FMI 2.0 states only around components that can have one)."""
    ET.SubElement(parent, "Events", cosimulation=" ".join(cosimulation_events(model)))


def _tool() -> str:
    return f"pogofmu {project_version()} (pogofmu export)"


def _description_body(root, cls, variables):
    """UnitDefinitions, LogCategories, DefaultExperiment (the same in FMI 2.0 and 3.0); returns the
    empty ModelVariables element."""
    model = cls.model
    used = {v.unit for v in variables if v.type == "Real" and v.unit}
    if used:
        root.append(unit_definitions(used))
    cats = ET.SubElement(root, "LogCategories")
    for name, description in cls.log_categories.items():
        ET.SubElement(cats, "Category", name=name, description=description)
    # tolerance: the default rel_tol (above); an importer integrating in model exchange at this
    # tolerance puts the PogoStick's contacts 1e-4 s off, at 1e-10 within 7e-8 s (docs/fmi3.md)
    ET.SubElement(root, "DefaultExperiment", startTime="0.0", stopTime=repr(float(model.default_stop_time)),
                  tolerance=repr(DEFAULT_EXPERIMENT_TOLERANCE), stepSize=repr(float(model.default_step)))
    if root.get("fmiVersion") == "2.0":
        _pogofmu_annotation(ET.SubElement(ET.SubElement(root, "VendorAnnotations"), "Tool", name="pogofmu"), model)
    return ET.SubElement(root, "ModelVariables")


def _variable_attributes(model, v):
    if not v.description:
        raise BuildError(f"{model.name}: variable {v.name} has no description")
    attrs = {"name": v.name, "valueReference": str(v.vr), "description": v.description,
             "causality": v.causality, "variability": v.variability}
    if v.causality == "parameter":
        attrs["initial"] = "exact"
    return attrs


def _dependencies(knowns):
    """The dependencies/dependenciesKind attributes listing ``knowns`` (indices or value references)."""
    knowns = sorted(knowns)
    return {"dependencies": " ".join(map(str, knowns)), "dependenciesKind": " ".join(["dependent"] * len(knowns))}


def model_description_fmi2(cls, token: str, source_files=(), directional=False) -> bytes:
    """The FMI 2.0 modelDescription.xml; ``source_files`` (a source FMU's compilation units, in
    ``sources/``) are listed in ``<CoSimulation><SourceFiles>``; ``directional``: the FMU provides
    directional derivatives (the native FMUs)."""
    model = cls.model
    variables = cls.variables()
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": model.name, "guid": token, "description": model.description,
        "author": cls.author, "license": cls.license, "version": project_version(),
        "generationTool": _tool(), "generationDateAndTime": _build_date(),
        # an array's elements are the scalars z[1] ... z[N]: names of the structured convention
        "variableNamingConvention": "structured" if any(v.element for v in variables) else "flat",
        "numberOfEventIndicators": "0"})
    ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": model.name, "needsExecutionTool": "false",
        "canHandleVariableCommunicationStepSize": "true", "canInterpolateInputs": "true",
        "maxOutputDerivativeOrder": "0", "canRunAsynchronuously": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "true",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
        "providesDirectionalDerivative": "true" if directional else "false"})
    if source_files:
        files = ET.SubElement(root.find("CoSimulation"), "SourceFiles")
        for name in source_files:
            ET.SubElement(files, "File", {"name": name})
    mv = _description_body(root, cls, variables)
    for v in variables:
        attrs = _variable_attributes(model, v)
        sv = ET.SubElement(mv, "ScalarVariable", attrs)
        t = {}
        if v.type == "Real" and v.unit:
            t["unit"] = v.unit
        if v.start is not None:
            t["start"] = _number(v.start, v.type == "Integer")
        ET.SubElement(sv, v.type, t)
    from .dependencies import initial_dependencies

    ms = ET.SubElement(root, "ModelStructure")
    outputs = [(i, v) for i, v in enumerate(variables, start=1) if v.causality == "output"]
    index_of = {v.name: i for i, v in enumerate(variables, start=1)}
    if outputs:
        out_el = ET.SubElement(ms, "Outputs")
        init_el = ET.SubElement(ms, "InitialUnknowns")
        initial = initial_dependencies(model)
        for index, v in outputs:
            # co-simulation: an output depends on the inputs it feeds through (and on internal states,
            # which are not knowns of the FMU); at initialization on the parameters its initial value
            # derives from and the inputs it feeds through (the engine's counters on none)
            deps = [index_of[n] for n in model.feeds_through(v.name)]
            ET.SubElement(out_el, "Unknown", index=str(index), **_dependencies(deps))
            ET.SubElement(init_el, "Unknown", index=str(index),
                          **_dependencies(index_of[n] for n in initial.get(f"output:{v.name}", ())))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def model_description_fmi3(cls, token: str, directional=False) -> bytes:
    """FMI 3.0: model exchange and co-simulation in one description (pogofmu.runtime.fmi3 for the extra
    variables: state locals, derivatives, event indicators, and the independent variable time)."""
    from pogofmu.runtime.fmi3 import check_state_outputs, fmi3_class
    from pogofmu.runtime.interface import indicator_name

    from .dependencies import structure

    problem = check_state_outputs(cls.model)
    if problem:
        raise BuildError(problem)
    cls3 = fmi3_class(cls)
    model = cls.model
    variables = cls3.variables()
    by_name = {v.name: v for v in variables}
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": model.name, "instantiationToken": token,
        "description": model.description, "author": cls.author, "license": cls.license,
        "version": project_version(), "generationTool": _tool(),
        "generationDateAndTime": _build_date(), "variableNamingConvention": "flat"})
    common = {"modelIdentifier": model.name, "canGetAndSetFMUState": "true", "canSerializeFMUState": "true",
              "providesDirectionalDerivatives": "true" if directional else "false",
              "providesAdjointDerivatives": "false",
              "canBeInstantiatedOnlyOncePerProcess": "false"}
    ET.SubElement(root, "ModelExchange", dict(common, needsCompletedIntegratorStep="true"))
    ET.SubElement(root, "CoSimulation", dict(common, canHandleVariableCommunicationStepSize="true",
                                             hasEventMode="true", canReturnEarlyAfterIntermediateUpdate="false",
                                             providesIntermediateUpdate="false", maxOutputDerivativeOrder="0"))
    mv = _description_body(root, cls, variables)
    declared = {d.name: d for d in model.declared_inputs() + model.declared_outputs()}
    for v in variables:
        if v.element and v.element[1] > 1:
            continue  # an array is one variable, at its first element's value reference
        attrs = _variable_attributes(model, v)
        if v.element:  # the array: the declared name and description
            attrs.update(name=v.element[0], description=declared[v.element[0]].description)
        if v.type == "Real" and v.unit:
            attrs["unit"] = v.unit
        if v.start is not None:
            attrs["start"] = " ".join([_number(v.start, v.type == "Integer")] * (v.element[2] if v.element else 1))
        if v.name.startswith("der(") and v.name[4:-1] in by_name:
            attrs["derivative"] = str(by_name[v.name[4:-1]].vr)
        var_el = ET.SubElement(mv, "Float64" if v.type == "Real" else "Int32", attrs)
        if v.element:
            ET.SubElement(var_el, "Dimension", start=str(v.element[2]))
    ms = ET.SubElement(root, "ModelStructure")
    states = [by_name[s.name] for s in model.states]
    derivatives = [by_name[f"der({s.name})"] for s in model.states]
    deps = structure(model)

    # an array's element stands for the array (its value reference is the first element's): the
    # dependencies of FMI 3.0 are on whole variables
    head = {v.vr: v.vr - v.element[1] + 1 if v.element else v.vr for v in variables}

    def knowns(key):
        on_states, on_inputs = deps.get(key, (set(), set()))
        return {head[by_name[n].vr] for n in on_states} | {head[by_name[n].vr] for n in on_inputs}

    def union(keys):
        return set().union(*map(knowns, keys))

    def keys_of(v, prefix):  # the element keys of an array variable, the variable's own otherwise
        if not v.element:
            return [f"{prefix}{v.name}"]
        return [f"{prefix}{w.name}" for w in variables if w.element and w.element[0] == v.element[0]]

    engine_outputs = {v.name for v in model.engine_outputs()}
    for v in variables:
        if v.causality == "output" and v.element and v.element[1] > 1:
            continue
        if v.causality == "output" and v.element:
            ET.SubElement(ms, "Output", valueReference=str(v.vr), **_dependencies(union(keys_of(v, "output:"))))
        elif v.causality == "output":
            # the engine's event counters change only at events: they depend on no known
            known = set() if v.name in engine_outputs else knowns(f"output:{v.name}")
            ET.SubElement(ms, "Output", valueReference=str(v.vr), **_dependencies(known))
    for s_var, v in zip(model.states, derivatives):
        ET.SubElement(ms, "ContinuousStateDerivative", valueReference=str(v.vr),
                      **_dependencies(knowns(f"der:{s_var.name}")))
    from .dependencies import initial_dependencies

    at_init = initial_dependencies(model)
    key_of = {v.vr: keys_of(v, "output:") for v in variables if v.causality == "output" and not
              (v.element and v.element[1] > 1)}
    key_of.update({v.vr: [f"state:{s.name}"] for s, v in zip(model.states, states)})
    key_of.update({v.vr: [f"der:{s.name}"] for s, v in zip(model.states, derivatives)})
    for vr in sorted(key_of):
        ET.SubElement(ms, "InitialUnknown", valueReference=str(vr),
                      **_dependencies({head[by_name[n].vr] for key in key_of[vr] for n in at_init.get(key, ())}))
    for ev in model.events:
        ET.SubElement(ms, "EventIndicator", valueReference=str(by_name[indicator_name(ev)].vr),
                      **_dependencies(knowns(f"indicator:{ev.name}")))
    _pogofmu_annotation(ET.SubElement(ET.SubElement(root, "Annotations"), "Annotation", type="org.pogofmu"), model)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def build_description_fmi3(model_name: str, units) -> bytes:
    """FMI 3.0 ``sources/buildDescription.xml``: one build configuration, the compilation units."""
    root = ET.Element("fmiBuildDescription", {"fmiVersion": "3.0"})
    config = ET.SubElement(root, "BuildConfiguration", {"modelIdentifier": model_name})
    files = ET.SubElement(config, "SourceFileSet", {"language": "C99"})
    for name in units:
        ET.SubElement(files, "SourceFile", {"name": name})
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"


def _build_date():
    """SOURCE_DATE_EPOCH (reproducible builds) or now."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    t = (datetime.datetime.fromtimestamp(int(epoch), datetime.timezone.utc) if epoch
         else datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0))
    return t.strftime("%Y-%m-%dT%H:%M:%SZ")
