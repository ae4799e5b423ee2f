"""The SSP master's C level stepping (fmu_src/native/master/pg_level.c) on its own: its thread
pool (workers that poll, then sleep; a batch the caller closes) and its macro step of several
levels (pgm_run_levels), driven by stand-in components in C (tests/c_host/level_pool.c).

The driver compares, to the bit, the value array after 200 macro steps of two levels (the second
fed lines of the first's outputs) on 2, 3 and 4 threads with a run without a pool, three times
each, and checks that a component failing on any thread stops the call after its level with its
code. Built once with ThreadSanitizer (a data race ends the run: exit code 66), once optimized
(-O2, the build the master uses).
"""
from __future__ import annotations

import os
import shutil
import subprocess

import pytest
from support import ROOT, needs

from pogofmu.codegen.build import ENGINE, MASTER

CC = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")
DRIVER = ROOT / "tests" / "c_host" / "level_pool.c"


def _build(tmp_path, flags):
    exe = tmp_path / "level_pool"
    proc = subprocess.run([CC, *flags, "-Wall", "-Wextra", f"-I{MASTER}", f"-I{ENGINE}", str(DRIVER), "-o", str(exe), "-lm",
                           "-pthread"], capture_output=True, text=True)
    return exe if proc.returncode == 0 else proc.stderr


def _run(exe, **env):
    proc = subprocess.run([str(exe)], capture_output=True, text=True, timeout=600, env={**os.environ, **env})
    return proc.returncode, proc.stdout + proc.stderr


@needs(CC is not None, "C compiler (gcc)")
def test_the_pool_gives_one_threads_bits_without_a_race(tmp_path):
    exe = _build(tmp_path, ["-O1", "-g", "-fsanitize=thread"])
    if isinstance(exe, str):  # gcc's ThreadSanitizer (libtsan) comes with Debian's gcc
        pytest.fail(f"{CC} cannot build with -fsanitize=thread: {exe[-1500:]}")
    code, out = _run(exe, TSAN_OPTIONS="halt_on_error=1")
    assert code == 0 and out.strip().endswith("ok"), out[-3000:]


@needs(CC is not None, "C compiler (gcc)")
def test_the_optimized_pool_gives_one_threads_bits(tmp_path):
    exe = _build(tmp_path, ["-O2"])
    assert not isinstance(exe, str), exe
    code, out = _run(exe)
    assert code == 0 and out.strip() == "ok", out[-3000:]
