#!/usr/bin/env python3
"""Build every FMU of the project into dist/, validate it, and pack the SSP systems.

For each slave file ``fmu_src/slave_*.py`` (one FMU each):

1. the FMU's Python code is staged under names private to this build of this model: the runtime
   modules of the ``pogofmu`` package become ``resources/_pogofmu_<Model>_<hash>/`` and the slave
   file ``resources/_pogofmu_<Model>_<hash>_slave.py`` (its ``pogofmu`` imports renamed), so that
   several FMUs — other models, other versions of the project — run side by side in one process;
   the build checks that this code imports in an isolated interpreter (standard library only);
2. ``binaries/linux64/<Model>.so`` is the project's native launcher (``fmu_src/native``), compiled
   here with the system C compiler: it brings a CPython interpreter into any FMI importer and
   calls the staged code; pythonfmu's own binaries are kept for the other platforms (Windows),
   which call the same code through pythonfmu's convention.  Without a C compiler the build warns
   and uses pythonfmu's Linux binary instead: such an FMU runs only inside a Python process;
3. ``modelDescription.xml`` is written from the adapter's variable table (units and unit
   definitions, descriptions, start values, InitialUnknowns) and ``fmpy.validation.validate_fmu``
   must report no problem, otherwise the build fails.

Each slave file gives two FMUs: FMI 2.0 co-simulation in ``dist/<Model>.fmu`` and FMI 3.0 (model
exchange and co-simulation with event mode, ``pogofmu.fmi3``) in ``dist/fmi3/<Model>.fmu``, whose
only binary is the launcher built with ``-DPOGOFMU_FMI=3`` (no FMI 3.0 Windows binary: pythonfmu's
speak FMI 2.0).

The zip is deterministic: with SOURCE_DATE_EPOCH set, the same sources give the same FMU bytes.

Then every ``ssp/<System>/SystemStructure.ssd`` is packed with its ``.ssv`` files and the FMUs
it references into ``dist/<System>.ssp``.

Usage: ``python build_fmu.py [--dest dist] [NAME ...]`` (names of FMUs, default: all).
"""
from __future__ import annotations

import argparse
import datetime
import hashlib
import importlib
import inspect
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import uuid
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

ROOT = Path(__file__).resolve().parent
SRC = ROOT / "fmu_src"
PACKAGE = SRC / "pogofmu"
NATIVE = SRC / "native"
SSP_DIR = ROOT / "ssp"
CACHE = ROOT / "build" / "native"

# the modules an FMU runs (host-side tools such as master.py or ssp.py stay out of the FMU)
RUNTIME_MODULES = ("__init__.py", "model.py", "engine.py", "_tableaux.py", "elements.py", "soil.py", "fmi.py",
                   "fmi3.py", "models")
ZIP_DATE = (1980, 1, 1, 0, 0, 0)


class BuildError(SystemExit):
    pass


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
        raise BuildError(f"{script}: expected exactly one HybridSlave subclass, found {classes}")
    return classes[0]


def project_version():
    from pogofmu import __version__

    return __version__


# ---------------------------------------------------------------------------------------------
# native launcher
# ---------------------------------------------------------------------------------------------

def fmi_headers() -> Path:
    import fmpy

    return Path(fmpy.__file__).parent / "c-code"


def compile_launcher(fmi_version: int = 2, cache: Path = CACHE):
    """Compile fmu_src/native/pogofmu_fmi.c for FMI 2 or 3; cached by the hash of source, headers
    and flags.  Returns the library's path, or None (with a warning) without a C compiler."""
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    source = NATIVE / "pogofmu_fmi.c"
    flags = ["-std=c11", "-O2", "-fPIC", "-shared", "-fvisibility=hidden", "-Wall", "-Wextra",
             "-Wno-unused-parameter", f"-DPOGOFMU_FMI={fmi_version}", f"-I{fmi_headers()}"]
    libs = ["-ldl", "-lpthread"]
    if cc is None:
        print("WARNING: no C compiler found (set CC): the FMUs get pythonfmu's Linux binary instead of the "
              "project's launcher and run only inside a Python process (fmpy, libcosimpy), not in a C "
              "importer", file=sys.stderr)
        return None
    digest = hashlib.sha256(source.read_bytes() + " ".join(flags + libs).encode())
    for header in sorted(fmi_headers().glob(f"fmi{fmi_version}*.h")):
        digest.update(header.read_bytes())
    cache.mkdir(parents=True, exist_ok=True)
    out = cache / f"pogofmu_fmi{fmi_version}_{digest.hexdigest()[:16]}.so"
    if not out.exists():
        tmp = out.with_suffix(f".{os.getpid()}.tmp")
        proc = subprocess.run([cc, *flags, str(source), "-o", str(tmp), *libs], capture_output=True, text=True)
        if proc.returncode:
            raise BuildError(f"compiling the native launcher failed ({cc}):\n{proc.stderr}")
        os.replace(tmp, out)
    return out


def pythonfmu_binaries():
    """pythonfmu's binaries per platform folder (used for the platforms the launcher does not serve)."""
    import pythonfmu

    base = Path(pythonfmu.__file__).parent / "resources" / "binaries"
    return {p.parent.name: p for ext in ("dll", "so", "dylib") for p in sorted(base.glob(f"*/*.{ext}"))}


def python_libraries():
    """libpython of the interpreter running the build: the launcher tries it first in a C host."""
    libdir, soname = sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME")
    if libdir and soname and sysconfig.get_config_var("Py_ENABLE_SHARED"):
        lib = Path(libdir) / soname
        if lib.exists():
            return [str(lib)]
    return []


# ---------------------------------------------------------------------------------------------
# staging the FMU's Python code under private names
# ---------------------------------------------------------------------------------------------

def runtime_files():
    """(relative path, bytes) of the package modules an FMU carries, in a stable order."""
    files = []
    for entry in RUNTIME_MODULES:
        path = PACKAGE / entry
        paths = sorted(path.rglob("*.py")) if path.is_dir() else [path]
        files += [(p.relative_to(PACKAGE).as_posix(), p.read_bytes()) for p in paths]
    return files


_IMPORT = re.compile(r"^(\s*)(from|import)\s+pogofmu(?=[\s.])", re.MULTILINE)


def rename_imports(source: str, package: str) -> str:
    """The slave file's ``pogofmu`` imports, renamed to the private package."""
    return _IMPORT.sub(lambda m: f"{m.group(1)}{m.group(2)} {package}", source)


def stage(script: Path, cls, stage_dir: Path, fmi_version: int, token_seed: str = ""):
    """Write resources/ for one FMU into ``stage_dir``; return (package, module, token)."""
    files = runtime_files()
    digest = hashlib.sha256(script.read_bytes())
    for rel, data in files:
        digest.update(rel.encode() + b"\0" + data)
    digest.update(f"{cls.__name__}:{project_version()}:{token_seed}".encode())
    tag = digest.hexdigest()[:12]
    package = f"_pogofmu_{cls.__name__}_{tag}"
    module = f"{package}_slave"
    token = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"pogofmu/{cls.__name__}/{tag}/fmi{fmi_version}")) + "}"
    res = stage_dir / "resources"
    for rel, data in files:
        target = res / package / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    source = rename_imports(script.read_text(), package)
    if re.search(r"^\s*(from|import)\s+pogofmu\b", source, re.MULTILINE):
        raise BuildError(f"{script}: an import of pogofmu was not renamed")
    (res / f"{module}.py").write_text(source)
    shutil.copy2(NATIVE / "pogofmu_boot.py", res / "pogofmu_boot.py")
    (res / "slavemodule.txt").write_text(module)  # pythonfmu's binaries read it
    lines = ["# read by the native launcher and resources/pogofmu_boot.py (written by build_fmu.py)",
             f"package={package}", f"module={module}", f"class={cls.__name__}", f"token={token}",
             f"fmi={fmi_version}"] + [f"python={lib}" for lib in python_libraries()]
    (res / "pogofmu_launch.txt").write_text("\n".join(lines) + "\n")
    return package, module, token


def check_isolated_import(stage_dir: Path, cls_name: str):
    """The staged code must import in an isolated interpreter (no site-packages, no pogofmu on
    the path): exactly what the launcher does in a C importer."""
    res = stage_dir / "resources"
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import pogofmu_boot; "
            f"cls = pogofmu_boot.load(sys.argv[1]); assert cls.__name__ == {cls_name!r}; "
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('pogofmu', 'pythonfmu', 'numpy', 'scipy')); "
            "assert not bad, bad")
    proc = subprocess.run([sys.executable, "-I", "-S", "-c", code, str(res)], capture_output=True, text=True,
                          cwd=tempfile.gettempdir())
    if proc.returncode:
        raise BuildError(f"{cls_name}: the FMU's Python code does not import with the standard library "
                         f"alone:\n{proc.stderr[-3000:]}")


# ---------------------------------------------------------------------------------------------
# modelDescription.xml
# ---------------------------------------------------------------------------------------------

def _number(value, integer):
    return str(int(value)) if integer else repr(float(value))


def unit_definitions(used):
    from pogofmu.units import UNITS

    defs = ET.Element("UnitDefinitions")
    for unit in sorted(used):
        if unit not in UNITS:
            raise BuildError(f"unit {unit!r} is not in pogofmu.units.UNITS")
        u = ET.SubElement(defs, "Unit", name=unit)
        if UNITS[unit] is not None:
            ET.SubElement(u, "BaseUnit", {k: str(v) for k, v in UNITS[unit].items()})
    return defs


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
    ET.SubElement(root, "DefaultExperiment", startTime="0.0", stopTime=repr(float(model.default_stop_time)),
                  stepSize=repr(float(model.default_step)))
    return ET.SubElement(root, "ModelVariables")


def _variable_attributes(model, v):
    if not v.description:
        raise BuildError(f"{model.name}: variable {v.name} has no description")
    attrs = {"name": v.name, "valueReference": str(v.vr), "description": v.description,
             "causality": v.causality, "variability": v.variability}
    if v.causality == "parameter":
        attrs["initial"] = "exact"
    return attrs


def model_description_fmi2(cls, token: str) -> bytes:
    model = cls.model
    variables = cls.variables()
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": model.name, "guid": token, "description": model.description,
        "author": cls.author, "license": cls.license, "version": project_version(),
        "generationTool": f"pogofmu {project_version()} (build_fmu.py)",
        "generationDateAndTime": _build_date(), "variableNamingConvention": "flat",
        "numberOfEventIndicators": "0"})
    ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": model.name, "needsExecutionTool": "false",
        "canHandleVariableCommunicationStepSize": "true", "canInterpolateInputs": "false",
        "maxOutputDerivativeOrder": "0", "canRunAsynchronuously": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "true",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
        "providesDirectionalDerivative": "false"})
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
    ms = ET.SubElement(root, "ModelStructure")
    outputs = [i for i, v in enumerate(variables, start=1) if v.causality == "output"]
    if outputs:
        out_el = ET.SubElement(ms, "Outputs")
        init_el = ET.SubElement(ms, "InitialUnknowns")
        for index in outputs:
            ET.SubElement(out_el, "Unknown", index=str(index))
            ET.SubElement(init_el, "Unknown", index=str(index))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def model_description_fmi3(cls, token: str) -> bytes:
    """FMI 3.0: model exchange and co-simulation in one description (pogofmu.fmi3 for the extra
    variables: state locals, derivatives, event indicators, and the independent variable time)."""
    from pogofmu.fmi3 import check_state_outputs, fmi3_class, indicator_name

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
        "version": project_version(), "generationTool": f"pogofmu {project_version()} (build_fmu.py)",
        "generationDateAndTime": _build_date(), "variableNamingConvention": "flat"})
    common = {"modelIdentifier": model.name, "canGetAndSetFMUState": "true", "canSerializeFMUState": "true",
              "providesDirectionalDerivatives": "false", "providesAdjointDerivatives": "false",
              "canBeInstantiatedOnlyOncePerProcess": "false"}
    ET.SubElement(root, "ModelExchange", dict(common, needsCompletedIntegratorStep="true"))
    ET.SubElement(root, "CoSimulation", dict(common, canHandleVariableCommunicationStepSize="true",
                                             hasEventMode="true", canReturnEarlyAfterIntermediateUpdate="false",
                                             providesIntermediateUpdate="false", maxOutputDerivativeOrder="0"))
    mv = _description_body(root, cls, variables)
    for v in variables:
        attrs = _variable_attributes(model, v)
        if v.type == "Real" and v.unit:
            attrs["unit"] = v.unit
        if v.start is not None:
            attrs["start"] = _number(v.start, v.type == "Integer")
        if v.name.startswith("der(") and v.name[4:-1] in by_name:
            attrs["derivative"] = str(by_name[v.name[4:-1]].vr)
        ET.SubElement(mv, "Float64" if v.type == "Real" else "Int32", attrs)
    ms = ET.SubElement(root, "ModelStructure")
    states = [by_name[s.name] for s in model.states]
    derivatives = [by_name[f"der({s.name})"] for s in model.states]
    for v in variables:
        if v.causality == "output":
            ET.SubElement(ms, "Output", valueReference=str(v.vr))
    for v in derivatives:
        ET.SubElement(ms, "ContinuousStateDerivative", valueReference=str(v.vr))
    initial = {v.vr for v in variables if v.causality == "output"} | {v.vr for v in states + derivatives}
    for vr in sorted(initial):
        ET.SubElement(ms, "InitialUnknown", valueReference=str(vr))
    for ev in model.events:
        ET.SubElement(ms, "EventIndicator", valueReference=str(by_name[indicator_name(ev)].vr))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _build_date():
    """SOURCE_DATE_EPOCH (reproducible builds) or now."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    t = (datetime.datetime.fromtimestamp(int(epoch), datetime.timezone.utc) if epoch
         else datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0))
    return t.strftime("%Y-%m-%dT%H:%M:%SZ")


# ---------------------------------------------------------------------------------------------
# packing
# ---------------------------------------------------------------------------------------------

def write_zip(out: Path, members):
    """members: (arcname, bytes, executable); deterministic (fixed dates, sorted)."""
    tmp = out.with_suffix(f".{os.getpid()}.tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data, executable in sorted(members, key=lambda m: m[0]):
            info = zipfile.ZipInfo(name, ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if executable else 0o644) << 16
            z.writestr(info, data)
    os.replace(tmp, out)


def build_one(script: Path, dest: Path, token_seed: str = "", fmi_version: int = 2) -> Path:
    """Build and validate one FMU: FMI 2.0 into ``dest/<Model>.fmu``, FMI 3.0 (model exchange and
    co-simulation) into ``dest/fmi3/<Model>.fmu``; both from the same slave file."""
    from fmpy.validation import validate_fmu

    cls = slave_class(script)
    name = cls.model.name
    if cls.__name__ != name:
        raise BuildError(f"{script}: class {cls.__name__} must carry the model's name {name}")
    launcher = compile_launcher(fmi_version)
    if launcher is None and fmi_version == 3:
        raise BuildError(f"{name}: an FMI 3.0 FMU needs the native launcher, and no C compiler was found (set CC)")
    with tempfile.TemporaryDirectory(prefix="pogofmu_build_") as tmp:
        stage_dir = Path(tmp)
        package, module, token = stage(script, cls, stage_dir, fmi_version, token_seed)
        check_isolated_import(stage_dir, name)
        members = [(p.relative_to(stage_dir).as_posix(), p.read_bytes(), False)
                   for p in sorted(stage_dir.rglob("*")) if p.is_file() and "__pycache__" not in p.parts]
    if fmi_version == 2:
        members.append(("modelDescription.xml", model_description_fmi2(cls, token), False))
        binaries = pythonfmu_binaries()
        if launcher is not None:
            binaries["linux64"] = launcher
    else:
        # the launcher only: pythonfmu's Windows binaries speak FMI 2.0 (no FMI 3.0 Windows binary)
        members.append(("modelDescription.xml", model_description_fmi3(cls, token), False))
        binaries = {"x86_64-linux": launcher}
        dest = dest / "fmi3"
        dest.mkdir(parents=True, exist_ok=True)
    for platform, lib in binaries.items():
        members.append((f"binaries/{platform}/{name}{lib.suffix}", lib.read_bytes(), True))
    fmu = dest / f"{name}.fmu"
    write_zip(fmu, members)
    problems = validate_fmu(str(fmu))
    if problems:
        raise BuildError(f"{fmu.name} (FMI {fmi_version}): fmpy validation failed:\n  " + "\n  ".join(problems))
    print(f"built and validated {fmu.relative_to(ROOT) if fmu.is_relative_to(ROOT) else fmu}")
    return fmu


def pack_ssp(system_dir: Path, dest: Path) -> Path:
    """Pack ``ssp/<System>/`` (SystemStructure.ssd, *.ssv) and the FMUs it references into an .ssp."""
    ssd = system_dir / "SystemStructure.ssd"
    text = ssd.read_text()
    out = dest / f"{system_dir.name}.ssp"
    members = [("SystemStructure.ssd", ssd.read_bytes(), False)]
    members += [(f"resources/{ssv.name}", ssv.read_bytes(), False) for ssv in sorted(system_dir.glob("*.ssv"))]
    for source in sorted(set(re.findall(r'source="(resources/[^"]+\.fmu)"', text))):
        fmu = dest / Path(source).name
        if not fmu.exists():  # an .ssp without its FMUs would only fail when run
            raise BuildError(f"{ssd}: component source {source} is not built in {dest}")
        members.append((source, fmu.read_bytes(), False))
    write_zip(out, members)
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
        built.append(build_one(script, dest, fmi_version=3))
    if not args.names:
        for ssd in sorted(SSP_DIR.glob("*/SystemStructure.ssd")):
            pack_ssp(ssd.parent, dest)
    return built


if __name__ == "__main__":
    main()
