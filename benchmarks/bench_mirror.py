#!/usr/bin/env python3
"""The SSP master at scale: native segmented mirrors of 1 and 4 rings (15 and 123 FMUs).

Each figure is a fresh process running the user's command, ``pogofmu ssp run M.ssp --step 1e-3
--stop-time T --threads N --quiet --out TMP`` (``pogofmu.ssp.cli.run``, the CSV of every
connector written as the user gets it), with two things changed: its figure is not drawn (a
matplotlib drawing of a fixed size, not a cost per step), and the wall time from the run's first
row (the initialization at t = 0 done) to the CSV's close is taken in the process: the macro
steps with their recording, no start-up (unpacking, loading 123 FMUs) in it. Its peak RSS comes
from the kernel (``os.wait4``). Ratios are against a peer in the same run, runs alternated, the
fastest of ``--repeat`` kept (the machine's load only adds):

1. cost per macro step per FMU of 4 rings relative to 1 ring; target <= 1.3;
2. ``--threads 2`` against ``--threads 1`` on the 4-ring package; target >= 1.6x on 2 idle cores.

Beside them, what the machine's two cores give: two processes of a plain arithmetic loop against
one (a shared VM's two vCPUs give less than 2).

A 12-ring native mirror (939 FMUs) builds and runs (docs/performance.md, "12 rings"), but its
export takes ~9 min of CPU, so it is not one of these cases. The packages are generated into a
temporary folder (``--packages DIR`` reuses ``DIR/m1.ssp``, ``DIR/m4.ssp``; the 4-ring export
takes minutes).

    python benchmarks/bench_mirror.py [--stop 0.5] [--repeat 3] [--packages DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_soak import peak_rss

RINGS = {1: 15, 4: 123}


class _Timed:
    """The run's recorder with the time of its first row and of its close noted."""

    def __init__(self, inner, marks):
        self.__dict__["_inner"], self.__dict__["_marks"] = inner, marks

    def add(self, row):
        if not self._marks:
            self._marks.append(time.perf_counter())
        self._inner.add(row)

    def bind_slots(self, *args):  # the C path's rows (CSVStream.bind_slots): timed as add
        put = self._inner.bind_slots(*args)
        if put is None:
            return None

        def timed_put(*row):
            if not self._marks:
                self._marks.append(time.perf_counter())
            return put(*row)
        return timed_put

    def close(self, complete=True):
        self._inner.close(complete)
        if len(self._marks) == 1:
            self._marks.append(time.perf_counter())

    def __getattr__(self, name):
        return getattr(self._inner, name)


def child(ssp, stop, threads, out):
    """In the fresh process: the user's command, timed from its first row to its close."""
    from pogofmu.ssp import cli

    marks = []
    simulate = cli.simulate

    def timed(*args, sink=None, **kw):
        return simulate(*args, sink=lambda *a: _Timed(sink(*a), marks), **kw)
    cli.simulate, cli.plot = timed, lambda *a, **k: None
    cli.run(ssp, stop_time=stop, step=1e-3, out=out, progress=False, threads=threads)
    print(json.dumps({"loop": marks[1] - marks[0]}))


def run(ssp, stop, threads, tmp):
    """(loop wall time [s], peak RSS [MB]) of one fresh process."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import bench_mirror; "
            f"bench_mirror.child({str(ssp)!r}, {stop!r}, {threads}, {str(tmp / 'out')!r})")
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen([sys.executable, "-c", code], cwd=tmp, stdout=out, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            err.seek(0)
            raise RuntimeError(f"the run of {ssp} failed:\n{err.read().decode()[-2000:]}")
        out.seek(0)
        loop = json.loads(out.read().decode().strip().splitlines()[-1])["loop"]
    return loop, usage.ru_maxrss / 1024.0


SPIN = "s = 0.0\nfor i in range(6_000_000):\n    s += i * 1e-9\n"


def machine_scaling(repeat=3) -> float:
    """What two cores give here: the throughput of two processes of a plain arithmetic loop run
    together against one alone (2.0 on two idle physical cores; less on shared vCPUs)."""
    def wall(n):
        t0 = time.perf_counter()
        procs = [subprocess.Popen([sys.executable, "-c", SPIN]) for _ in range(n)]
        for p in procs:
            p.wait()
        return time.perf_counter() - t0
    one = min(wall(1) for _ in range(repeat))
    two = min(wall(2) for _ in range(repeat))
    return 2 * one / two


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stop", type=float, default=0.5, help="simulated time of each run [s]")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--packages", type=Path)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_mirror_") as tmp:
        tmp = Path(tmp)
        pkgs = args.packages or tmp
        for r in RINGS:
            if not (pkgs / f"m{r}.ssp").exists():
                cmd = [sys.executable, "-m", "pogofmu.cli", "ssp", "mirror", "--rings", str(r), "--backend",
                       "native", "--out", str(pkgs / f"m{r}.ssp")]
                peak_rss(cmd, tmp)
        cases = [(1, 1), (4, 1), (4, 2)]
        best = {c: float("inf") for c in cases}
        peak = {c: 0.0 for c in cases}
        for _ in range(args.repeat):  # alternated
            for c in cases:
                loop, rss = run(pkgs / f"m{c[0]}.ssp", args.stop, c[1], tmp)
                best[c], peak[c] = min(best[c], loop), max(peak[c], rss)
        steps = round(args.stop / 1e-3)
        print(f"native mirrors, step 1e-3 s, {steps} macro steps (events synchronized, Gauss-Seidel, "
              f"every connector recorded), best of {args.repeat}")
        print(f"{'rings':>5} {'FMUs':>5} {'threads':>7} {'loop s':>8} {'us/step/FMU':>12} {'peak MB':>8}")
        per = {}
        for (r, th) in cases:
            per[r, th] = best[r, th] / steps / RINGS[r] * 1e6
            print(f"{r:>5} {RINGS[r]:>5} {th:>7} {best[r, th]:>8.3f} {per[r, th]:>12.1f} {peak[r, th]:>8.1f}")
        scale = per[4, 1] / per[1, 1]
        speed = best[4, 1] / best[4, 2]
        print(f"(1) cost per step per FMU, 4 rings / 1 ring: {scale:.2f} (target <= 1.3: "
              f"{'holds' if scale <= 1.3 else 'missed'})")
        print(f"(2) 4 rings, --threads 2 speed-up over --threads 1: {speed:.2f}x (target >= 1.6x: "
              f"{'holds' if speed >= 1.6 else 'missed'})")
        print(f"the machine: two processes of an arithmetic loop at {machine_scaling():.2f}x the throughput "
              f"of one (the bound of any two-thread speed-up here)")
        load = os.getloadavg()
        print(f"load average during the runs (1, 5, 15 min): {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    return 0 if scale <= 1.3 and speed >= 1.6 else 1


if __name__ == "__main__":
    sys.exit(main())
