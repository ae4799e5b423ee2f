"""Where a model comes from, and how its Python code goes into an FMU.

A :class:`ModelSource` is one model to export: the :class:`~pogofmu.runtime.model.HybridModel`,
the module of the FMU's private package that defines it, and the files to stage there.

* The project's models live in ``pogofmu/runtime/models/`` (:func:`project_sources`): they are
  staged with the runtime as they are.
* A user's model file (:func:`load_model_file`) is imported on the host as a plain module (its
  ``from pogofmu import ...`` reads the installed package); inside the FMU it becomes
  ``<package>.user.<stem>``, with the local modules it imports beside it, and every import of
  ``pogofmu``, ``pogofmu.elements``, ``pogofmu.fmath`` or ``pogofmu.runtime.*`` and of a local
  module rewritten to the private names (on the same lines, so that a traceback inside the FMU
  names the user's line).  The standard library is imported as it is; a third-party module is
  refused unless the user declares it (``--requires NAME``: recorded in the FMU's
  documentation, the FMU then needs it on the target).
"""
from __future__ import annotations

import ast
import hashlib
import importlib.util
import os
import re
import sys
import traceback
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

from .errors import ModelFileError

RUNTIME = Path(__file__).resolve().parents[1] / "runtime"
# the public modules of the API and the runtime modules a model file may import, by the name it
# imports them with -> the module of the FMU's private package ("" for the package itself)
_RUNTIME_MODULES = sorted(p.stem for p in RUNTIME.glob("*.py") if p.stem != "__init__") + ["solver", "models"]


def _public_target(module: str) -> Optional[str]:
    """``pogofmu[.x]`` as the module of the private package it is inside an FMU, or None (host-side)."""
    parts = module.split(".")
    if parts == ["pogofmu"] or parts == ["pogofmu", "runtime"]:
        return ""
    if len(parts) == 2 and parts[1] in ("elements", "fmath"):
        return parts[1]
    if len(parts) >= 3 and parts[1] == "runtime" and parts[2] in _RUNTIME_MODULES:
        return ".".join(parts[2:])
    return None


class ModelSource:
    """One model to export: ``model``, its ``module`` inside the FMU's package (``models.pogo_stick``,
    ``user.ball``), the ``attr`` of that module holding it, the user's ``origin`` file (None for
    the project's models), the user ``files`` to stage (``(path in the package, original text,
    rewrite plan)``) and the third-party ``requirements`` declared for it."""

    def __init__(self, model, module: str, attr: str, origin: Optional[Path] = None, files=(),
                 requirements: Sequence[str] = (), sources: Sequence[Path] = ()):
        self.model, self.module, self.attr, self.origin = model, module, attr, origin
        self.files = list(files)
        self.sources = list(sources)  # the user's files on the host (the model file and its local modules)
        self.requirements = tuple(requirements)
        self._cls = None

    @property
    def origin_name(self) -> str:
        return self.origin.name if self.origin is not None else f"pogofmu/runtime/{self.module.replace('.', '/')}.py"

    def user_files(self) -> List[str]:
        """The files whose lines the messages about this model name: the user's, or the model's module."""
        if self.sources:
            return [str(f) for f in self.sources]
        import importlib

        mod = importlib.import_module(f"pogofmu.runtime.{self.module}")
        return [mod.__file__]

    def where(self) -> str:
        return str(self.origin) if self.origin is not None else self.model.name

    def staged_files(self, package: str) -> List[Tuple[str, str]]:
        """``(path in the package, text)`` of the user files, their imports pointing at ``package``."""
        return [(rel, rewrite(text, plan, package)) for rel, text, plan in self.files]

    def slave_class(self):
        """The FMI 2.0 slave class of the model on the host (the class the FMU's slave module defines)."""
        if self._cls is None:
            from pogofmu.runtime.fmi2 import HybridSlave

            self._cls = type(self.model.name, (HybridSlave,), {"model": self.model, "__module__": __name__})
        return self._cls


def project_sources() -> List[ModelSource]:
    """The project's own models (``pogofmu/runtime/models/``), sorted by model name."""
    from pogofmu.runtime.models import entries

    return [ModelSource(model, f"models.{module}", "MODEL") for module, model in entries()]


# ---------------------------------------------------------------------------------------------
# a user's model file
# ---------------------------------------------------------------------------------------------

def _identifier(stem: str) -> str:
    out = re.sub(r"\W", "_", stem)
    return out if out and not out[0].isdigit() else f"m_{out}"


class _Import:
    """One module a file imports: its name, the line, and what it is (``public``, ``local``,
    ``stdlib``, ``third-party``)."""

    def __init__(self, module: str, line: int, kind: str):
        self.module, self.line, self.kind = module, line, kind


def _local_path(folder: Path, top: str) -> Optional[Path]:
    for cand in (folder / f"{top}.py", folder / top / "__init__.py"):
        if cand.is_file():
            return cand
    return None


def _classify(module: str, folder: Path) -> str:
    top = module.split(".")[0]
    if top == "pogofmu":
        return "public" if _public_target(module) is not None else "host"
    if top == "__future__" or top in sys.stdlib_module_names:
        return "stdlib"
    if _local_path(folder, top) is not None:
        return "local"
    return "third-party"


def _imports(tree, folder: Path, in_package: bool, path: Path) -> List[_Import]:
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                out.append(_Import(alias.name, node.lineno, _classify(alias.name, folder)))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                if not in_package:
                    raise ModelFileError(f"{path}:{node.lineno}: a relative import in a model file: a model file is "
                                         f"imported as a top-level module; write `import {node.module or 'name'}` "
                                         f"for a module beside it")
                continue
            out.append(_Import(node.module, node.lineno, _classify(node.module, folder)))
    return out


def _line_offsets(data: bytes) -> List[int]:
    starts = [0]
    for i, b in enumerate(data):
        if b == 0x0A:
            starts.append(i + 1)
    return starts


def _plan(text: str, tree, path: Path) -> List[Tuple[int, int, str, str]]:
    """The import rewrites of one file: ``(start byte, end byte, kind, payload)`` where the text
    between is a module name (``from X import``) or an alias (``import X as Y``).  Kinds:
    ``from-public``/``from-local`` (payload: the module), ``alias-public``/``alias-local``
    (payload: ``module`` or ``module as name``)."""
    data = text.encode("utf-8")
    starts = _line_offsets(data)
    folder = path.parent
    plan = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and not node.level:
            kind = _classify(node.module, folder)
            if kind not in ("public", "local"):
                continue
            begin = starts[node.lineno - 1] + node.col_offset
            m = re.match(rb"from\s+([A-Za-z_][\w.]*)", data[begin:])
            if m is None or m.group(1).decode() != node.module:
                raise ModelFileError(f"{path}:{node.lineno}: write `from {node.module} import ...` with the module "
                                     f"name on the line of `from` (the exporter rewrites it for the FMU)")
            plan.append((begin + m.start(1), begin + m.end(1), f"from-{kind}", node.module))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                kind = _classify(alias.name, folder)
                if kind not in ("public", "local"):
                    continue
                begin = starts[alias.lineno - 1] + alias.col_offset
                end = starts[alias.end_lineno - 1] + alias.end_col_offset
                payload = alias.name + (f" as {alias.asname}" if alias.asname else "")
                plan.append((begin, end, f"alias-{kind}", payload))
    return sorted(plan)


def _target(kind: str, module: str, package: str) -> str:
    if kind == "public":
        sub = _public_target(module)
        return package + (f".{sub}" if sub else "")
    return f"{package}.user.{module}"


def rewrite(text: str, plan, package: str) -> str:
    """``text`` with the imports of ``plan`` pointing at the FMU's private ``package``."""
    data = text.encode("utf-8")
    out, pos = [], 0
    for k, (begin, end, kind, payload) in enumerate(plan):
        out.append(data[pos:begin])
        what, _, scope = kind.partition("-")
        if what == "from":
            new = _target(scope, payload, package)
        else:
            module, _, asname = payload.partition(" as ")
            target = _target(scope, module, package)
            top = module.split(".")[0]
            if asname:
                new = f"{target} as {asname}"
            elif "." not in module:
                new = f"{target} as {top}"
            else:  # ``import a.b`` binds ``a`` and loads ``a.b``
                new = f"{target} as _pogofmu_import_{k}, {_target(scope, top, package)} as {top}"
        out.append(new.encode("utf-8"))
        pos = end
    out.append(data[pos:])
    return b"".join(out).decode("utf-8")


def _parse(path: Path) -> Tuple[str, ast.AST]:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelFileError(f"{path}: cannot read the model file: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        return text, ast.parse(text, filename=str(path))
    except SyntaxError as exc:
        raise ModelFileError(f"{path}:{exc.lineno}: syntax error: {exc.msg}") from None


def user_frame(tb, files) -> Optional[traceback.FrameSummary]:
    """The innermost frame of a traceback in one of ``files`` (the user's), or None."""
    names = {os.path.abspath(str(f)) for f in files}
    found = None
    for frame in traceback.extract_tb(tb):
        if os.path.abspath(frame.filename) in names:
            found = frame
    return found


def describe_exception(exc: BaseException, files, fallback: str) -> str:
    """``file:line: Type: message`` at the user's innermost line of ``exc`` (or ``fallback:``)."""
    frame = user_frame(exc.__traceback__, files)
    where = f"{frame.filename}:{frame.lineno}" if frame else fallback
    return f"{where}: {type(exc).__name__}: {exc}"


class _FileSet:
    """The user files of one model file: the file itself and the local modules it imports (closed
    over their own imports), with their import rewrites."""

    def __init__(self, path: Path, allowed: Sequence[str]):
        self.path = path
        self.folder = path.parent
        self.allowed = set(allowed)
        self.entries: List[Tuple[str, str, list]] = []  # (path in the package, text, plan)
        self.sources: List[Path] = []
        self.requirements: List[str] = []
        self.local_names: List[str] = []
        self._seen: set = set()
        self.stem = _identifier(path.stem)
        self._add(path, f"user/{self.stem}.py", in_package=False)

    def _add(self, file: Path, rel: str, in_package: bool):
        file = file.resolve()
        if file in self._seen:
            return
        self._seen.add(file)
        text, tree = _parse(file)
        self.sources.append(file)
        for imp in _imports(tree, self.folder, in_package, file):
            top = imp.module.split(".")[0]
            if imp.kind == "host":
                raise ModelFileError(f"{file}:{imp.line}: `{imp.module}` is host-side pogofmu code, not available "
                                     f"inside an FMU: a model file imports pogofmu (HybridModel, Event, ...), "
                                     f"pogofmu.elements and pogofmu.fmath")
            if imp.kind == "third-party":
                if top not in self.allowed:
                    raise ModelFileError(
                        f"{file}:{imp.line}: import of the third-party module {top!r}: an FMU carries the standard "
                        f"library, pogofmu and the model's local modules only; pass --requires {top} to export it "
                        f"anyway (recorded in the FMU's documentation: the target's Python must have it; the "
                        f"native FMUs cannot call it)")
                if top not in self.requirements:
                    self.requirements.append(top)
            if imp.kind == "local":
                self._add_local(top)
        self.entries.append((rel, text, _plan(text, tree, file)))

    def _add_local(self, top: str):
        found = _local_path(self.folder, top)
        if found.name == "__init__.py":
            for file in sorted(found.parent.rglob("*.py")):
                if "__pycache__" not in file.parts:
                    rel = file.relative_to(self.folder).as_posix()
                    self._add(file, f"user/{rel}", in_package=True)
        else:
            self._add(found, f"user/{top}.py", in_package=False)
        if top not in self.local_names:
            self.local_names.append(top)

    def staged(self):
        return [("user/__init__.py", '"""The user\'s model file and its local modules (staged by pogofmu export)."""\n',
                 [])] + self.entries


def load_model_file(path, names: Sequence[str] = (), requires: Sequence[str] = ()) -> List[ModelSource]:
    """The models of a user's model file: ``MODEL`` if it defines one and ``names`` is empty, else its
    :class:`HybridModel` s (module-level), those named in ``names`` if given.  Mistakes are
    :class:`ModelFileError` s naming the file and the line."""
    from pogofmu.runtime.model import HybridModel

    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such model file")
    if path.suffix != ".py":
        raise ModelFileError(f"{path}: a model file is a Python file (.py)")
    path = path.resolve()
    files = _FileSet(path, requires)
    module = _import_user_module(path, files)
    found: Dict[str, Tuple[str, object]] = {}
    for attr, value in vars(module).items():
        if isinstance(value, HybridModel):
            found.setdefault(value.name, (attr, value))
    if names:
        missing = [n for n in names if n not in found and not isinstance(getattr(module, n, None), HybridModel)]
        if missing:
            raise ModelFileError(f"{path}: no model {', '.join(map(repr, missing))} in the file; its models are "
                                 f"{', '.join(sorted(found)) or 'none'}")
        picked = []
        for n in names:
            if n in found:
                picked.append(found[n])
            else:
                picked.append((n, getattr(module, n)))
    elif isinstance(getattr(module, "MODEL", None), HybridModel):
        picked = [("MODEL", module.MODEL)]
    elif found:
        picked = sorted(found.values(), key=lambda e: e[1].name)
    else:
        raise ModelFileError(f"{path}: the file defines no HybridModel (write MODEL = HybridModel(...))")
    staged = files.staged()
    return [ModelSource(model, f"user.{files.stem}", attr, path, staged, files.requirements, files.sources)
            for attr, model in picked]


def _local_path_index() -> int:
    """Where a model file's folder goes on ``sys.path`` while the file loads: after the standard
    library, before the installed packages. A module beside the model named as a standard module
    (``platform.py``, ``random.py``) must not stand in for it on the host, for the model's own
    ``import random`` or for a library that imports it then: inside the FMU the standard module is
    the one imported (only the local modules the file imports are staged with it). A local module
    still comes before an installed package of its name, as inside the FMU."""
    for k, entry in enumerate(sys.path):
        if "site-packages" in entry or "dist-packages" in entry:
            return k
    return len(sys.path)


def _import_user_module(path: Path, files: _FileSet):
    """Import the model file as a module of its own on the host, with its folder on the path for
    its local modules (removed afterwards, as are the local modules from ``sys.modules``: two model
    files may each have a ``helpers.py``)."""
    digest = hashlib.sha256(str(path).encode()).hexdigest()[:10]
    name = f"_pogofmu_user_{files.stem}_{digest}"
    for local in files.local_names:
        for key in [k for k in sys.modules if k == local or k.startswith(local + ".")]:
            del sys.modules[key]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(_local_path_index(), str(path.parent))
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except ModelFileError:
        raise
    except BaseException as exc:  # noqa: BLE001 - any mistake of the file: one line naming it
        sys.modules.pop(name, None)
        if isinstance(exc, KeyboardInterrupt):
            raise
        raise ModelFileError(describe_exception(exc, files.sources, str(path))) from None
    finally:
        try:
            sys.path.remove(str(path.parent))
        except ValueError:
            pass
    return module
