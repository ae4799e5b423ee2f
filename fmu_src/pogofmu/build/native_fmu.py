"""The native FMUs: the same modelDescription as the Python-hosted FMU of that FMI version (but for
its token and, FMI 2.0, ``<SourceFiles>``), a binary of C generated from the Python model
(:mod:`pogofmu.codegen`) with the native engine and adapter — no Python at run time — for Linux,
for Windows where the mingw-w64 cross compiler is installed, and the C sources themselves
(``sources/``; FMI 3.0: with buildDescription.xml), from which both binaries are compiled and an
importer compiles its own."""
from __future__ import annotations

import tempfile
from pathlib import Path

from .errors import BuildError
from .python_fmu import fmi_headers, warn_once


def mingw_available() -> bool:
    from pogofmu.codegen.build import mingw_compiler

    return mingw_compiler() is not None


def build_native_fmu(source, dest: Path, fmi_version: int, cache: Path = None, windows: bool = None) -> Path:
    """Build and validate the native FMU of ``source``: FMI 2.0 into ``dest/native/<Model>.fmu``,
    FMI 3.0 into ``dest/native/fmi3/<Model>.fmu``; with a Windows binary if ``windows`` (default:
    where mingw-w64 is installed; an export decides it once for all its FMUs)."""
    from pogofmu.codegen.build import CompileError, native_fmu

    from .description import build_description_fmi3, model_description_fmi2, model_description_fmi3
    from .package import documentation, write_zip

    name = source.model.name
    cls = source.slave_class()
    out_dir = dest / "native" / ("fmi3" if fmi_version == 3 else "")
    windows = mingw_available() if windows is None else windows
    if not windows:
        warn_once("no mingw-w64 cross compiler (Debian: gcc-mingw-w64-x86-64): the native FMUs get no "
                  "Windows binary (their sources/ still build on any platform)")
    with tempfile.TemporaryDirectory(prefix="pogofmu_native_") as tmp:
        try:
            nb = native_fmu(source.model, fmi_version, Path(tmp), fmi_headers(), windows=windows,
                            cache=None if cache is None else Path(cache) / "objects")
        except CompileError as exc:
            raise BuildError(f"{name}: the native FMU does not compile: {exc}") from None
        if fmi_version == 2:
            description = model_description_fmi2(cls, nb.token, nb.units, directional=True)
        else:
            description = model_description_fmi3(cls, nb.token, directional=True)
            (nb.sources / "buildDescription.xml").write_bytes(build_description_fmi3(name, nb.units))
        members = [("modelDescription.xml", description, False)]
        members += [(f"binaries/{platform}/{name}{lib.suffix}", lib.read_bytes(), True)
                    for platform, lib in sorted(nb.binaries.items())]
        members += [(f"sources/{p.name}", p.read_bytes(), False) for p in sorted(nb.sources.iterdir())]
        members += documentation(source, "native", fmi_version, sorted(nb.binaries))
    fmu = out_dir / f"{name}.fmu"
    write_zip(fmu, members, f"native FMI {fmi_version}")
    return fmu
