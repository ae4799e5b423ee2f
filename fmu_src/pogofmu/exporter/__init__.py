"""The exporter: any :class:`~pogofmu.runtime.model.HybridModel` to FMUs (host-side; never inside an FMU).

* :mod:`.source` — where a model comes from: the project's models, or a user's model file (its
  imports rewritten for the FMU's private package);
* :mod:`.checks` — the checks of a model before anything is built;
* :mod:`.python_fmu`, :mod:`.native_fmu` — the Python-hosted and the native FMUs;
* :mod:`.description` — modelDescription.xml; :mod:`.dependencies` — the model structure's
  dependencies, probed from the model's functions; :mod:`.package` — zip, documentation,
  validation; :mod:`.ssp` — packing SSP systems;
* :mod:`.export` — ``pogofmu export`` and the one build path (:class:`~.export.Exporter`) that
  also builds the project's own models (:func:`build_project`, called by ``build_fmu.py``).
"""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional, Sequence

from .errors import BuildError, ModelFileError
from .export import Exporter, NativeRefusal, export_files
from .native_fmu import zig_available
from .python_fmu import NATIVE, compile_launcher, fmi_headers, launcher_sources
from .source import ModelSource, load_model_file, project_sources
from .ssp import pack_ssp

__all__ = ["BuildError", "ModelFileError", "NativeRefusal", "Exporter", "export_files", "load_model_file",
           "ModelSource", "project_sources", "model_names", "source_of", "slave_class", "build_project",
           "build_one", "build_native", "pack_ssp", "launcher_sources", "fmi_headers", "zig_available", "NATIVE",
           "compile_launcher"]


def model_names() -> List[str]:
    """The names of the project's models (``pogofmu/runtime/models/``), sorted."""
    return [s.model.name for s in project_sources()]


def source_of(name: str) -> ModelSource:
    for s in project_sources():
        if s.model.name == name:
            return s
    raise BuildError(f"no model {name!r}; the models are {', '.join(model_names())}")


_CLASSES = {}


def slave_class(name: str):
    """The FMI 2.0 slave class of the project's model ``name`` (the class its FMU's slave module defines)."""
    if name not in _CLASSES:
        _CLASSES[name] = source_of(name).slave_class()
    return _CLASSES[name]


def build_one(name: str, dest: Path, token_seed: str = "", fmi_version: int = 2, cache: Optional[Path] = None) -> Path:
    """The Python-hosted FMU of the project's model ``name`` (FMI 2.0 into ``dest``, 3.0 into ``dest/fmi3``)."""
    with Exporter(dest, (fmi_version,), ("python",), cache=cache, log=print, token_seed=token_seed) as ex:
        return ex.export(source_of(name))[0]


def build_native(name: str, dest: Path, fmi_version: int = 2) -> Path:
    """The native FMU of the project's model ``name`` (into ``dest/native``, ``dest/native/fmi3``)."""
    with Exporter(dest, (fmi_version,), ("native",), log=print) as ex:
        return ex.export(source_of(name))[0]


def build_project(dest: Path, names: Sequence[str] = (), ssp_dir: Optional[Path] = None,
                  cache: Optional[Path] = None, log=print, platforms: Optional[Sequence[str]] = None) -> List[Path]:
    """Every FMU of the project's models (``names``: only those) into ``dest`` — the same
    :class:`Exporter` as ``pogofmu export`` — and, for a full build, the SSP systems of ``ssp_dir``
    (SSP 1.0 with the FMI 2.0 FMUs, SSP 2.0 with the FMI 3.0 ones), with the Python-hosted FMUs
    into ``dest`` and with the native ones into ``dest/native``."""
    dest = Path(dest)
    known = model_names()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise BuildError(f"no model {', '.join(map(repr, unknown))}; the models are {', '.join(known)}")
    built = []
    with Exporter(dest, cache=cache, log=log, platforms=platforms) as ex:
        for source in project_sources():
            if not names or source.model.name in names:
                built += ex.export(source)
        if ex.refusals:
            raise BuildError("; ".join(ex.refusals))
    if not names and ssp_dir is not None:
        # each system with the Python-hosted FMUs, and again with the native ones (dest/native/)
        for folder in (dest, dest / "native"):
            if not (folder / "fmi3").is_dir():
                continue
            for ssd in sorted(Path(ssp_dir).glob("*/SystemStructure.ssd")):
                for fmi3 in (False, True):
                    out = pack_ssp(ssd.parent, folder, fmi3=fmi3)
                    log(f"packed {out}")
    return built
