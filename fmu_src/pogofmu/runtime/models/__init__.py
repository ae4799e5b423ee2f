"""The model variants: every module of this folder that defines ``MODEL`` (a
:class:`~..model.HybridModel`) is one FMU of the project, named after the model.

This is the one registry of the models: the build, the master and the sweeps find them here, so
adding a model variant is adding one module with a ``MODEL``.
"""
from __future__ import annotations

import importlib
import pkgutil
from typing import Dict, List, Tuple

_HELPERS = ("stick",)  # modules of this folder that build models but are none


def entries() -> List[Tuple[str, object]]:
    """``(module name, MODEL)`` of every model variant, sorted by model name."""
    out = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_") or info.name in _HELPERS:
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        model = getattr(module, "MODEL", None)
        if model is not None:
            out.append((info.name, model))
    names = [m.name for _, m in out]
    if len(set(names)) != len(names):
        raise RuntimeError(f"two model modules define the same model name: {sorted(names)}")
    return sorted(out, key=lambda e: e[1].name)


def all_models() -> Dict[str, object]:
    """``{model name: MODEL}`` of every model variant."""
    return {m.name: m for _, m in entries()}


def module_of(name: str) -> str:
    """The module (of this folder) that defines the model ``name``."""
    for module, model in entries():
        if model.name == name:
            return module
    raise KeyError(name)


def get(name: str):
    """The model named ``name``; a KeyError lists the models there are."""
    models = all_models()
    try:
        return models[name]
    except KeyError:
        raise KeyError(f"no model {name!r}; the models are {', '.join(models)}") from None
