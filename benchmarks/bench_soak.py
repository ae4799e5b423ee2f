#!/usr/bin/env python3
"""Soak benchmark: peak memory of the SSP master over 10^4, 10^5, 10^6 steps.

Each run is a fresh process running the user's command,
``python -m pogofmu.ssp run SpaceHopper.ssp --stop-time T --step 1e-3 --quiet --out TMP``
(the package's bound parameter set, Earth: the hopper hops and events happen all along), and its
peak resident set size is read from the kernel when it ends (``os.wait4``, ``ru_maxrss``): CSV
written, figure drawn, everything counted. Peers measured in the same run:

* ``baseline``: the same command for 10 steps: the memory of the master before the run (Python,
  numpy, fmpy, matplotlib, two FMUs loaded, a figure drawn). ``growth`` = peak - baseline is
  what the run's length costs;
* ``fmpy``: ``fmpy.ssp.simulation.simulate_ssp`` on the same package and grid (fmpy's own SSP
  demonstrator: results kept in memory, no CSV, no figure), also in a fresh process.

Target: the master's peak at 10^6 steps <= 150 MB (exit status 1 if missed). The SpaceHopper.ssp
is built into a temporary folder (never into dist/). The 10^6-step runs take minutes.

    python benchmarks/bench_soak.py [--sizes 10000 100000 1000000] [--no-fmpy]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

STEP = 1e-3
TARGET_MB = 150.0
FMPY_PEER = """
import sys
from fmpy.ssp.simulation import simulate_ssp
res = simulate_ssp(sys.argv[1], stop_time=float(sys.argv[2]), step_size=float(sys.argv[3]))
# its loop adds the step to the time: the last point may fall one step short of the stop time
assert abs(res["time"][-1] - float(sys.argv[2])) <= 1.5 * float(sys.argv[3]), res["time"][-1]
"""


def peak_rss(cmd, cwd) -> tuple:
    """(peak RSS [MB], wall time [s]) of a fresh process running ``cmd``; raises if it fails."""
    with tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)  # reaps it: the kernel's account of this process only
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            err.seek(0)
            raise RuntimeError(f"{' '.join(map(str, cmd))} failed:\n{err.read().decode()[-2000:]}")
    return usage.ru_maxrss / 1024.0, wall  # ru_maxrss is in KiB on Linux


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--no-fmpy", action="store_true", help="skip the fmpy simulate_ssp peer")
    args = ap.parse_args(argv)
    from pogofmu.exporter import build_project

    with tempfile.TemporaryDirectory(prefix="pogofmu_soak_") as tmp:
        tmp = Path(tmp)
        import contextlib
        import io

        with contextlib.redirect_stdout(io.StringIO()):
            build_project(tmp / "dist", ssp_dir=ROOT / "ssp", cache=ROOT / "build" / "native")
        ssp = tmp / "dist" / "SpaceHopper.ssp"

        def master(n):
            out = tmp / f"out{n}"
            mb, wall = peak_rss([sys.executable, "-m", "pogofmu.ssp", "run", str(ssp), "--stop-time",
                                 repr(n * STEP), "--step", repr(STEP), "--quiet", "--out", str(out)], tmp)
            csv_mb = sum(f.stat().st_size for f in out.glob("*.csv")) / 1e6
            return mb, wall, csv_mb

        base, _, _ = master(10)
        print(f"SpaceHopper.ssp (bound set: Earth), step {STEP:g} s; peak RSS of a fresh process each")
        print(f"baseline (master, 10 steps): {base:.1f} MB")
        print(f"{'steps':>9} {'master MB':>10} {'growth MB':>10} {'CSV MB':>8} {'time s':>7} "
              f"{'fmpy MB':>8} {'fmpy s':>7} {'master/fmpy':>11}")
        worst = None
        for n in args.sizes:
            mb, wall, csv_mb = master(n)
            if args.no_fmpy:
                fm, fw, ratio = float("nan"), float("nan"), float("nan")
            else:
                fm, fw = peak_rss([sys.executable, "-c", FMPY_PEER, str(ssp), repr(n * STEP), repr(STEP)], tmp)
                ratio = mb / fm
            print(f"{n:>9} {mb:>10.1f} {mb - base:>10.1f} {csv_mb:>8.1f} {wall:>7.1f} {fm:>8.1f} {fw:>7.1f} "
                  f"{ratio:>11.2f}", flush=True)
            if n == max(args.sizes):
                worst = mb
        ok = worst <= TARGET_MB
        print(f"target: master peak at {max(args.sizes)} steps {worst:.1f} MB <= {TARGET_MB:g} MB: "
              f"{'met' if ok else 'MISSED'}")
        return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
