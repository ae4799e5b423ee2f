"""Reading an SSP package: unpacking the .ssp, parsing SystemStructure.ssd and its .ssv parameter
sets into plain data (:class:`System` and its parts). Nothing here loads an FMU."""
from __future__ import annotations

import math
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
# connector and parameter types: SSP 1.0's, and SSP 2.0's FMI 3.0 names (Float64, Int32, ...)
TYPES = ("Real", "Float64", "Float32", "Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64",
         "UInt64", "Boolean", "String", "Enumeration", "Binary")
REAL = ("Real", "Float64", "Float32")
WHOLE = ("Integer", "Int32", "Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64", "UInt64", "Enumeration")
WHOLE_RANGE = {"Int8": (-2 ** 7, 2 ** 7 - 1), "UInt8": (0, 2 ** 8 - 1), "Int16": (-2 ** 15, 2 ** 15 - 1),
               "UInt16": (0, 2 ** 16 - 1), "UInt32": (0, 2 ** 32 - 1), "Int64": (-2 ** 63, 2 ** 63 - 1),
               "UInt64": (0, 2 ** 64 - 1)}


def same_type(a: Optional[str], b: Optional[str]) -> bool:
    """Two type names for the same kind of value (SSP 1.0 ``Real`` is FMI 3.0's ``Float64``, and
    ``Integer`` its ``Int32``)."""
    alias = {"Real": "Float64", "Integer": "Int32"}
    return alias.get(a, a) == alias.get(b, b)


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
    # an element of an array connector (SSP 2.0 ssc:Dimension): (array name, 1-based index, size);
    # the system holds the elements z[1] ... z[N] of an array connector z, never z itself
    element: tuple = ()


@dataclass
class Component:
    name: str
    source: str
    connectors: Dict[str, Connector]
    bindings: List[str]  # sources of the component's ParameterBindings, in order
    variables: dict = field(default_factory=dict)  # name -> fmpy ScalarVariable (filled on validation)
    model_description: object = None
    # FMI 3.0 array elements (filled on validation): element connector name -> (array, 1-based index, size)
    elements: dict = field(default_factory=dict)


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

    def update_order(self) -> List[str]:
        """The order the master updates the components in (Gauss–Seidel, initialization, event
        iteration): each after the components that feed its direct feed-through inputs (the FMUs'
        declared dependencies, once validated), else that of :meth:`order`."""
        from .graph import update_order

        return update_order(self, self.order())

    def order(self) -> List[str]:
        """Gauss-Seidel order: first appearance in the connections (start, then end element),
        then the components no connection mentions, in ssd:Elements order."""
        seen = []
        for c in self.connections:
            for name in (c.start_element, c.end_element):
                if name in self.components and name not in seen:
                    seen.append(name)
        return seen + [n for n in self.components if n not in seen]


def element_name(name: str, index: int) -> str:
    """Element ``index`` (1-based) of the array connector ``name``: ``name[index]`` (the FMI
    structured naming of an array's element, the name of the FMI 2.0 scalar)."""
    return f"{name}[{index}]"


def _array_size(cel, where, problems) -> Optional[int]:
    """The size of a 1-D array connector (one ``ssc:Dimension size="N"``), None for a scalar."""
    dims = cel.findall("ssc:Dimension", NS)
    if not dims:
        return None
    if len(dims) > 1:
        problems.append(f"{where}: {len(dims)} ssc:Dimension elements: only 1-D array connectors are supported")
        return None
    raw = dims[0].get("size")
    if raw is None or not raw.strip().isdigit() or int(raw) < 1:
        problems.append(f"{where}: ssc:Dimension size={raw!r} violates the rule: a whole number >= 1 (a "
                        f"sizeConnector is not supported)")
        return None
    return int(raw)


def _element_connections(index, cel, arrays, problems) -> list:
    """The connections of one ssd:Connection between scalars and array elements: an array connector
    with ``startIndices``/``endIndices`` (one 1-based index, 1-D) is that element; an array without
    indices is all its elements, connected one to one to an array of the same size."""
    ends = []
    for role in ("start", "end"):
        el, cn, raw = cel.get(f"{role}Element"), cel.get(f"{role}Connector"), cel.get(f"{role}Indices")
        where = f"Connection {index} ({cel.get('startElement')}.{cel.get('startConnector')} -> " \
                f"{cel.get('endElement')}.{cel.get('endConnector')})"
        size = arrays.get((el, cn))
        if raw is None:
            ends.append([cn] if size is None else [element_name(cn, i) for i in range(1, size + 1)])
            continue
        items = raw.split()
        if size is None:
            problems.append(f"{where}: {role}Indices={raw!r} on {el}.{cn}, which is not an array connector (no "
                            f"ssc:Dimension)")
            return []
        if len(items) != 1 or not items[0].isdigit() or not 1 <= int(items[0]) <= size:
            problems.append(f"{where}: {role}Indices={raw!r} violates the rule: one index from 1 to {size} ({el}.{cn} "
                            f"is a 1-D array of {size})")
            return []
        ends.append([element_name(cn, int(items[0]))])
    if len(ends[0]) != len(ends[1]):
        problems.append(f"Connection {index} ({cel.get('startElement')}.{cel.get('startConnector')} -> "
                        f"{cel.get('endElement')}.{cel.get('endConnector')}): {len(ends[0])} value(s) into "
                        f"{len(ends[1])}: connect arrays of the same size, or one element (startIndices/endIndices) "
                        f"with a scalar")
        return []
    return [Connection(index, cel.get("startElement"), a, cel.get("endElement"), b) for a, b in zip(*ends)]


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
    arrays = {}  # (component, array connector) -> size
    for el in (list(elements) if elements is not None else []):
        if el.tag != _tag("ssd", "Component"):
            problems.append(f"ssd:Elements: element {el.tag.split('}')[-1]} {el.get('name')!r} is not supported "
                            f"(only ssd:Component; no nested systems)")
            continue
        name = el.get("name")
        connectors = {}
        for cel in el.findall("ssd:Connectors/ssd:Connector", NS):
            t, unit = _connector_type(cel)
            size = _array_size(cel, f"Connector {name}.{cel.get('name')}", problems)
            if size is None:
                connectors[cel.get("name")] = Connector(cel.get("name"), cel.get("kind"), t, unit)
            else:
                arrays[(name, cel.get("name"))] = size
                for i in range(1, size + 1):
                    connectors[element_name(cel.get("name"), i)] = Connector(
                        element_name(cel.get("name"), i), cel.get("kind"), t, unit, (cel.get("name"), i, size))
        bindings = []
        for bel in el.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
            children = {child.tag.split("}")[-1] for child in bel}
            if "ParameterValues" in children or bel.get("source") is None:
                problems.append(f"Component {name}: a ParameterBinding with inline values (ssd:ParameterValues"
                                f"{'' if bel.get('source') else ', no source'}): not supported, give the "
                                f"values in an .ssv file named by source")
            elif "ParameterMapping" in children:
                problems.append(f"Component {name}: ParameterBinding {bel.get('source')}: an ssd:ParameterMapping "
                                f"(.ssm) is not supported: name the FMU's variables in the .ssv itself")
            else:
                bindings.append(bel.get("source"))
        if name in components:
            problems.append(f"Component {name}: the name is used twice in ssd:Elements")
        components[name] = Component(name, el.get("source"), connectors, bindings)
    connections = []
    for i, cel in enumerate(system_el.findall("ssd:Connections/ssd:Connection", NS), start=1):
        missing = [a for a in ("startConnector", "endConnector") if not cel.get(a)]
        if missing:  # (a missing startElement/endElement is a connector of the system: refused later)
            problems.append(f"Connection {i}: no {' and no '.join(missing)} attribute (every connection joins two "
                            f"named connectors)")
            continue
        transforms = [child.tag.split("}")[-1] for child in cel if child.tag.endswith("Transformation")]
        if transforms:
            problems.append(f"Connection {i} ({cel.get('startElement')}.{cel.get('startConnector')} -> "
                            f"{cel.get('endElement')}.{cel.get('endConnector')}): ssc:{transforms[0]} is not "
                            f"supported (the master passes values unchanged; scale them in a component)")
            continue
        connections += _element_connections(i, cel, arrays, problems)
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
    if type_ in REAL:
        try:
            return float(text)
        except ValueError:
            raise ValueError("is not a number (xs:double, e.g. 1.62 or 2e-3)") from None
    if type_ in WHOLE:
        try:
            value = int(text)
        except ValueError:
            raise ValueError("is not a whole number (xs:int, e.g. 8)") from None
        lo, hi = WHOLE_RANGE.get(type_, INT32)
        if not lo <= value <= hi:
            where = "fmi2Integer" if type_ == "Integer" else type_
            bits = {"Integer": 32, "Int32": 32}.get(type_, None)
            span = f"the {bits}-bit range" if bits else "the range"
            raise ValueError(f"is outside {span} [{lo}, {hi}] of {where}")
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
        for t in ("Real", "Float64", "Float32", "Integer", "Int32", "Int8", "UInt8", "Int16", "UInt16", "UInt32",
                  "Int64", "UInt64", "Boolean", "String"):
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

