#!/usr/bin/env python3
"""Build every FMU of the project into dist/, complete and validate its modelDescription.xml.

For each slave file ``fmu_src/slave_*.py`` (one FMU each):

1. pythonfmu 0.7 builds the FMU, bundling the ``pogofmu`` package as project files;
2. the modelDescription.xml is completed with what pythonfmu cannot write: a unit for every
   Real variable (and the ``<UnitDefinitions>``), and ``ModelStructure/InitialUnknowns`` for the
   outputs (they are ``calculated`` from the parameters during initialization);
3. ``fmpy.validation.validate_fmu`` must report no problem, otherwise the build fails.

Then every ``ssp/<System>/SystemStructure.ssd`` is packed with its ``.ssv`` files and the FMUs
it references into ``dist/<System>.ssp``.

Usage: ``python build_fmu.py [--dest dist] [NAME ...]`` (names of FMUs, default: all).
"""
from __future__ import annotations

import argparse
import importlib
import inspect
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

ROOT = Path(__file__).resolve().parent
SRC = ROOT / "fmu_src"
PACKAGE = SRC / "pogofmu"
SSP_DIR = ROOT / "ssp"


def slave_files():
    return sorted(SRC.glob("slave_*.py"))


def slave_class(script: Path):
    """The HybridSlave subclass a slave file defines (imported under its own unique module name)."""
    if str(SRC) not in sys.path:
        sys.path.insert(0, str(SRC))
    module = importlib.import_module(script.stem)
    from pogofmu.fmi import HybridSlave

    classes = [c for _, c in inspect.getmembers(module, inspect.isclass)
               if issubclass(c, HybridSlave) and c is not HybridSlave]
    if len(classes) != 1:
        raise SystemExit(f"{script}: expected exactly one HybridSlave subclass, found {classes}")
    return classes[0]


def complete_model_description(xml: bytes, cls) -> bytes:
    """Add units, unit definitions and InitialUnknowns to pythonfmu's modelDescription.xml."""
    from pogofmu.units import UNITS

    model = cls.model
    units = {v.name: v.unit for v in model.all_outputs() + model.inputs}
    units.update({p.name: p.unit for p in model.parameters})
    root = ET.fromstring(xml)
    used = set()
    variables = root.find("ModelVariables")
    outputs = []
    for index, sv in enumerate(variables.findall("ScalarVariable"), start=1):
        name = sv.get("name")
        if name not in units:
            raise SystemExit(f"{model.name}: variable {name} has no unit in the model")
        if sv.get("causality") == "output":
            outputs.append(index)
        real = sv.find("Real")
        unit = units[name]
        if real is not None and unit:
            if unit not in UNITS:
                raise SystemExit(f"{model.name}: unit {unit!r} of {name} is not in pogofmu.units.UNITS")
            real.set("unit", unit)
            used.add(unit)
        if not sv.get("description"):
            raise SystemExit(f"{model.name}: variable {name} has no description")
    if used:
        defs = ET.Element("UnitDefinitions")
        for unit in sorted(used):
            u = ET.SubElement(defs, "Unit", name=unit)
            if UNITS[unit] is not None:
                ET.SubElement(u, "BaseUnit", {k: str(v) for k, v in UNITS[unit].items()})
        # UnitDefinitions come right after CoSimulation (and before LogCategories) in the schema
        position = list(root).index(root.find("CoSimulation")) + 1
        root.insert(position, defs)
    structure = root.find("ModelStructure")
    if outputs:
        initial = ET.SubElement(structure, "InitialUnknowns")
        for index in outputs:
            ET.SubElement(initial, "Unknown", index=str(index))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def rewrite_member(fmu: Path, member: str, transform):
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / fmu.name
        with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zout:
            for item in zin.infolist():
                data = zin.read(item.filename)
                if item.filename == member:
                    data = transform(data)
                zout.writestr(item, data)
        shutil.move(str(out), fmu)


def build_one(script: Path, dest: Path) -> Path:
    from pythonfmu import FmuBuilder
    from fmpy.validation import validate_fmu

    cls = slave_class(script)
    fmu = FmuBuilder.build_FMU(script, dest=dest, project_files=[PACKAGE], canGetAndSetFMUstate=True)
    fmu = Path(fmu)
    rewrite_member(fmu, "modelDescription.xml", lambda xml: complete_model_description(xml, cls))
    problems = validate_fmu(str(fmu))
    if problems:
        raise SystemExit(f"{fmu.name}: fmpy validation failed:\n  " + "\n  ".join(problems))
    print(f"built and validated {fmu.relative_to(ROOT) if fmu.is_relative_to(ROOT) else fmu}")
    return fmu


def pack_ssp(system_dir: Path, dest: Path) -> Path:
    """Pack ``ssp/<System>/`` (SystemStructure.ssd, *.ssv) and the FMUs it references into an .ssp."""
    ssd = system_dir / "SystemStructure.ssd"
    text = ssd.read_text()
    out = dest / f"{system_dir.name}.ssp"
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(ssd, "SystemStructure.ssd")
        for ssv in sorted(system_dir.glob("*.ssv")):
            z.write(ssv, f"resources/{ssv.name}")
        import re

        for source in sorted(set(re.findall(r'source="(resources/[^"]+\.fmu)"', text))):
            fmu = dest / Path(source).name
            if not fmu.exists():  # an .ssp without its FMUs would only fail when run
                raise SystemExit(f"{ssd}: component source {source} is not built in {dest}")
            z.write(fmu, source)
    print(f"packed {out.relative_to(ROOT) if out.is_relative_to(ROOT) else out}")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dest", default=str(ROOT / "dist"), help="output folder (default: dist/)")
    ap.add_argument("names", nargs="*", help="FMU names to build (default: all)")
    args = ap.parse_args(argv)
    dest = Path(args.dest).resolve()
    dest.mkdir(parents=True, exist_ok=True)
    built = []
    for script in slave_files():
        name = slave_class(script).__name__
        if args.names and name not in args.names:
            continue
        built.append(build_one(script, dest))
    if not args.names:
        for ssd in sorted(SSP_DIR.glob("*/SystemStructure.ssd")):
            pack_ssp(ssd.parent, dest)
    return built


if __name__ == "__main__":
    main()
