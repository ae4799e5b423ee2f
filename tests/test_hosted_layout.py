"""The Python-hosted FMUs' ctypes mirror of the adapter agrees with its C: ``PgVar`` and ``PgFmu`` of
pg_instance.h, read from a C program compiled against that header by this machine's compiler (each
struct's size, every field's offset and size), equal ``pogofmu.runtime.hosted``'s structures. The
mirror is kept by hand: a field added, removed, moved or retyped on one side only fails here (before
it would corrupt the variable table of every Python-hosted FMU)."""
import ctypes
import re
import subprocess
from pathlib import Path

import pytest

from pogofmu.codegen.build import _run_cc, c_compiler
from pogofmu.runtime import hosted
from support import require

pytestmark = pytest.mark.own_fmus  # (needs no FMU)

NATIVE = Path(hosted.__file__).resolve().parents[2] / "native"
HEADER = NATIVE / "adapter" / "pg_instance.h"
STRUCTS = {"PgVar": hosted.PgVar, "PgFmu": hosted.PgFmu}


def _c_layout(tmp_path):
    cc = c_compiler()
    require(cc is not None, "a C compiler (gcc, or the ziglang package)")
    lines = [f'#include "{HEADER}"', "#include <stddef.h>", "#include <stdio.h>", "int main(void) {"]
    for t, s in STRUCTS.items():
        lines.append(f'    printf("{t} sizeof %zu\\n", sizeof({t}));')
        for f, _ in s._fields_:
            lines.append(f'    printf("{t} {f} %zu %zu\\n", offsetof({t}, {f}), sizeof((({t} *)0)->{f}));')
    lines += ["    return 0;", "}"]
    src = tmp_path / "layout.c"
    src.write_text("\n".join(lines) + "\n")
    exe = tmp_path / "layout"
    r = _run_cc(cc, [str(src), f"-I{NATIVE}", f"-I{NATIVE / 'engine'}", f"-I{NATIVE / 'adapter'}", "-o", str(exe)])
    assert r.returncode == 0, r.stderr[-3000:]
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    return {(t, f): tuple(int(v) for v in rest) for t, f, *rest in (line.split() for line in out.splitlines())}


def test_pgvar_and_pgfmu_match_the_c_header(tmp_path):
    c = _c_layout(tmp_path)
    for t, s in STRUCTS.items():
        assert c[t, "sizeof"] == (ctypes.sizeof(s),), t
        for name, ctype in s._fields_:
            assert c[t, name] == (getattr(s, name).offset, ctypes.sizeof(ctype)), f"{t}.{name} (offset, size)"


@pytest.mark.parametrize("t", STRUCTS)
def test_the_struct_names_every_field_of_the_c_struct(t):
    """The other direction: the C struct declares exactly the ctypes fields, in order (a field the
    Python side does not know would shift nothing if it came last, and would never be filled)."""
    text = HEADER.read_text()
    body = text[text.index(f"typedef struct {t} {{"):text.index(f"}} {t};")]
    body = re.sub(r"/\*.*?\*/", "", body, flags=re.S)
    declared = re.findall(r"\**\s*([A-Za-z_]\w*)\s*(?=[;,])", body.split("{", 1)[1])
    assert declared == [name for name, _ in STRUCTS[t]._fields_]
