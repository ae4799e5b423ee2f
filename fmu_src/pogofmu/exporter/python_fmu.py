"""The Python-hosted FMUs: the model's Python code staged under private names, behind the
project's launcher (``fmu_src/native``: the FMI entry files and the one adapter, whose model is the
FMU's Python code: ``python/pg_source_py.c``, :mod:`pogofmu.runtime.hosted`).

1. The FMU's Python code is staged under names private to this build of this model: the folder
   ``pogofmu/runtime/`` (the code that goes into FMUs, as it is) becomes
   ``resources/_pogofmu_<Model>_<hash>/``, a user's model file and its local modules go into its
   ``user/`` subpackage (their imports of ``pogofmu`` rewritten to the private name,
   :mod:`.source`), and a slave module generated here, ``resources/_pogofmu_<Model>_<hash>_slave.py``,
   names the model's class (``resources/pogofmu_launch.txt`` tells the launcher these names), so
   that several FMUs — other models, other versions of the project — run side by side in one
   process; the build checks that this code imports in an isolated interpreter.
2. ``binaries/<platform>/<Model>.so`` is the launcher, compiled with the system C compiler: it
   brings a CPython interpreter into any FMI importer and calls the staged code.  It is compiled
   by the system's C compiler or, where there is none, by the ziglang package's (a dependency).
   The Python-hosted FMUs have no Windows binary: on Windows, use the native FMUs.
"""
from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import uuid
from pathlib import Path
from typing import Optional

from .errors import BuildError

PACKAGE = Path(__file__).resolve().parents[1]  # fmu_src/pogofmu
RUNTIME = PACKAGE / "runtime"  # the code that goes into every FMU, staged as a whole
# the C layer (in a clone or a wheel), the FMI headers it carries, and one way to compile a library
# for this machine (a prebuilt copy of the package, else the system's compiler or ziglang's)
from pogofmu.codegen.build import (ADAPTER, ADAPTER_SOURCES, BINDING_SOURCES, ENGINE, NATIVE,  # noqa: E402
                                   CompileError, _host_library, fmi_headers)


def launcher_sources(fmi_version: int):
    """The C files of the Python-hosted FMUs' binary: the entry file of that FMI version (the one the
    native FMUs are built from, ``fmu_src/native/fmi2/pg_fmi2.c`` or ``fmi3/pg_fmi3.c``), the log
    filter, the C adapter of the native FMUs (``native/adapter/``: the FMI rules, the FMU states)
    whose model comes from Python (``native/python/pg_source_py.c``, with the embedding of CPython),
    and the engine with its Python binding."""
    return [NATIVE / f"fmi{fmi_version}" / f"pg_fmi{fmi_version}.c", NATIVE / "pg_logging.c",
            *(ADAPTER / s for s in ADAPTER_SOURCES),
            NATIVE / "python" / "pg_source_py.c", NATIVE / "python" / "python_embed.c",
            *(ENGINE / s for s in BINDING_SOURCES)]


_WARNED = set()


def warn_once(text: str) -> None:
    if text not in _WARNED:
        _WARNED.add(text)
        print(f"WARNING: {text}", file=sys.stderr)


def compile_launcher(fmi_version: int, cache: Optional[Path] = None, into: Optional[Path] = None) -> Path:
    """The Python-hosted FMUs' binary for FMI 2 or 3 (:func:`launcher_sources`): the installed
    package's prebuilt copy (``pogofmu/_lib``, compiled when the package was built), else compiled
    once per version of its sources, headers, flags and compiler into ``cache`` (default: the
    user's cache folder); ``into``: compile it there under the prebuilt name (the package build,
    setup.py). Returns the library's path. The launcher carries the engine (the engine's C files
    with ``pg_binding.c``, compiled with the engine's flags: no fused multiply-add), so where there
    is no prebuilt copy a C compiler is needed (the system's, else the ziglang package's)."""
    sources = launcher_sources(fmi_version)
    # (headers only besides the sources: a stray .c beside them must not change the key)
    headers = {*NATIVE.glob("*.h"), *(NATIVE / "python").glob("*.h"),
               *ADAPTER.glob("*.h"), *ENGINE.glob("*.h"), *fmi_headers().glob(f"fmi{fmi_version}*.h")}
    include = [fmi_headers(), NATIVE, NATIVE / "python", ADAPTER, ENGINE]
    try:
        return _host_library(f"pogofmu_launcher_fmi{fmi_version}", sources, headers, include,
                             ["-std=c11", "-fvisibility=hidden", "-Wno-unused-parameter", "-DPG_PYTHON_SOURCE"], None,
                             ": the Python-hosted FMUs' launcher carries the engine, which is C", into,
                             ("-ldl", "-lpthread", "-lm"), cache)
    except CompileError as exc:
        raise BuildError(f"compiling the FMUs' launcher failed: {exc}") from None


def python_libraries():
    """libpython of the interpreter running the build: the launcher tries it first in a C host."""
    libdir, soname = sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME")
    if libdir and soname and sysconfig.get_config_var("Py_ENABLE_SHARED"):
        lib = Path(libdir) / soname
        if lib.exists():
            return [str(lib)]
    return []


SLAVE_TEMPLATE = '''"""FMU slave of {name}, generated by pogofmu export."""
from {package}.fmi2 import HybridSlave as Fmi2Slave
from {package}.{module} import {attr} as MODEL


class {name}(Fmi2Slave):
    model = MODEL

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
'''


def slave_source(package: str, module: str, attr: str, name: str) -> str:
    """The slave module of one FMU: the model's class behind the FMI 2.0 adapter (the launcher's
    boot code puts it behind the FMI 3.0 one for an FMI 3.0 FMU)."""
    return SLAVE_TEMPLATE.format(package=package, module=module, attr=attr, name=name)


def runtime_files():
    """(relative path, bytes) of the files of the runtime folder, in a stable order."""
    return [(p.relative_to(RUNTIME).as_posix(), p.read_bytes()) for p in sorted(RUNTIME.rglob("*.py"))
            if "__pycache__" not in p.parts]


def stage(source, stage_dir: Path, fmi_version: int, token_seed: str = ""):
    """Write resources/ of one FMU of ``source`` (a :class:`~.source.ModelSource`) into ``stage_dir``;
    return (package, module, token)."""
    from .description import project_version

    name = source.model.name
    files = runtime_files()
    digest = hashlib.sha256(SLAVE_TEMPLATE.encode() + source.module.encode() + source.attr.encode())
    for rel, data in files:
        digest.update(rel.encode() + b"\0" + data)
    for rel, text in source.staged_files("\0"):
        digest.update(rel.encode() + b"\0" + text.encode())
    digest.update(f"{name}:{project_version()}:{token_seed}".encode())
    tag = digest.hexdigest()[:12]
    package = f"_pogofmu_{name}_{tag}"
    module = f"{package}_slave"
    token = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"pogofmu/{name}/{tag}/fmi{fmi_version}")) + "}"
    res = stage_dir / "resources"
    for rel, data in files:
        target = res / package / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    for rel, text in source.staged_files(package):
        target = res / package / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text, encoding="utf-8")
    (res / f"{module}.py").write_text(slave_source(package, source.module, source.attr, name))
    shutil.copy2(NATIVE / "python" / "pogofmu_boot.py", res / "pogofmu_boot.py")
    lines = ["# read by the launcher and resources/pogofmu_boot.py (written by pogofmu export)",
             f"package={package}", f"module={module}", f"class={name}", f"token={token}",
             f"fmi={fmi_version}"] + [f"python={lib}" for lib in python_libraries()]
    (res / "pogofmu_launch.txt").write_text("\n".join(lines) + "\n")
    return package, module, token


def check_isolated_import(stage_dir: Path, source):
    """The staged code must import in an isolated interpreter (no pogofmu on the path; no
    site-packages unless the model declares third-party requirements): what the launcher does in a
    C importer (the slave class with its model, and the module that makes it the adapter's model)."""
    res = stage_dir / "resources"
    cls_name = source.model.name
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import pogofmu_boot; "
            f"cls = pogofmu_boot.load(sys.argv[1]); assert cls.__name__ == {cls_name!r}; "
            "import importlib; pkg = pogofmu_boot.read_launch_file(sys.argv[1])['package'][0]; "
            "importlib.import_module(pkg + '.hosted'); "
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('pogofmu', 'pythonfmu')); "
            "assert not bad, bad")
    flags = ["-I"] if source.requirements else ["-I", "-S"]
    proc = subprocess.run([sys.executable, *flags, "-c", code, str(res)], capture_output=True, text=True,
                          cwd=tempfile.gettempdir())
    if proc.returncode:
        last = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise BuildError(f"{source.where()}: the FMU's Python code does not import on its own "
                         f"({'with its declared requirements' if source.requirements else 'standard library only'}): "
                         f"{last}")


def build_python_fmu(source, dest: Path, fmi_version: int, launcher: Path, token_seed: str = "") -> Path:
    """Build and validate the Python-hosted FMU of ``source`` around ``launcher`` (:func:`compile_launcher`,
    which carries the engine): FMI 2.0 co-simulation into ``dest/<Model>.fmu``, FMI 3.0 (model exchange
    and co-simulation) into ``dest/fmi3/<Model>.fmu``."""
    from .description import model_description_fmi2, model_description_fmi3
    from .package import documentation, write_zip

    name = source.model.name
    cls = source.slave_class()
    with tempfile.TemporaryDirectory(prefix="pogofmu_build_") as tmp:
        stage_dir = Path(tmp)
        package, module, token = stage(source, stage_dir, fmi_version, token_seed)
        check_isolated_import(stage_dir, source)
        members = [(p.relative_to(stage_dir).as_posix(), p.read_bytes(), False)
                   for p in sorted(stage_dir.rglob("*")) if p.is_file() and "__pycache__" not in p.parts]
    if fmi_version == 2:
        members.append(("modelDescription.xml", model_description_fmi2(cls, token), False))
        # the launcher for Linux (it carries the engine; Windows: the native FMUs)
        binaries = {"linux64": launcher}
    else:
        # the launcher for Linux, as for FMI 2.0
        members.append(("modelDescription.xml", model_description_fmi3(cls, token), False))
        binaries = {"x86_64-linux": launcher}
        dest = dest / "fmi3"
    for platform, lib in binaries.items():
        members.append((f"binaries/{platform}/{name}{lib.suffix}", lib.read_bytes(), True))
    members += documentation(source, "python", fmi_version, sorted(binaries))
    fmu = dest / f"{name}.fmu"
    write_zip(fmu, members, f"FMI {fmi_version}")
    return fmu
