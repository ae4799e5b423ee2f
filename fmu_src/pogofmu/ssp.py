"""SSP master: run an SSP 1.0 package (.ssp) of FMI 2.0 co-simulation FMUs with fmpy.

    .venv/bin/python -m pogofmu.ssp run dist/SpaceHopper.ssp --parameters moon --stop-time 30 --step 1e-3 [--out DIR]
    .venv/bin/python -m pogofmu.ssp check dist/SpaceHopper.ssp

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
* checks every other input (``--stop-time``/``--step`` finite, the ``.ssv`` values against their
  types, the output folder writable) before the first step; never shows a traceback (an
  unexpected error is one line; ``--debug`` or ``POGOFMU_DEBUG=1`` for the traceback);
* streams every connector at every communication point to a CSV while it runs and plots them (PNG)
  from a min/max envelope, so its memory does not grow with the run; prints a progress line
  every 10 % of a long run.

Host-side code (fmpy, numpy, matplotlib); never imported inside an FMU.
"""
from __future__ import annotations

import argparse
import math
import os
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
        for attr in ("startTime", "stopTime"):
            try:
                value = parse_value("Real", de.get(attr)) if de.get(attr) is not None else None
            except ValueError as exc:
                problems.append(f"ssd:DefaultExperiment: {attr} {de.get(attr)!r} {exc}")
                continue
            if value is not None and not math.isfinite(value):
                problems.append(f"ssd:DefaultExperiment: {attr} = {value!r} must be a finite number")
            elif attr == "startTime" and value is not None:
                start = value
            elif value is not None:
                stop = value
    parameter_sets = {}
    for ssv in sorted((root / "resources").glob("*.ssv")) if (root / "resources").is_dir() else []:
        source = f"resources/{ssv.name}"
        parameter_sets[source] = read_ssv(ssv, source, problems)
    system = System(system_el.get("name") or top.get("name"), root, components, connections, parameter_sets,
                    start, stop)
    if problems:
        raise SSPError(_problem_text(system, problems))
    return system


INT32 = (-2 ** 31, 2 ** 31 - 1)  # the range of fmi2Integer


def parse_value(type_: str, raw: Optional[str]):
    """The value of an ``ssv:Real|Integer|Boolean|String`` element's ``value`` attribute.

    Raises ValueError with the rule the text breaks (the caller names the parameter and the file).
    Real follows xs:double (``1.62``, ``2e-3``, also ``NaN``/``INF``, which the FMU's own parameter
    rules then judge); Integer is xs:int (a whole number within fmi2Integer's 32 bits, so ``2.5``
    and ``3.0`` are refused); Boolean is ``true``/``false``/``1``/``0``.
    """
    if raw is None:
        raise ValueError("has no value attribute")
    if type_ == "String":
        return raw
    text = raw.strip()
    if not text:
        raise ValueError("is empty")
    if type_ == "Real":
        try:
            return float(text)
        except ValueError:
            raise ValueError("is not a number (xs:double, e.g. 1.62 or 2e-3)") from None
    if type_ == "Integer":
        try:
            value = int(text)
        except ValueError:
            raise ValueError("is not a whole number (xs:int, e.g. 8)") from None
        if not INT32[0] <= value <= INT32[1]:
            raise ValueError(f"is outside the 32-bit range [{INT32[0]}, {INT32[1]}] of fmi2Integer")
        return value
    if text in ("true", "1"):
        return True
    if text in ("false", "0"):
        return False
    raise ValueError("is not a boolean (true, false, 1 or 0)")


def read_ssv(path: Path, source: str, problems: list) -> ParameterSet:
    """Parse one .ssv; every value that breaks its type's rule is added to ``problems``."""
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
                try:
                    params.append(Parameter(pel.get("name"), t, parse_value(t, raw), v.get("unit")))
                except ValueError as exc:
                    problems.append(f"{source}: parameter {pel.get('name')!r}: {t} value {raw!r} {exc}")
                break
        else:
            problems.append(f"{source}: parameter {pel.get('name')!r} has no Real/Integer/Boolean/String value")
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

from pogofmu.runtime.status import status_name as _label  # noqa: E402


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


PLOT_BINS = 2000  # time slices of a figure's min/max envelope (more than the figure's pixel columns)


class Envelope:
    """Min/max envelope of every column of a run over ``bins`` equal slices of its rows.

    Drawn as a line through each slice's minimum and maximum in time order, a run of any length
    looks like the full one at the figure's resolution (every peak, every mode switch stays
    visible) from at most ``2 * bins`` points per signal; with no more rows than ``bins`` it keeps
    every row. Rows arrive in blocks of any size (:meth:`add`), so nothing else of the run is kept.
    """

    def __init__(self, n_rows: int, n_cols: int, bins: int = PLOT_BINS):
        import numpy as np

        self.n, self.bins, self.rows = n_rows, min(bins, n_rows), 0
        shape = (self.bins, n_cols)
        self.kmin, self.kmax = np.full(shape, -1, np.int64), np.full(shape, -1, np.int64)
        self.vmin, self.vmax = np.full(shape, np.inf), np.full(shape, -np.inf)
        self.tmin, self.tmax = np.zeros(shape), np.zeros(shape)

    def add(self, block):
        """Rows ``self.rows ...`` of the run: a 2-D array, column 0 the time."""
        import numpy as np

        block = np.asarray(block, dtype=np.float64)
        m = len(block)
        if m == 0:
            return
        slot = np.arange(self.rows, self.rows + m) * self.bins // self.n
        cuts = np.flatnonzero(np.diff(slot)) + 1
        cols = np.arange(block.shape[1])
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, m]):
            seg, j = block[a:b], slot[a]
            for pick, k_, v_, t_, better in ((np.argmin, self.kmin, self.vmin, self.tmin, np.less),
                                             (np.argmax, self.kmax, self.vmax, self.tmax, np.greater)):
                i = pick(seg, axis=0)
                v = seg[i, cols]
                new = better(v, v_[j])  # NaN never wins: a NaN sample leaves a gap
                k_[j, new] = self.rows + a + i[new]
                v_[j, new] = v[new]
                t_[j, new] = seg[i[new], 0]
        self.rows += m

    def series(self, col: int):
        """(time, value) of column ``col``: each slice's min and max in time order."""
        import numpy as np

        k = np.stack([self.kmin[:, col], self.kmax[:, col]], axis=1)
        t = np.stack([self.tmin[:, col], self.tmax[:, col]], axis=1)
        v = np.stack([self.vmin[:, col], self.vmax[:, col]], axis=1)
        order = np.argsort(k, axis=1, kind="stable")
        k, t, v = (np.take_along_axis(a, order, axis=1).ravel() for a in (k, t, v))
        keep = (k >= 0) & np.r_[True, k[1:] != k[:-1]]
        return t[keep], v[keep]


class Result:
    """Every connector at every communication point: ``res["PogoStick.y"]`` is a numpy array
    (what :func:`simulate` returns by default; the ``run`` command streams to a CSV instead)."""

    def __init__(self, names, types, units, n):
        import numpy as np

        self.names = ["time"] + list(names)
        self.types = dict(zip(names, types))
        self.units = dict(zip(names, units))
        self.data = {"time": np.empty(n)}
        for name, t in zip(names, types):
            self.data[name] = np.empty(n, dtype=np.float64 if t == "Real" else np.int64)
        self.n, self.rows = n, 0
        self._envelope = None

    def __getitem__(self, name):
        return self.data[name]

    def add(self, row):
        for name, v in zip(self.names, row):
            self.data[name][self.rows] = v
        self.rows += 1

    def close(self, complete=True):
        pass

    def envelope(self) -> Envelope:
        if self._envelope is None:
            import numpy as np

            self._envelope = Envelope(self.rows, len(self.names))
            self._envelope.add(np.column_stack([self.data[n][:self.rows] for n in self.names]))
        return self._envelope


class CSVStream:
    """Rows written to ``path`` while the run goes (in chunks), with the figure's :class:`Envelope`
    as the only thing kept in memory: the master's memory does not grow with the run's length.

    The file is written as ``<path>.part`` and renamed to ``path`` once the run is complete; a run
    that fails leaves its rows so far in ``<stem>.incomplete.csv`` (never a truncated ``path``).
    """

    CHUNK = 4096  # rows per write

    def __init__(self, path: Path, names, types, units, n_rows):
        import csv

        self.path = Path(path)
        self.part = self.path.with_name(self.path.name + ".part")
        self.incomplete = self.path.with_name(f"{self.path.stem}.incomplete.csv")
        self.names = ["time"] + list(names)
        self.types = dict(zip(names, types))
        self.units = dict(zip(names, units))
        self.n, self.rows, self.last_time = n_rows, 0, None
        self._env = Envelope(n_rows, len(self.names))
        self._buf = []
        self._file = self.part.open("w", newline="")
        self._csv = csv.writer(self._file)  # floats as repr (shortest round trip), integers as integers
        self._csv.writerow(self.names)

    def add(self, row):
        self._buf.append(row)
        if len(self._buf) >= self.CHUNK:
            self._flush()

    def _flush(self):
        if self._buf:
            self._csv.writerows(self._buf)
            self._env.add(self._buf)
            self.rows += len(self._buf)
            self.last_time = self._buf[-1][0]
            self._buf.clear()

    def close(self, complete=True):
        if self._file.closed:
            return
        try:
            self._flush()
        finally:
            self._file.close()
        self.part.replace(self.path if complete else self.incomplete)

    def envelope(self) -> Envelope:
        return self._env


def simulate(ssp, parameters: Optional[str] = None, stop_time: Optional[float] = None, step: float = 1e-3,
             start_time: Optional[float] = None, algorithm: str = "gauss-seidel", progress: bool = False,
             echo_log: bool = True, sink=None):
    """Run an SSP package; return a :class:`Result` (see the module docstring).

    ``sink(names, types, units, n_rows)``, if given, makes the recorder instead (an object with
    ``add(row)`` and ``close(complete)``, e.g. a :class:`CSVStream`): it is called once the package
    and every number are found valid, before any FMU is loaded, and what it returns is returned.
    """
    # no scipy import: the FMUs do not use scipy (the workaround of README "Known issues" is for
    # scipy-using FMUs) and it would cost the master 50 MB of its 150 MB budget (issue 9 item 10)
    if algorithm not in ALGORITHMS:
        raise SSPError(f"algorithm {algorithm!r} is not one of {ALGORITHMS}")
    for what, value in (("communication step (--step)", step), ("stop time (--stop-time)", stop_time),
                        ("start time", start_time)):
        if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise SSPError(f"{what} = {value!r} must be a finite number")
    if not step > 0:
        raise SSPError(f"communication step (--step) = {step!r} must be > 0")
    work = Path(tempfile.mkdtemp(prefix="pogofmu_ssp_"))
    instances = {}
    res = None
    try:
        root = unpack(Path(ssp), work / "package")
        system = read_ssd(root)
        selected = validate(system, parameters)
        t0 = system.start_time if start_time is None else float(start_time)
        t_end = stop_time if stop_time is not None else system.stop_time
        if t_end is None:
            raise SSPError("no stop time: give one (--stop-time) or set ssd:DefaultExperiment stopTime")
        if not t_end > t0:
            raise SSPError(f"stop time {t_end!r} s must be later than the start time {t0!r} s")
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
        columns = ([f"{n}.{c.name}" for n, c in record], [c.type for _, c in record],
                   [c.unit or _fmu_unit(system.components[n].variables[c.name]) for n, c in record], n_steps + 1)
        res = (sink or Result)(*columns)
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

        def store(t):
            row = [t]
            for name, con in record:
                key = (name, con.name)
                if con.kind == "input":
                    v = inputs_now.get(key)
                    if v is None:
                        v = instances[name].fmu.getReal([instances[name].vr(con.name)])[0] if con.type == "Real" \
                            else instances[name].fmu.getInteger([instances[name].vr(con.name)])[0]
                else:
                    v = value[key]
                row.append(v)
            res.add(row)

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
        store(t0)

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
            store(t0 + (k + 1) * step)
            if k + 1 in marks:
                el = _time.perf_counter() - wall0
                frac = (k + 1) / n_steps
                print(f"{system.name}: {100 * frac:3.0f} %  t = {t0 + (k + 1) * step:.6g} s  "
                      f"({k + 1}/{n_steps} steps, {el:.1f} s elapsed, ~{el / frac - el:.1f} s left)", flush=True)
        res.system = system.name
        res.parameter_set = ", ".join(sorted({ps.name for ps in selected.values() if ps is not None})) or "none"
        res.algorithm, res.step, res.connections = algorithm, step, list(system.connections)
        res.close(complete=True)
        res.last_time = t0 + n_steps * step
        return res
    finally:
        if res is not None:
            res.close(complete=False)  # a no-op once the run is complete
        for inst in instances.values():
            try:
                inst.close()
            except Exception:  # noqa: BLE001 - never mask the real error while cleaning up
                pass
        shutil.rmtree(work, ignore_errors=True)


def _panels(rec, connections):
    """The figure's panels, one signal each (integer signals last); a connected input is not
    drawn again (it is its source's copy, held over the step): ``copies`` names it instead."""
    fed = {f"{c.end_element}.{c.end_connector}": f"{c.start_element}.{c.start_connector}" for c in connections}
    copies = {}
    for dst, src in fed.items():
        copies.setdefault(src, []).append(dst)
    shown = [n for n in rec.names[1:] if n not in fed and not n.endswith(".n_events")]
    return sorted(shown, key=lambda n: rec.types[n] != "Real"), copies  # integer signals last


def figure(rec, title: str, connections=()):
    """The run's figure (a matplotlib Figure): every signal against time, y-labels with units,
    integer ticks for the integer signals, each connected signal drawn once (its inputs named in
    the label), drawn from the run's min/max envelope."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    env = rec.envelope()
    col = {n: i for i, n in enumerate(rec.names)}
    panels, copies = _panels(rec, connections)
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 1.7 * len(panels) + 0.9), sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], panels):
        t, v = env.series(col[name])
        label = " = ".join([name] + copies.get(name, []))
        if rec.types[name] != "Real":
            ax.step(t, v, where="post", lw=0.8, label=label)
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        else:
            ax.plot(t, v, lw=0.8, label=label)
        ax.set_ylabel(f"{name.split('.', 1)[1]} [{rec.units.get(name) or '-'}]")
        ax.legend(loc="upper right", fontsize=7, handlelength=1)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(title, fontsize=10)
    fig.align_ylabels(axes[:, 0])
    fig.tight_layout()
    return fig


def plot(rec, path: Path, title: str, connections=()):
    """:func:`figure` written to ``path`` (PNG)."""
    import matplotlib.pyplot as plt

    fig = figure(rec, title, connections)
    try:
        fig.savefig(path, dpi=110)
    finally:
        plt.close(fig)
    return path


def prepare_out(out: Path, *files: Path):
    """The output folder, created, and proven writable before the first step (never after the run)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise SSPError(f"output folder {str(out)!r} (--out) is an existing file, not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise SSPError(f"output folder {str(out)!r} (--out) cannot be written: {exc.strerror or exc}") from None
    for f in files:
        if f.is_dir():
            raise SSPError(f"output file {str(f)!r} is a folder: remove it or choose another --out")


def run(ssp, parameters=None, stop_time=None, step=1e-3, out=None, algorithm="gauss-seidel", progress=True):
    """The ``run`` command: simulate, streaming ``<out>/<set>.csv``, then draw ``<out>/<set>.png``.

    The package, the numbers and the output folder are all checked before the first step."""
    ssp = Path(ssp)
    out = Path(out) if out is not None else Path("results") / ssp.stem
    tag = parameters or "default"
    csv_path, png_path = out / f"{tag}.csv", out / f"{tag}.png"
    opened = []

    def open_csv(names, types, units, n_rows):  # called once the package and the numbers are valid
        prepare_out(out, csv_path, png_path)
        try:
            opened.append(CSVStream(csv_path, names, types, units, n_rows))
        except OSError as exc:
            raise SSPError(f"cannot write {csv_path}: {exc.strerror or exc}") from None
        return opened[0]

    try:
        rec = simulate(ssp, parameters, stop_time, step, algorithm=algorithm, progress=progress, sink=open_csv)
    except SSPError as exc:
        if opened and opened[0].rows:
            s = opened[0]
            raise SSPError(f"{exc}\n  the {s.rows} rows up to t = {s.last_time:.10g} s are in {s.incomplete}") from None
        raise
    try:
        plot(rec, png_path, f"{rec.system} ({rec.parameter_set}): {algorithm}, step {step:g} s", rec.connections)
    except OSError as exc:
        raise SSPError(f"cannot write {png_path}: {exc.strerror or exc} (the results are in {csv_path})") from None
    print(f"{rec.system}: simulated to t = {rec.last_time:.6g} s -> {csv_path}, {png_path}")
    return rec, csv_path, png_path


def main(argv=None, prog="python -m pogofmu.ssp"):
    """The command line (``run`` / ``check``); returns the exit status. ``prog`` names the command
    in the usage text (a console command forwarding here may pass its own)."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--debug", action="store_true",
                        help="show the Python traceback of an unexpected error (also: POGOFMU_DEBUG=1)")
    ap = argparse.ArgumentParser(prog=prog, description="SSP master built on fmpy")
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", parents=[common], help="simulate an .ssp with a fixed communication step")
    r.add_argument("ssp")
    r.add_argument("--parameters", help="parameter set: resources/NAME.ssv (default: the .ssd's bindings)")
    r.add_argument("--stop-time", type=float, help="default: the .ssd's DefaultExperiment stopTime")
    r.add_argument("--step", type=float, default=1e-3, help="communication step [s] (default 1e-3)")
    r.add_argument("--algorithm", choices=ALGORITHMS, default="gauss-seidel")
    r.add_argument("--out", help="output folder (default results/<SSP name>)")
    r.add_argument("--quiet", action="store_true", help="no progress lines")
    c = sub.add_parser("check", parents=[common],
                       help="validate an .ssp (structure, FMUs, units, parameter sets) without running")
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
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the last resort: one line, never a traceback by default
        if args.debug or os.environ.get("POGOFMU_DEBUG", "") not in ("", "0"):
            raise
        print(f"error: unexpected {type(exc).__name__}: {exc} -- this is a bug of pogofmu, please report it "
              f"(run again with --debug or POGOFMU_DEBUG=1 for the traceback)", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
