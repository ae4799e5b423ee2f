"""Benchmark (g)'s independent limit, ``benchmarks/c/dopri5_pogostick.c`` (a hand-written C
Dormand-Prince 5(4) of the basic pogo stick, no code of the project's engine), computes what the
native PogoStick FMU computes: the same 19 events of the default experiment, each within 1e-6 s of
the FMU's (what rel_tol = 1e-6 allows; both locate the events on DOPRI5's continuous extension),
the same y on the 1 ms grid, and both near the closed-form event times. A limit that solves another
problem, or solves it less accurately, would measure nothing. The same holds for its FMU_DUTIES
build (the FMU's seven states, every state and output served at every point), which the benchmark
prints for information."""
import csv
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pogofmu.codegen.build import _run_cc, c_compiler
from support import fmu_path, require

HERE = Path(__file__).resolve().parent
SOURCE = HERE.parent / "benchmarks" / "c" / "dopri5_pogostick.c"
CLOSED_FORM = HERE / "data" / "pogo_basic_events.csv"
STOP, STEP = 10.0, 1e-3


BUILDS = pytest.mark.parametrize("defines", [[], ["-DFMU_DUTIES"]], ids=["limit", "fmu-duties"])


def _dopri5(tmp_path, defines=()):
    cc = c_compiler()
    require(cc is not None, "a C compiler (gcc, or the ziglang package)")
    exe = tmp_path / "dopri5_pogostick"
    r = _run_cc(cc, ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", *defines, str(SOURCE), "-o", str(exe), "-lm"])
    assert r.returncode == 0, r.stderr[-3000:]
    return exe


def _events(out: str):
    rows = [line.split() for line in out.splitlines() if line.startswith("event ")]
    return [(kind, float(t)) for _, _, kind, _, _, t in rows]


def _fmu_run():
    from fmpy import simulate_fmu

    res = simulate_fmu(str(fmu_path("native/PogoStick")), stop_time=STOP, output_interval=STEP,
                       output=["y", "n_events", "t_last_event", "last_event"])
    changed = np.nonzero(np.diff(res["n_events"]))[0] + 1
    assert np.all(np.diff(res["n_events"]) <= 1), "two events in one communication step: not read this way"
    kinds = {1: "touchdown", 2: "liftoff"}
    return res, [(kinds[int(res["last_event"][i])], float(res["t_last_event"][i])) for i in changed]


@BUILDS
def test_the_hand_written_dopri5_finds_the_fmus_events(tmp_path, defines):
    exe = _dopri5(tmp_path, defines)
    out = subprocess.run([str(exe), repr(STOP), repr(STEP), "1"], capture_output=True, text=True, check=True).stdout
    mine = _events(out)
    res, theirs = _fmu_run()
    assert len(mine) == len(theirs) == 19, (mine, theirs)
    assert [k for k, _ in mine] == [k for k, _ in theirs]
    gaps = [abs(a - b) for (_, a), (_, b) in zip(mine, theirs)]
    assert max(gaps) <= 1e-6, gaps
    # both are DOPRI5 at rel_tol 1e-6 of the same equations: near the exact (closed-form) times too
    with open(CLOSED_FORM) as f:
        exact = [float(row["time_s"]) for row in csv.DictReader(line for line in f if not line.startswith("#"))]
    assert len(exact) == 19
    assert max(abs(a - e) for (_, a), e in zip(mine, exact)) <= 1e-6


@BUILDS
def test_the_hand_written_dopri5_records_the_fmus_y(tmp_path, defines):
    """The checksum of its y on the grid is the FMU's: the same 10001 points, to the accuracy of
    the tolerance (and the same y at the stop time)."""
    exe = _dopri5(tmp_path, defines)
    out = subprocess.run([str(exe), repr(STOP), repr(STEP), "2"], capture_output=True, text=True, check=True).stdout
    line = next(line for line in out.splitlines() if line.startswith("y checksum"))
    checksum = float(line.split()[2].rstrip(","))
    y_stop = float(line.split("= ")[1])
    res, _ = _fmu_run()
    assert len(res) == 10001
    assert abs(checksum - float(np.sum(res["y"]))) <= 1e-6 * len(res)
    assert abs(y_stop - float(res["y"][-1])) <= 1e-6
    assert "recorded 10001 points, 19 events, loop cpu" in out
