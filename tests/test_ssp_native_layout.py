"""The master's C level and its ctypes binding agree: ``pgm_comp``'s layout (every field's offset
and the struct's size) and the enums of pg_level.c, read from a C program compiled from that
source by this machine's compiler, equal ``pogofmu.ssp.native_level``'s ``PgmComp`` and constants.
A field added, removed, moved or retyped on one side only fails here (before it would corrupt a
run's values)."""
import subprocess
from pathlib import Path

import pytest

from pogofmu.codegen.build import _run_cc, c_compiler
from pogofmu.ssp import native_level
from support import require

pytestmark = pytest.mark.own_fmus  # (needs no FMU)

MASTER = Path(native_level.__file__).resolve().parents[2] / "native" / "master"
ENUMS = ["OP_FEED", "OP_SAVE", "OP_STEP", "OP_READ", "CALL_SET_REAL", "CALL_SAVE", "CALL_STEP", "CALL_GET_REAL",
         "CALL_SET_INT", "CALL_GET_INT", "CALL_SET_DERIV"]


def _c_layout(tmp_path):
    cc = c_compiler()
    require(cc is not None, "a C compiler (gcc, or the ziglang package)")
    fields = [name for name, _ in native_level.PgmComp._fields_]
    lines = [f'#include "{MASTER / "pg_level.c"}"', f'#include "{MASTER / "pg_csv.c"}"',
             f'#include "{MASTER.parent / "engine" / "pg_repr.c"}"', "#include <stddef.h>",
             "#include <stdio.h>", "int main(void) {", '    printf("sizeof %zu\\n", sizeof(pgm_comp));']
    lines += [f'    printf("{f} %zu\\n", offsetof(pgm_comp, {f}));' for f in fields]
    lines += [f'    printf("{e} %d\\n", (int){e});' for e in ENUMS]
    lines += ["    return 0;", "}"]
    src = tmp_path / "layout.c"
    src.write_text("\n".join(lines) + "\n")
    exe = tmp_path / "layout"
    r = _run_cc(cc, [str(src), f"-I{MASTER.parent / 'engine'}", "-o", str(exe), "-lpthread", "-lm"])
    assert r.returncode == 0, r.stderr[-3000:]
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    return {k: int(v) for k, v in (line.split() for line in out.splitlines())}


def test_pgm_comp_and_the_enums_match_the_c_source(tmp_path):
    c = _c_layout(tmp_path)
    s = native_level.PgmComp
    assert c["sizeof"] == __import__("ctypes").sizeof(s)
    for name, _ in s._fields_:
        assert c[name] == getattr(s, name).offset, name
    for e in ENUMS:
        assert c[e] == getattr(native_level, e), e


def test_the_struct_names_every_field_of_the_c_struct():
    """The other direction: no field of the C struct is missing from ``PgmComp`` (a field the
    Python side does not know would shift nothing if it came last, and would never be filled)."""
    import re

    text = (MASTER / "pg_level.c").read_text()
    body = text[text.index("typedef struct {\n    void *instance;"):text.index("} pgm_comp;")]
    body = re.sub(r"/\*.*?\*/", "", body, flags=re.S)
    declared = re.findall(r"\**\s*([A-Za-z_]\w*)\s*(?=[;,])", body.split("{", 1)[1])
    assert declared == [name for name, _ in native_level.PgmComp._fields_]
