"""Compiling the native code: a model's generated C with the engine's C files, by the system C
compiler (host-side; ``build_fmu.py`` and the tests use it).

Flags: C99, ``-O2`` and ``-ffp-contract=off`` — no fused multiply-add, so that every operation is
rounded as Python rounds it (the same bits as the Python engine).
"""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import Iterable, Optional, Sequence

NATIVE = Path(__file__).resolve().parents[2] / "native"
ENGINE = NATIVE / "engine"
CFLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-fno-strict-aliasing", "-Wall", "-Wextra")


class CompileError(Exception):
    """The C compiler is missing or failed (the message holds its first lines of output)."""


def c_compiler(cc: Optional[str] = None) -> Optional[str]:
    for name in ([cc] if cc else [os.environ.get("CC"), "cc", "gcc", "clang"]):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def compile_c(sources: Sequence[Path], out: Path, *, shared: bool = True, include: Iterable[Path] = (),
              defines: Iterable[str] = (), cc: Optional[str] = None, extra: Sequence[str] = (),
              libs: Sequence[str] = ("-lm",)) -> Path:
    compiler = c_compiler(cc)
    if compiler is None:
        raise CompileError("no C compiler found (cc, gcc or clang; or set CC)")
    cmd = [compiler, *CFLAGS, *(["-shared", "-fPIC"] if shared else []), *extra,
           *(f"-I{p}" for p in include), *(f"-D{d}" for d in defines),
           *(str(s) for s in sources), "-o", str(out), *libs]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        lines = (proc.stderr or proc.stdout).strip().splitlines()
        raise CompileError(f"{Path(compiler).name} failed ({proc.returncode}): " + " | ".join(lines[:6]))
    return out


def write_model_source(model_name: str, folder: Path) -> Path:
    """``<folder>/<Model>_model.c``, generated from the Python model."""
    from pogofmu.runtime.models import get

    from .cmodel import generate

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{model_name}_model.c"
    text = generate(get(model_name))
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
    return path


def model_library(model_name: str, folder: Path, cc: Optional[str] = None) -> Path:
    """A shared library of the model's generated C and the engine's support code (``PG_MODEL``
    exported), for tests that call the generated functions directly."""
    src = write_model_source(model_name, folder)
    out = folder / f"lib{model_name}_model.so"
    return compile_c([src, ENGINE / "pg_support.c"], out, include=[ENGINE], cc=cc)


def write_pairs_source(folder: Path) -> Path:
    """``<folder>/pg_pairs.c``, generated from the Python engine's tableaux."""
    from .cpairs import generate

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "pg_pairs.c"
    text = generate()
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
    return path


ENGINE_SOURCES = ("pg_engine.c", "pg_support.c")


def engine_library(model_name: str, folder: Path, cc: Optional[str] = None) -> Path:
    """A shared library of the native engine with the model's generated C (``PG_MODEL`` and the
    ``pg_engine_*`` functions exported), for tests that drive the engine directly."""
    srcs = [write_model_source(model_name, folder), write_pairs_source(folder), *(ENGINE / s for s in ENGINE_SOURCES)]
    out = folder / f"lib{model_name}_engine.so"
    return compile_c(srcs, out, include=[ENGINE], cc=cc)


ADAPTER = NATIVE / "adapter"
ADAPTER_SOURCES = ("pg_instance.c", "pg_sha256.c")
FMI_ENTRY = {2: NATIVE / "fmi2" / "pg_fmi2.c"}


def native_sources(model_name: str, fmi: int, folder: Path):
    """Every C file of the native FMU of ``model_name`` (the generated ones written into
    ``folder``), without the description file, which needs the token: ``(sources, digest)``, the
    digest covering their bytes (the FMU's build name and token derive from it)."""
    import hashlib

    srcs = [write_model_source(model_name, folder), write_pairs_source(folder),
            *(ENGINE / s for s in ENGINE_SOURCES), *(ADAPTER / s for s in ADAPTER_SOURCES), FMI_ENTRY[fmi]]
    digest = hashlib.sha256(f"fmi{fmi}".encode())
    headers = sorted([*ENGINE.glob("*.h"), *ADAPTER.glob("*.h"), NATIVE / "call_states.h"])
    for path in [*srcs, *headers]:
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return srcs, digest.hexdigest()


def write_fmu_source(model_name: str, fmi: int, folder: Path, token: str, build: str) -> Path:
    from pogofmu.runtime.models import get

    from .cfmu import generate

    path = folder / f"{model_name}_fmi{fmi}.c"
    path.write_text(generate(get(model_name), fmi, token, build))
    return path


def native_fmu_library(model_name: str, fmi: int, folder: Path, fmi_headers: Path, cc: Optional[str] = None,
                       token: Optional[str] = None):
    """Compile the native FMU's binary: ``(library, token, build name, sources)``."""
    import uuid

    srcs, digest = native_sources(model_name, fmi, folder)
    build = f"native_{model_name}_{digest[:12]}"
    token = token or "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"pogofmu/{build}/fmi{fmi}")) + "}"
    desc = write_fmu_source(model_name, fmi, folder, token, build)
    out = folder / f"{model_name}.so"
    compile_c([*srcs, desc], out, include=[ENGINE, ADAPTER, fmi_headers], cc=cc,
              extra=("-fvisibility=hidden",), libs=("-lm",))
    return out, token, build, [*srcs, desc]
