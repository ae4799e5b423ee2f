"""The native FMUs: the same modelDescription as the Python-hosted FMU of that FMI version (but for
its token and, FMI 2.0, ``<SourceFiles>``), binaries of C generated from the Python model
(:mod:`pogofmu.codegen`) with the native engine and adapter — no Python at run time — for x86-64
and aarch64 Linux, x86-64 Windows and x86-64 and aarch64 macOS (cross-compiled with zig, the
ziglang package; ``platforms`` chooses a subset), and the C sources themselves (``sources/``; FMI
3.0: with buildDescription.xml), from which every binary is compiled and an importer compiles its own."""
from __future__ import annotations

import tempfile
from pathlib import Path

from .errors import BuildError
from pogofmu.codegen.build import fmi_headers


def zig_available() -> bool:
    from pogofmu.codegen.build import zig_cc

    return zig_cc("native") is not None


def build_native_fmu(source, dest: Path, fmi_version: int, cache: Path = None, platforms=None, objects: Path = None) -> Path:
    """Build and validate the native FMU of ``source``: FMI 2.0 into ``dest/native/<Model>.fmu``,
    FMI 3.0 into ``dest/native/fmi3/<Model>.fmu``; with binaries for ``platforms`` (FMI 3.0 tuples,
    default all of :data:`pogofmu.codegen.build.PLATFORMS`); the model-independent objects kept in
    ``objects`` (default ``cache/objects``)."""
    from pogofmu.codegen.build import PLATFORMS, CompileError, native_fmu

    from .description import build_description_fmi3, model_description_fmi2, model_description_fmi3
    from .package import documentation, write_zip

    name = source.model.name
    cls = source.slave_class()
    out_dir = dest / "native" / ("fmi3" if fmi_version == 3 else "")
    platforms = tuple(PLATFORMS) if platforms is None else tuple(platforms)
    with tempfile.TemporaryDirectory(prefix="pogofmu_native_") as tmp:
        try:
            nb = native_fmu(source.model, fmi_version, Path(tmp), fmi_headers(), platforms=platforms,
                            cache=objects if objects is not None else None if cache is None else Path(cache) / "objects")
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
