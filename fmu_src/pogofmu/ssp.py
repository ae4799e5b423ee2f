"""SSP master: run an SSP 1.0 package (.ssp) of FMI 2.0 co-simulation FMUs with fmpy.

    python -m pogofmu.ssp run dist/SpaceHopper.ssp --parameters moon --stop-time 30 --step 1e-3 [--out DIR]
    python -m pogofmu.ssp check dist/SpaceHopper.ssp

What it does (README "SpaceHopper.ssp: the SSP master"):

* reads ``SystemStructure.ssd`` (one flat ``ssd:System`` of ``ssd:Component`` s with
  ``source="resources/X.fmu"``, typed and united ``ssd:Connectors``, ``ssd:Connections``,
  component ``ssd:ParameterBindings`` referencing ``.ssv`` files) and the ``.ssv`` files;
* validates the whole system before loading anything and rejects it with one message per
  problem, each naming the element: unknown component, dangling connection (connector not
  declared, or not a variable of the FMU), kind/type mismatch, unit mismatch (connection ends,
  connector vs FMU, parameter vs FMU), missing FMU or ``.ssv``, a parameter no component takes;
* selects a parameter set: the ``.ssv`` bound in the ``.ssd`` (SSP's own meaning), or with
  ``--parameters NAME`` the set ``resources/NAME.ssv`` (or the ``ssv:ParameterSet`` named NAME),
  which then takes the place of every component's bound set;
* instantiates every FMU with fmpy (logging on; warnings and errors are printed), sets the
  parameters as start values, initializes the components in order (an input of a later
  component already sees the initial outputs of the earlier ones);
* steps with a fixed communication step, by default **Gauss-Seidel in connection order** (a
  component's inputs are set from the latest outputs just before its ``fmi2DoStep``; the order is
  that of first appearance in ``ssd:Connections``), or Jacobi (``--algorithm jacobi``: every input
  from the outputs at the start of the step, as libcosim's fixed-step algorithm);
* checks every ``fmi2DoStep``: an error status ends the run with the component, the time and the
  FMU's own log message (never a silently truncated result);
* writes every connector at every communication point to a CSV and plots them (PNG), and prints a
  progress line every 10 % of a long run.

Host-side code (fmpy, numpy, matplotlib); never imported inside an FMU.
"""
from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
import time as _time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional
from xml.etree import ElementTree as ET

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
}
TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration", "Binary")
ALGORITHMS = ("gauss-seidel", "jacobi")


class SSPError(Exception):
    """The package cannot be run as it is; the message names every offending element."""


# =============================================================================================
# the system as read from the package
# =============================================================================================

@dataclass
class Connector:
    name: str
    kind: str
    type: str
    unit: Optional[str]


@dataclass
class Component:
    name: str
    source: str
    connectors: Dict[str, Connector]
    bindings: List[str]  # sources of the component's ParameterBindings, in order
    variables: dict = field(default_factory=dict)  # name -> fmpy ScalarVariable (filled on validation)
    model_description: object = None


@dataclass
class Connection:
    index: int  # 1-based position in ssd:Connections
    start_element: str
    start_connector: str
    end_element: str
    end_connector: str

    def __str__(self):
        return (f"Connection {self.index} ({self.start_element}.{self.start_connector} -> "
                f"{self.end_element}.{self.end_connector})")


@dataclass
class Parameter:
    name: str
    type: str
    value: object
    unit: Optional[str]


@dataclass
class ParameterSet:
    name: str
    source: str  # path inside the package, e.g. resources/moon.ssv
    parameters: List[Parameter]


@dataclass
class System:
    name: str
    root: Path  # directory of the unpacked package
    components: Dict[str, Component]  # in ssd:Elements order
    connections: List[Connection]
    parameter_sets: Dict[str, ParameterSet]  # by source
    start_time: float = 0.0
    stop_time: Optional[float] = None

    def order(self) -> List[str]:
        """Gauss-Seidel order: first appearance in the connections (start, then end element),
        then the components no connection mentions, in ssd:Elements order."""
        seen = []
        for c in self.connections:
            for name in (c.start_element, c.end_element):
                if name in self.components and name not in seen:
                    seen.append(name)
        return seen + [n for n in self.components if n not in seen]


def _tag(prefix, name):
    return f"{{{NS[prefix]}}}{name}"


def _connector_type(el):
    for t in TYPES:
        child = el.find(f"ssc:{t}", NS)
        if child is not None:
            return t, child.get("unit")
    return None, None


def unpack(ssp: Path, dest: Path) -> Path:
    """Unzip an .ssp into ``dest`` (a directory holding SystemStructure.ssd is used as it is)."""
    ssp = Path(ssp)
    if ssp.is_dir():
        return ssp
    if not ssp.exists():
        raise SSPError(f"{ssp}: no such file")
    try:
        with zipfile.ZipFile(ssp) as z:
            z.extractall(dest)
    except zipfile.BadZipFile:
        raise SSPError(f"{ssp}: not an SSP package (not a zip archive)") from None
    return dest


def read_ssd(root: Path) -> System:
    """Parse ``root/SystemStructure.ssd`` and the .ssv files under ``root/resources``."""
    path = root / "SystemStructure.ssd"
    if not path.exists():
        raise SSPError(f"{root}: the package holds no SystemStructure.ssd")
    try:
        tree = ET.parse(path)
    except ET.ParseError as exc:
        raise SSPError(f"SystemStructure.ssd is not well-formed XML: {exc}") from None
    top = tree.getroot()
    if top.tag != _tag("ssd", "SystemStructureDescription"):
        raise SSPError(f"SystemStructure.ssd: root element is {top.tag}, not ssd:SystemStructureDescription "
                       f"(namespace {NS['ssd']})")
    system_el = top.find("ssd:System", NS)
    if system_el is None:
        raise SSPError("SystemStructure.ssd: no ssd:System element")
    components = {}
    elements = system_el.find("ssd:Elements", NS)
    problems = []
    for el in (list(elements) if elements is not None else []):
        if el.tag != _tag("ssd", "Component"):
            problems.append(f"ssd:Elements: element {el.tag.split('}')[-1]} {el.get('name')!r} is not supported "
                            f"(only ssd:Component; no nested systems)")
            continue
        name = el.get("name")
        connectors = {}
        for cel in el.findall("ssd:Connectors/ssd:Connector", NS):
            t, unit = _connector_type(cel)
            connectors[cel.get("name")] = Connector(cel.get("name"), cel.get("kind"), t, unit)
        bindings = []
        for bel in el.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
            if bel.get("source") is None:
                problems.append(f"Component {name}: a ParameterBinding without source (inline values "
                                f"are not supported)")
            else:
                bindings.append(bel.get("source"))
        if name in components:
            problems.append(f"Component {name}: the name is used twice in ssd:Elements")
        components[name] = Component(name, el.get("source"), connectors, bindings)
    connections = []
    for i, cel in enumerate(system_el.findall("ssd:Connections/ssd:Connection", NS), start=1):
        connections.append(Connection(i, cel.get("startElement"), cel.get("startConnector"),
                                      cel.get("endElement"), cel.get("endConnector")))
    start, stop = 0.0, None
    de = top.find("ssd:DefaultExperiment", NS)
    if de is not None:
        start = float(de.get("startTime", 0.0))
        stop = float(de.get("stopTime")) if de.get("stopTime") is not None else None
    parameter_sets = {}
    for ssv in sorted((root / "resources").glob("*.ssv")) if (root / "resources").is_dir() else []:
        source = f"resources/{ssv.name}"
        parameter_sets[source] = read_ssv(ssv, source)
    system = System(system_el.get("name") or top.get("name"), root, components, connections, parameter_sets,
                    start, stop)
    if problems:
        raise SSPError(_problem_text(system, problems))
    return system


def read_ssv(path: Path, source: str) -> ParameterSet:
    try:
        top = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise SSPError(f"{source} is not well-formed XML: {exc}") from None
    if top.tag != _tag("ssv", "ParameterSet"):
        raise SSPError(f"{source}: root element is {top.tag}, not ssv:ParameterSet (namespace {NS['ssv']})")
    params = []
    for pel in top.findall("ssv:Parameters/ssv:Parameter", NS):
        for t in ("Real", "Integer", "Boolean", "String"):
            v = pel.find(f"ssv:{t}", NS)
            if v is not None:
                raw = v.get("value")
                value = {"Real": float, "Integer": int, "Boolean": lambda s: s in ("true", "1"),
                         "String": str}[t](raw)
                params.append(Parameter(pel.get("name"), t, value, v.get("unit")))
                break
        else:
            raise SSPError(f"{source}: parameter {pel.get('name')!r} has no Real/Integer/Boolean/String value")
    return ParameterSet(top.get("name"), source, params)


def _problem_text(system, problems):
    head = f"SSP system {system.name!r} is invalid ({len(problems)} problem{'s' * (len(problems) > 1)}):"
    return "\n  ".join([head] + problems)


# =============================================================================================
# validation
# =============================================================================================

def _fmu_unit(var):
    unit = getattr(var, "unit", None)
    if unit is None and getattr(var, "declaredType", None) is not None:
        unit = getattr(var.declaredType, "unit", None)
    return unit or None


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
            if var is None:
                problems.append(f"{where}: {comp.source} has no variable {con.name!r}")
                continue
            if con.type is not None and var.type != con.type:
                problems.append(f"{where}: type {con.type} but the FMU's variable is {var.type}")
            if con.kind in ("input", "output") and var.causality != con.kind:
                problems.append(f"{where}: kind {con.kind} but the FMU's variable has causality {var.causality}")
            fu = _fmu_unit(var)
            if con.type == "Real" and (con.unit or None) != fu:
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
        if a.type != b.type:
            problems.append(f"{c}: type mismatch: {a.type} -> {b.type}")
        elif (a.unit or None) != (b.unit or None):
            problems.append(f"{c}: unit mismatch: {c.start_element}.{a.name} is in {a.unit!r}, "
                            f"{c.end_element}.{b.name} in {b.unit!r} (no unit conversion)")
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
            avail = ", ".join(Path(s).stem for s in system.parameter_sets) or "none"
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
            if p.type != var.type and not (p.type == "Real" and var.type == "Integer" and float(p.value).is_integer()):
                problems.append(f"{where}: type {p.type} but the FMU's variable is {var.type}")
            fu = _fmu_unit(var)
            if p.unit is not None and fu is not None and p.unit != fu:
                problems.append(f"{where}: unit mismatch: {p.unit!r} in the .ssv, {fu!r} in the FMU")
    for (source, name), applied in used.items():
        if not applied:
            problems.append(f"parameter {name} of {source}: no component bound to this set has a variable {name!r}")
    if problems:
        raise SSPError(_problem_text(system, problems))
    return selected


# =============================================================================================
# the master
# =============================================================================================

def _label(status):
    return ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"][min(int(status), 5)]


class _Instance:
    """One FMU of the system, instantiated with fmpy, with its log kept."""

    def __init__(self, comp: Component, workdir: Path, echo):
        from fmpy import extract
        from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, \
            fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE
        from fmpy import calloc, free

        self.comp = comp
        self.messages = []
        self.dead = False
        md = comp.model_description
        self.dir = extract(str(comp.model_description_path), unzipdir=str(workdir / comp.name))
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=self.dir, modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=comp.name)

        def logger(component, instance, status, category, message):
            text = message.decode(errors="replace") if message else ""
            self.messages.append((int(status), text))
            if status >= 1 and echo:
                print(f"[{_label(status)}] {comp.name}: {text}", file=sys.stderr, flush=True)

        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(logger)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._cb = cb  # keep the callbacks alive
        self.fmu.instantiate(loggingOn=True, callbacks=cb)

    def last_error(self):
        for status, text in reversed(self.messages):
            if status >= 2:
                return text
        return "no message from the FMU"

    def vr(self, name):
        return self.comp.variables[name].valueReference

    def set_value(self, name, value):
        var = self.comp.variables[name]
        if var.type == "Real":
            self.fmu.setReal([var.valueReference], [float(value)])
        elif var.type in ("Integer", "Enumeration"):
            self.fmu.setInteger([var.valueReference], [int(value)])
        elif var.type == "Boolean":
            self.fmu.setBoolean([var.valueReference], [bool(value)])
        else:
            self.fmu.setString([var.valueReference], [str(value)])

    def close(self):
        if self.dead:  # FMI 2.0: nothing may be called on an instance after fmi2Fatal
            return
        try:
            self.fmu.terminate()
        finally:
            self.fmu.freeInstance()


class Result:
    """Every connector at every communication point: ``res["PogoStick.y"]`` is a numpy array."""

    def __init__(self, names, types, n):
        import numpy as np

        self.names = ["time"] + list(names)
        self.types = dict(zip(names, types))
        self.data = {"time": np.empty(n)}
        for name, t in zip(names, types):
            self.data[name] = np.empty(n, dtype=np.float64 if t == "Real" else np.int64)
        self.n = n

    def __getitem__(self, name):
        return self.data[name]

    def write_csv(self, path: Path):
        import csv

        cols = [self.data[n] for n in self.names]
        with Path(path).open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(self.names)
            for row in zip(*cols):
                w.writerow([repr(float(v)) if isinstance(v, float) or hasattr(v, "dtype") and v.dtype.kind == "f"
                            else str(int(v)) for v in row])


def simulate(ssp, parameters: Optional[str] = None, stop_time: Optional[float] = None, step: float = 1e-3,
             start_time: Optional[float] = None, algorithm: str = "gauss-seidel", progress: bool = False,
             echo_log: bool = True) -> Result:
    """Run an SSP package; return a :class:`Result` (see the module docstring)."""
    import scipy.integrate  # noqa: F401  (README "Known issues": before any FMU is loaded)

    if algorithm not in ALGORITHMS:
        raise SSPError(f"algorithm {algorithm!r} is not one of {ALGORITHMS}")
    if not (math.isfinite(step) and step > 0):
        raise SSPError(f"communication step {step!r} must be a finite number > 0")
    work = Path(tempfile.mkdtemp(prefix="pogofmu_ssp_"))
    instances = {}
    try:
        root = unpack(Path(ssp), work / "package")
        system = read_ssd(root)
        selected = validate(system, parameters)
        t0 = system.start_time if start_time is None else float(start_time)
        t_end = stop_time if stop_time is not None else system.stop_time
        if t_end is None:
            raise SSPError("no stop time: give one (--stop-time) or set ssd:DefaultExperiment stopTime")
        n_steps = int(round((t_end - t0) / step))
        if n_steps < 1 or not math.isclose(t0 + n_steps * step, t_end, rel_tol=1e-9, abs_tol=1e-12):
            raise SSPError(f"stop time {t_end} - start time {t0} is not a whole number of steps {step}")
        order = system.order()
        for name in order:
            comp = system.components[name]
            comp.model_description_path = root / comp.source
        # incoming connections of every component, in connection order
        incoming = {name: [c for c in system.connections if c.end_element == name] for name in order}
        # record: every connector of every component
        record = [(name, con) for name in order for con in system.components[name].connectors.values()]
        res = Result([f"{n}.{c.name}" for n, c in record], [c.type for _, c in record], n_steps + 1)
        outputs = {name: [c for c in system.components[name].connectors.values() if c.kind != "input"]
                   for name in order}
        value = {}  # (component, connector) -> latest value of an output connector

        def read_outputs(inst):
            comp = inst.comp
            reals = [c.name for c in outputs[comp.name] if c.type == "Real"]
            ints = [c.name for c in outputs[comp.name] if c.type in ("Integer", "Enumeration")]
            if reals:
                for n, v in zip(reals, inst.fmu.getReal([inst.vr(n) for n in reals])):
                    value[(comp.name, n)] = v
            if ints:
                for n, v in zip(ints, inst.fmu.getInteger([inst.vr(n) for n in ints])):
                    value[(comp.name, n)] = v

        inputs_now = {}  # (component, connector) -> value set for the coming step

        def set_inputs(inst):
            reals, rv, ints, iv = [], [], [], []
            for c in incoming[inst.comp.name]:
                v = value[(c.start_element, c.start_connector)]
                inputs_now[(c.end_element, c.end_connector)] = v
                var = inst.comp.variables[c.end_connector]
                if var.type == "Real":
                    reals.append(var.valueReference)
                    rv.append(float(v))
                else:
                    ints.append(var.valueReference)
                    iv.append(int(v))
            if reals:
                inst.fmu.setReal(reals, rv)
            if ints:
                inst.fmu.setInteger(ints, iv)

        def store(k, t):
            res.data["time"][k] = t
            for name, con in record:
                key = (name, con.name)
                if con.kind == "input":
                    v = inputs_now.get(key)
                    if v is None:
                        v = instances[name].fmu.getReal([instances[name].vr(con.name)])[0] if con.type == "Real" \
                            else instances[name].fmu.getInteger([instances[name].vr(con.name)])[0]
                else:
                    v = value[key]
                res.data[f"{name}.{con.name}"][k] = v

        # ---- instantiate and initialize, in order ----
        for name in order:
            comp = system.components[name]
            inst = instances[name] = _Instance(comp, work, echo_log)
            # no stop time for the FMUs (stopTimeDefined = false): the engine clamps its steps at a
            # defined stop time, and an input change within ~1e-14 s of it ends in a 'step size
            # collapsed' fatal error (seen with PogoStick at t = 6 - 1e-14 s; report of issue 5)
            inst.fmu.setupExperiment(startTime=t0)
            inst.fmu.enterInitializationMode()
            ps = selected.get(name)
            try:
                for p in (ps.parameters if ps is not None else []):
                    if p.name in comp.variables:
                        inst.set_value(p.name, p.value)
                if all((c.start_element, c.start_connector) in value for c in incoming[name]):
                    set_inputs(inst)
                inst.fmu.exitInitializationMode()
            except Exception as exc:  # noqa: BLE001 - fmpy raises FMICallException on an error status
                inst.dead = "fatal" in str(exc).lower()
                raise SSPError(f"Component {name}: initialization failed with "
                               f"{ps.source if ps else 'no parameter set'}: {inst.last_error()}") from None
            read_outputs(inst)
        for name in order:  # inputs of earlier components fed by later ones
            set_inputs(instances[name])
        store(0, t0)

        # ---- fixed-step loop ----
        insts = [instances[n] for n in order]
        marks = {int(round(n_steps * q / 10)) for q in range(1, 11)} if progress else set()
        wall0 = _time.perf_counter()
        for k in range(n_steps):
            t = t0 + k * step
            if algorithm == "jacobi":
                for inst in insts:
                    set_inputs(inst)
            for inst in insts:
                if algorithm == "gauss-seidel":
                    set_inputs(inst)
                try:
                    inst.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=step)
                except Exception as exc:  # noqa: BLE001 - FMICallException: status discard/error/fatal
                    inst.dead = "fatal" in str(exc).lower()
                    raise SSPError(f"Component {inst.comp.name}: fmi2DoStep from t = {t:.10g} s "
                                   f"(step {step:g} s) failed ({exc}): {inst.last_error()}") from None
                if algorithm == "gauss-seidel":
                    read_outputs(inst)
            if algorithm == "jacobi":
                for inst in insts:
                    read_outputs(inst)
            for c in system.connections:  # the values the inputs will get for the next step
                inputs_now[(c.end_element, c.end_connector)] = value[(c.start_element, c.start_connector)]
            store(k + 1, t0 + (k + 1) * step)
            if k + 1 in marks:
                el = _time.perf_counter() - wall0
                frac = (k + 1) / n_steps
                print(f"{system.name}: {100 * frac:3.0f} %  t = {t0 + (k + 1) * step:.6g} s  "
                      f"({k + 1}/{n_steps} steps, {el:.1f} s elapsed, ~{el / frac - el:.1f} s left)", flush=True)
        res.system = system.name
        res.parameter_set = ", ".join(sorted({ps.name for ps in selected.values() if ps is not None})) or "none"
        res.algorithm, res.step = algorithm, step
        return res
    finally:
        for inst in instances.values():
            try:
                inst.close()
            except Exception:  # noqa: BLE001 - never mask the real error while cleaning up
                pass
        shutil.rmtree(work, ignore_errors=True)


def plot(res: Result, path: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = {}
    for name in res.names[1:]:
        if name.endswith(".n_events"):
            continue
        key = "integer" if res.types[name] != "Real" else name.split(".", 1)[1]
        groups.setdefault(key, []).append(name)
    # merge connectors that carry the same signal (e.g. PogoStick.y and HopController.y)
    panels = list(groups.values())
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 1.9 * len(panels) + 0.8), sharex=True, squeeze=False)
    t = res["time"]
    for ax, names in zip(axes[:, 0], panels):
        for name in names:
            if res.types[name] != "Real":
                ax.step(t, res[name], where="post", lw=0.8, label=name)
            else:
                ax.plot(t, res[name], lw=0.8, label=name)
        ax.legend(loc="upper right", fontsize=7)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run(ssp, parameters=None, stop_time=None, step=1e-3, out=None, algorithm="gauss-seidel", progress=True):
    """The ``run`` command: simulate, write ``<out>/<set>.csv`` and ``<out>/<set>.png``."""
    ssp = Path(ssp)
    res = simulate(ssp, parameters, stop_time, step, algorithm=algorithm, progress=progress)
    out = Path(out) if out is not None else Path("results") / ssp.stem
    out.mkdir(parents=True, exist_ok=True)
    tag = parameters or "default"
    csv_path, png_path = out / f"{tag}.csv", out / f"{tag}.png"
    res.write_csv(csv_path)
    plot(res, png_path, f"{res.system} ({res.parameter_set}): {algorithm}, step {step:g} s")
    print(f"{res.system}: simulated to t = {res['time'][-1]:.6g} s -> {csv_path}, {png_path}")
    return res, csv_path, png_path


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m pogofmu.ssp", description="SSP master built on fmpy")
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="simulate an .ssp with a fixed communication step")
    r.add_argument("ssp")
    r.add_argument("--parameters", help="parameter set: resources/NAME.ssv (default: the .ssd's bindings)")
    r.add_argument("--stop-time", type=float, help="default: the .ssd's DefaultExperiment stopTime")
    r.add_argument("--step", type=float, default=1e-3, help="communication step [s] (default 1e-3)")
    r.add_argument("--algorithm", choices=ALGORITHMS, default="gauss-seidel")
    r.add_argument("--out", help="output folder (default results/<SSP name>)")
    r.add_argument("--quiet", action="store_true", help="no progress lines")
    c = sub.add_parser("check", help="validate an .ssp (structure, FMUs, units, parameter sets) without running")
    c.add_argument("ssp")
    c.add_argument("--parameters")
    args = ap.parse_args(argv)
    try:
        if args.command == "check":
            with tempfile.TemporaryDirectory() as tmp:
                system = read_ssd(unpack(Path(args.ssp), Path(tmp)))
                validate(system, args.parameters)
                print(f"{args.ssp}: system {system.name!r} is valid: components {system.order()}, "
                      f"{len(system.connections)} connections, parameter sets "
                      f"{[Path(s).stem for s in system.parameter_sets]}")
            return 0
        run(args.ssp, args.parameters, args.stop_time, args.step, args.out, args.algorithm, not args.quiet)
    except SSPError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
