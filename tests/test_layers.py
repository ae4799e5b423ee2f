"""The layers of the package: the runtime (the code that goes into every FMU, staged under a name
private to each build) imports nothing of the host side — no exporter, code generator, SSP master,
sweep or study — at module level or inside a function. The host tells the runtime what it must know
(``cengine.set_host_library``). Read from the sources' own import statements (ast)."""
import ast
from pathlib import Path

import pytest

from support import ROOT

pytestmark = pytest.mark.own_fmus  # (needs no FMU)

RUNTIME = ROOT / "fmu_src" / "pogofmu" / "runtime"


def _imports(path: Path):
    """``(line, module)`` of every import in the file, relative ones resolved against the runtime."""
    tree = ast.parse(path.read_text(), str(path))
    package = ["pogofmu", *path.relative_to(RUNTIME.parent).parent.parts]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                yield node.lineno, ".".join(base + ([node.module] if node.module else []))
            else:
                yield node.lineno, node.module


def test_the_runtime_imports_nothing_of_the_host_side():
    files = sorted(RUNTIME.rglob("*.py"))
    assert len(files) > 10
    offenders = [f"{path.relative_to(ROOT)}:{line} imports {module}" for path in files
                 for line, module in _imports(path)
                 if module.split(".")[0] == "pogofmu" and not module.startswith("pogofmu.runtime")]
    assert not offenders, offenders
