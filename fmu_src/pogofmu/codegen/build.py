"""Compiling the native code: a model's generated C with the engine's C files, by the system C
compiler (host-side; :mod:`pogofmu.exporter` and the tests use it); the native FMUs' binaries, for
every platform of :data:`PLATFORMS`, by zig (:func:`native_fmu`).  Functions that take a model take
a :class:`~pogofmu.runtime.model.HybridModel` or the name of one of the project's models.

Flags: C99, ``-O2`` and ``-ffp-contract=off`` — no fused multiply-add, so that every operation is
rounded as Python rounds it (the generated model gives the bits of the Python model).
"""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import Iterable, Optional, Sequence

def native_dir() -> Path:
    """The C layer: ``fmu_src/native`` of a clone (or an editable install), else the copy an
    installed wheel carries as ``pogofmu/_native`` (setup.py copies it there)."""
    package = Path(__file__).resolve().parents[1]
    source = package.parent / "native"
    return source if (source / "pg_backend.h").is_file() else package / "_native"


NATIVE = native_dir()


def fmi_headers() -> Path:
    """The FMI standard's C headers (2.0 and 3.0) the project carries (``fmu_src/native/fmi``, with
    their provenance and licence): what the FMUs' C and the tests' C hosts are compiled against."""
    return NATIVE / "fmi"
ENGINE = NATIVE / "engine"
CFLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-fno-strict-aliasing", "-Wall", "-Wextra")


class CompileError(Exception):
    """The C compiler is missing or failed (the message holds its first lines of output)."""


NO_COMPILER = "no C compiler found (cc, gcc or clang on the PATH, CC, or the ziglang package: pip install ziglang)"


def c_compiler(cc=None) -> Optional[list]:
    """The command that compiles C for this machine: ``cc`` if given (a name or path, or a command
    as a list), else ``CC``, ``cc``, ``gcc`` or ``clang`` on the PATH, else the ziglang package's
    ``zig cc`` for the host (so a machine with Python and nothing else compiles the host-side
    libraries too); None without any of them."""
    if isinstance(cc, (list, tuple)):
        return list(cc)
    for name in ([cc] if cc else [os.environ.get("CC"), "cc", "gcc", "clang"]):
        if name and shutil.which(name):
            return [shutil.which(name)]
    if cc:
        return None
    return zig_cc(None)


def _run_cc(command: Sequence[str], args: Sequence[str]) -> subprocess.CompletedProcess:
    """Run a compiler command; zig is run from its own folder (see :func:`zig_cc`)."""
    cwd = Path(command[0]).parent if len(command) > 1 else None
    return subprocess.run([*command, *args], capture_output=True, text=True, cwd=cwd)


def _shown(command: Sequence[str]) -> str:
    return Path(command[0]).name if len(command) == 1 else " ".join([Path(command[0]).name, *command[1:]])


def compile_c(sources: Sequence[Path], out: Path, *, shared: bool = True, include: Iterable[Path] = (),
              defines: Iterable[str] = (), cc=None, extra: Sequence[str] = (),
              libs: Sequence[str] = ("-lm",), pic: bool = True) -> Path:
    command = c_compiler(cc)
    if command is None:
        raise CompileError(NO_COMPILER)
    # absolute paths: zig runs from its own folder
    args = [*CFLAGS, *(["-shared"] if shared else []), *(["-fPIC"] if shared and pic else []), *extra,
            *(f"-I{Path(p).resolve()}" for p in include), *(f"-D{d}" for d in defines),
            *(str(Path(s).resolve()) for s in sources), "-o", str(Path(out).resolve()), *libs]
    proc = _run_cc(command, args)
    if proc.returncode != 0:
        lines = (proc.stderr or proc.stdout).strip().splitlines()
        raise CompileError(f"{_shown(command)} failed ({proc.returncode}): " + " | ".join(lines[:6]))
    return out


def _model(model):
    """A model given as itself or by the name of one of the project's models."""
    if isinstance(model, str):
        from pogofmu.runtime.models import get

        return get(model)
    return model


def write_model_source(model, folder: Path) -> Path:
    """``<folder>/<Model>_model.c``, generated from the Python model."""
    from .cmodel import generate

    model = _model(model)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{model.name}_model.c"
    text = generate(model)
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
    return path


def model_library(model, folder: Path, cc=None) -> Path:
    """A shared library of the model's generated C and the engine's support code (``PG_MODEL``
    exported), for tests that call the generated functions directly."""
    model = _model(model)
    src = write_model_source(model, folder)
    out = folder / f"lib{model.name}_model.so"
    return compile_c([src, ENGINE / "pg_support.c", ENGINE / "pg_repr.c"], out, include=[ENGINE], cc=cc)


# the engine's C files (pg_pairs.c is generated from the tableaux by pogofmu.codegen.cpairs and kept
# in the repository; a test regenerates it); pg_binding.c is what the Python binding calls
ENGINE_SOURCES = ("pg_engine.c", "pg_pairs.c", "pg_rodas.c", "pg_support.c", "pg_repr.c")
BINDING_SOURCES = (*ENGINE_SOURCES, "pg_binding.c")


def cache_dir() -> Path:
    """Where compiled engine libraries are kept between runs: ``POGOFMU_CACHE``, else the user's
    cache folder (``XDG_CACHE_HOME`` or ``~/.cache`` on Linux, ``LOCALAPPDATA`` on Windows) /pogofmu."""
    given = os.environ.get("POGOFMU_CACHE")
    if given:
        return Path(given)
    if os.name == "nt" and os.environ.get("LOCALAPPDATA"):
        return Path(os.environ["LOCALAPPDATA"]) / "pogofmu" / "cache"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "pogofmu"


def prebuilt_dir() -> Path:
    """Where an installed package carries its host libraries, compiled when the package was built
    (setup.py's build_py step): ``pogofmu/_lib``."""
    return Path(__file__).resolve().parents[1] / "_lib"


def _host_key(sources: Sequence[Path], headers: Iterable[Path], extra: Sequence[str], libs: Sequence[str]) -> str:
    """The digest of a host library's sources, headers, flags and platform (not the compiler):
    the name of the package's prebuilt copy."""
    import hashlib
    import sys

    digest = hashlib.sha256(" ".join([*CFLAGS, "-shared", "-fPIC", *extra, *libs, sys.platform]).encode())
    for path in sorted({*sources, *headers}):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:16]


def _suffix() -> str:
    import sys

    return ".dll" if os.name == "nt" else ".dylib" if sys.platform == "darwin" else ".so"


def _host_library(stem: str, sources: Sequence[Path], headers: Iterable[Path], include: Sequence[Path],
                  extra: Sequence[str] = (), cc: Optional[str] = None, why: str = "",
                  into: Optional[Path] = None, libs: Sequence[str] = ("-lm",),
                  folder: Optional[Path] = None) -> Path:
    """A shared library of ``sources`` for this machine: the package's prebuilt copy
    (:func:`prebuilt_dir`, same sources and flags) if it has one, else compiled once per version of
    its sources, headers, flags and compiler into ``folder`` (default :func:`cache_dir`) as
    ``<stem>_<digest>.so``. ``into``: compile into that folder under the prebuilt name (the
    package build). ``libs``: what it links."""
    import hashlib
    import sys

    headers = list(headers)
    suffix = _suffix()
    key = _host_key(sources, headers, extra, libs)
    prebuilt = prebuilt_dir() / f"{stem}_{key}{suffix}"
    if into is None and cc is None and prebuilt.is_file():
        return prebuilt
    compiler = c_compiler(cc)
    if compiler is None:
        raise CompileError(f"{NO_COMPILER}{why}")
    if into is not None:
        into.mkdir(parents=True, exist_ok=True)
        return compile_c(sources, into / prebuilt.name, include=include, cc=compiler, extra=list(extra), libs=libs)
    flags = [*CFLAGS, "-shared", "-fPIC", *extra, *libs]
    zig = [f"zig {zig_version()}"] if len(compiler) > 1 else []
    digest = hashlib.sha256(" ".join([*compiler, *zig, *flags, sys.platform]).encode())
    for path in sorted({*sources, *headers}):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    folder = cache_dir() if folder is None else Path(folder)
    out = folder / f"{stem}_{digest.hexdigest()[:16]}{suffix}"
    if not out.exists():
        folder.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f"{out.stem}.{os.getpid()}.tmp{suffix}")
        compile_c(sources, tmp, include=include, cc=compiler, extra=list(extra), libs=libs)
        os.replace(tmp, out)
    return out


def host_engine_library(cc: Optional[str] = None, into: Optional[Path] = None) -> Path:
    """The engine as a shared library for this machine (its ``pgb_*`` functions exported): the
    installed package's prebuilt copy, else compiled once per version of its sources, flags and
    compiler into :func:`cache_dir` (:func:`_host_library`): what the host-side
    tools run a Python model's simulation with (:mod:`pogofmu.runtime.solver.cengine`)."""
    return _host_library("pogofmu_engine", [ENGINE / s for s in BINDING_SOURCES], ENGINE.glob("*.h"), [ENGINE],
                         ["-fvisibility=hidden"], cc, ": the engine is C", into)


MASTER = NATIVE / "master"


def host_level_library(cc: Optional[str] = None, into: Optional[Path] = None) -> Path:
    """The SSP master's C stepping of a level of components (``fmu_src/native/master/pg_level.c``,
    :mod:`pogofmu.ssp.native_level`) and its CSV rows (``pg_csv.c``, :mod:`pogofmu.ssp.record`),
    compiled once per version like :func:`host_engine_library`."""
    return _host_library("pogofmu_level", [MASTER / "pg_level.c", MASTER / "pg_csv.c", ENGINE / "pg_repr.c"],
                         (ENGINE / "pg_repr.h",), [MASTER, ENGINE], ["-fvisibility=hidden", "-pthread"], cc, "", into)


def engine_library(model, folder: Path, cc: Optional[str] = None) -> Path:
    """A shared library of the native engine with the model's generated C (``PG_MODEL`` and the
    ``pg_engine_*`` functions exported), for tests that drive the engine directly."""
    model = _model(model)
    srcs = [write_model_source(model, folder), *(ENGINE / s for s in ENGINE_SOURCES)]
    out = folder / f"lib{model.name}_engine.so"
    return compile_c(srcs, out, include=[ENGINE], cc=cc)


ADAPTER = NATIVE / "adapter"
ADAPTER_SOURCES = ("pg_backend.c", "pg_instance.c", "pg_instance3.c", "pg_derivatives.c", "pg_handles.c",
                   "pg_sha256.c")
# the entry files (shared with the Python-hosted FMUs' launcher) and what they share; each adds the
# sweep's stepping loop (one loop, pg_run_grid.h, over that version's entry points)
FMI_ENTRY = {v: (NATIVE / f"fmi{v}" / f"pg_fmi{v}.c", NATIVE / f"fmi{v}" / "pg_run_grid.c", NATIVE / "pg_run_grid.h")
             for v in (2, 3)}
ENTRY_SHARED = tuple(NATIVE / f for f in ("call_states.h", "pg_backend.h", "pg_logging.h", "pg_logging.c"))
FMI_HEADERS = {2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
               3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")}
# The native FMUs' binaries are cross-compiled by zig's clang (the ziglang package from PyPI, a
# dependency: one compiler and its own libc stubs for every target), key: the FMI 3.0 platform
# tuple -> (FMI 2.0 folder, zig target, library suffix, flags).  Every target gets CFLAGS'
# -ffp-contract=off (aarch64 compilers contract a*b+c into a fused multiply-add by default) and
# no fast-math, so that each platform computes the same bits.  Linux: glibc 2.17 symbols at most;
# macOS: 10.13 / 11.0 at least; Windows: the UCRT (part of Windows 10 and later), symbols stripped,
# and its math functions the UCRT's, not zig's compiler runtime's (POGOFMU_CRT_MATH: pg_crt_math.h).
# FMI 2.0 names no aarch64 folder: fmpy's FMI 2.0 loader looks in binaries/<fmpy.platform>, which is
# linux64 / darwin64 on aarch64 too; darwin64 therefore holds a universal (fat) Mach-O of both
# macOS architectures, as the Reference-FMUs' FMI 2.0 builds do, and aarch64 Linux, which cannot
# share linux64 with x86-64, gets the FMI 3.0 tuple's folder aarch64-linux (docs/native.md).
# Linux: link-time optimized (-flto), so that the engine calls the model's functions inlined (its
# PG_ONE_MODEL) and the FMI calls run into the adapter and the engine without a call per layer; the
# same operations in the same order (no fast-math, no contraction), the same bits. zig 0.17 cannot do
# it for the other targets: Windows fails its link (an undefined nanl in zig's C runtime), and its
# Mach-O linker has no LTO. Those binaries keep one object per file.
LTO = ("-flto",)
PLATFORMS = {
    "x86_64-linux": ("linux64", "x86_64-linux-gnu.2.17", ".so", ("-fPIC", "-fvisibility=hidden", "-s", *LTO)),
    "aarch64-linux": ("aarch64-linux", "aarch64-linux-gnu.2.17", ".so", ("-fPIC", "-fvisibility=hidden", "-s", *LTO)),
    "x86_64-windows": ("win64", "x86_64-windows-gnu", ".dll", ("-s", "-DPOGOFMU_CRT_MATH")),
    "x86_64-darwin": ("darwin64", "x86_64-macos.10.13", ".dylib", ("-fPIC", "-fvisibility=hidden", "-s")),
    "aarch64-darwin": ("darwin64", "aarch64-macos.11.0", ".dylib", ("-fPIC", "-fvisibility=hidden", "-s")),
}
NO_FAST_MATH = ("-fno-fast-math",)


def zig_cc(target: Optional[str]) -> Optional[list]:
    """The command that compiles C for ``target`` (None: this machine) with the ziglang package's
    zig, or None without it.
    The zig executable by its absolute path, run from its own folder (:func:`compile_units`): zig
    keys its cache of the targets' C libraries (minutes of work for Windows' mingw-w64 CRT) by its
    lib folder's path relative to the current folder, which must not change between callers."""
    import importlib.util

    spec = importlib.util.find_spec("ziglang")
    if spec is None or not spec.submodule_search_locations:
        return None
    folder = Path(list(spec.submodule_search_locations)[0]).resolve()
    exe = folder / ("zig.exe" if os.name == "nt" else "zig")
    if not exe.is_file():
        return None
    return [str(exe), "cc", *(["-target", target] if target else [])]


def zig_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ziglang")
    except PackageNotFoundError:
        return ""


def platform_folder(platform: str, fmi: int) -> str:
    """The FMU's ``binaries/`` folder of a platform (FMI 3.0 tuple) in that FMI version."""
    return PLATFORMS[platform][0] if fmi == 2 else platform


def parse_platforms(text) -> tuple:
    """``--platforms``: comma-separated FMI 3.0 platform tuples (or ``all``), checked, in PLATFORMS' order."""
    names = [t.strip() for t in (text.split(",") if isinstance(text, str) else text) if t.strip()]
    if not names or names == ["all"]:
        return tuple(PLATFORMS)
    unknown = [n for n in names if n not in PLATFORMS]
    if unknown:
        raise ValueError(f"unknown platform {', '.join(map(repr, unknown))}; the platforms are {', '.join(PLATFORMS)}")
    return tuple(p for p in PLATFORMS if p in names)


def fat_macho(slices: Sequence[Path], out: Path) -> Path:
    """A universal (fat) Mach-O of thin Mach-O ``slices`` (what ``lipo -create`` writes): the fat
    header, big-endian, then each slice at a 16 KiB boundary."""
    import struct

    align = 14
    datas = [Path(s).read_bytes() for s in slices]
    header = struct.pack(">II", 0xCAFEBABE, len(datas))
    offset = 1 << align
    entries, body = [], b""
    for data in datas:
        cputype, subtype = struct.unpack_from("<ii", data, 4)
        entries.append(struct.pack(">iiIII", cputype, subtype, offset, len(data), align))
        pad = (-(offset + len(data))) % (1 << align) if data is not datas[-1] else 0
        body += data + b"\0" * pad
        offset += len(data) + pad
    first = header + b"".join(entries)
    out.write_bytes(first + b"\0" * ((1 << align) - len(first)) + body)
    return out


def stage_sources(model, fmi: int, folder: Path, fmi_headers: Path):
    """Write every file of the native FMU's ``sources/`` into ``folder`` (flat: the generated model
    and tableaux, the engine, the adapter and its backend functions, the FMI entry file, the
    call-state table, the log filter and the FMI headers), without the description file, which needs the token: ``(files, digest)``, the digest
    covering their names and bytes (the FMU's build name and token derive from it).  The binaries
    are compiled from this folder alone, as an importer compiles a source FMU."""
    import hashlib

    folder.mkdir(parents=True, exist_ok=True)
    write_model_source(model, folder)
    copied = [*(ENGINE / s for s in ENGINE_SOURCES), *ENGINE.glob("*.h"), *(ADAPTER / s for s in ADAPTER_SOURCES),
              *ADAPTER.glob("*.h"), *FMI_ENTRY[fmi], *ENTRY_SHARED,
              *(fmi_headers / h for h in FMI_HEADERS[fmi])]
    for path in copied:
        shutil.copyfile(path, folder / path.name)
    from .cmodel import sizes_header

    (folder / "pg_sizes.h").write_text(sizes_header(_model(model)))  # (the engine's default replaced)
    files = sorted(p.name for p in folder.iterdir() if p.suffix in (".c", ".h"))
    digest = hashlib.sha256(f"fmi{fmi}".encode())
    for name in files:
        digest.update(name.encode() + b"\0" + (folder / name).read_bytes())
    return files, digest.hexdigest()


def write_fmu_source(model, fmi: int, folder: Path, token: str, build: str) -> Path:
    from .cfmu import generate

    model = _model(model)
    path = folder / f"{model.name}_fmi{fmi}.c"
    path.write_text(generate(model, fmi, token, build))
    return path


class NativeBuild:
    """A native FMU's compiled parts: ``sources`` (the folder), ``units`` (its compilation units, in
    the order of ``<SourceFiles>``), ``token``, ``build`` (the build name) and ``binaries``
    (FMI platform folder -> library)."""

    def __init__(self, sources: Path, units, token: str, build: str, binaries: dict):
        self.sources, self.units, self.token, self.build, self.binaries = sources, units, token, build, binaries


def _included(unit: Path, include: Sequence[Path]):
    """``unit`` and the headers it includes (``#include "..."``, found in ``include``), transitively."""
    import re

    seen, todo = [], [unit]
    while todo:
        f = todo.pop()
        if f in seen:
            continue
        seen.append(f)
        for name in re.findall(r'#\s*include\s+"([^"]+)"', f.read_text(errors="replace")):
            for folder in [f.parent, *include]:
                cand = Path(folder) / name
                if cand.is_file():
                    todo.append(cand)
                    break
    return sorted(seen)


def compile_units(units: Sequence[Path], out: Path, include: Sequence[Path], cc=None,
                  extra: Sequence[str] = (), pic: bool = True, cache: Optional[Path] = None,
                  shared_units: Iterable[str] = ()) -> Path:
    """A shared library of ``units`` compiled one object per unit, in parallel, then linked: the
    objects of ``shared_units`` (the engine and adapter files, the same for every model) are kept in
    ``cache`` by the hash of the compiler, the flags, the unit and every header of ``include``, so a
    second model (or FMI version) compiles only its own two files.  ``cc``: a compiler's name or
    path, or a command (a list: :func:`zig_cc`)."""
    import hashlib
    from concurrent.futures import ThreadPoolExecutor

    command = c_compiler(cc)
    if command is None:
        raise CompileError(NO_COMPILER)
    compiler = " ".join(command) + (f" zig {zig_version()}" if len(command) > 1 else "")
    # zig names its lib folder relative to the current folder and keys its cache of the targets' C
    # libraries by that name: run it from its own folder, so that one cache serves every caller
    cwd = Path(command[0]).parent if len(command) > 1 else None
    shown = Path(command[0]).name if len(command) == 1 else " ".join(command[-3:])
    flags = [*CFLAGS, *(["-fPIC"] if pic else []), *extra, *(f"-I{p}" for p in include)]
    shared_units = set(shared_units)
    objdir = out.parent / f"{out.stem}.objects"
    objdir.mkdir(parents=True, exist_ok=True)

    def one(unit: Path) -> Path:
        obj = objdir / (unit.stem + ".o")
        cached = None
        if cache is not None and unit.name in shared_units:
            # (not the include folders' paths, a temporary folder each build: their headers' contents)
            key = hashlib.sha256(" ".join([compiler, *(f for f in flags if not f.startswith("-I"))]).encode())
            for part in _included(unit, include):  # the unit and every header it includes, by content
                key.update(part.name.encode() + b"\0" + part.read_bytes())
            cached = Path(cache) / f"{unit.stem}-{key.hexdigest()[:20]}.o"
            if cached.exists():
                shutil.copyfile(cached, obj)
                return obj
        proc = subprocess.run([*command, *flags, "-c", str(unit), "-o", str(obj)], capture_output=True, text=True,
                              cwd=cwd)
        if proc.returncode != 0:
            lines = (proc.stderr or proc.stdout).strip().splitlines()
            raise CompileError(f"{shown} failed ({proc.returncode}) on {unit.name}: " + " | ".join(lines[:6]))
        if cached is not None:
            cached.parent.mkdir(parents=True, exist_ok=True)
            tmp = cached.with_suffix(f".{os.getpid()}.tmp")
            shutil.copyfile(obj, tmp)
            os.replace(tmp, cached)
        return obj

    with ThreadPoolExecutor(max_workers=max(1, min(len(units), os.cpu_count() or 1))) as pool:
        objects = list(pool.map(one, units))
    # (the optimization level again: a link-time optimized build compiles the program at the link)
    cmd = [*command, "-shared", *(f for f in CFLAGS if f.startswith("-O")), *extra, *(str(o) for o in objects),
           "-o", str(out), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=cwd)
    if proc.returncode != 0:
        lines = (proc.stderr or proc.stdout).strip().splitlines()
        raise CompileError(f"{shown} failed ({proc.returncode}) linking: " + " | ".join(lines[:6]))
    shutil.rmtree(objdir, ignore_errors=True)
    return out


def native_fmu(model, fmi: int, folder: Path, fmi_headers: Path, token: Optional[str] = None,
               platforms: Sequence[str] = tuple(PLATFORMS), cache: Optional[Path] = None) -> NativeBuild:
    """Stage the native FMU's sources in ``folder/sources`` and compile them for each of
    ``platforms`` (FMI 3.0 tuples, keys of :data:`PLATFORMS`) with zig (objects of the
    model-independent files kept in ``cache``, see :func:`compile_units`); FMI 2.0's darwin64 gets
    one universal library of the macOS platforms asked for."""
    import uuid
    from concurrent.futures import ThreadPoolExecutor

    model = _model(model)
    model_name = model.name
    src = folder / "sources"
    files, digest = stage_sources(model, fmi, src, fmi_headers)
    build = f"native_{model_name}_{digest[:12]}"
    token = token or "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"pogofmu/{build}/fmi{fmi}")) + "}"
    desc = write_fmu_source(model, fmi, src, token, build)
    units = sorted({*(f for f in files if f.endswith(".c")), desc.name})
    # every object kept in the cache by its contents: the engine's and adapter's are the same for
    # every model; a model's own two files are the same again when it is exported again unchanged
    # (the tests' session build, a user's re-export), so that costs a link per platform only
    shared = list(units)

    def one(platform: str) -> Path:
        _, target, suffix, extra = PLATFORMS[platform]
        command = zig_cc(target)
        if command is None:
            raise CompileError("no ziglang (PyPI: ziglang, a dependency of pogofmu): the native binaries are "
                               "compiled with zig cc")
        out = folder / platform / f"{model_name}{suffix}"
        out.parent.mkdir(parents=True, exist_ok=True)
        return compile_units([src / u for u in units], out, include=[src], cc=command, extra=(*NO_FAST_MATH, *extra),
                             pic=False, cache=cache, shared_units=shared)

    with ThreadPoolExecutor(max_workers=len(platforms) or 1) as pool:
        built = dict(zip(platforms, pool.map(one, platforms)))
    binaries = {}
    for platform, lib in built.items():
        binaries.setdefault(platform_folder(platform, fmi), []).append(lib)
    for name, libs in binaries.items():
        if len(libs) > 1:  # FMI 2.0 darwin64: both macOS architectures in one file
            binaries[name] = [fat_macho(libs, folder / f"{model_name}.universal{libs[0].suffix}")]
    return NativeBuild(src, units, token, build, {name: libs[0] for name, libs in binaries.items()})
