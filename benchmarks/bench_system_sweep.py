#!/usr/bin/env python3
"""Benchmark: ``pogofmu sweep SYSTEM.ssp`` on Dask against direct in-process master runs.

The native SpaceHopper (dist/native/SpaceHopper.ssp, its default bindings), ``--stop-time`` s
(default 10) at the master's 1 ms step, over a grid of the PogoStick's stiffness ``k`` from 80 to
120 N/m (every run differs):

* **direct**: :func:`pogofmu.ssp.master.simulate` of every point in this process, one after the
  other (what a hand-written loop around the master costs), ``--compare`` points (default 100);
* **sweep, 1 worker**: the same points through the sweep machinery (:func:`pogofmu.sweep.run_sweep`
  of a :class:`~pogofmu.sweep.system.SystemSweep`: Dask tasks of chunks, the summaries, the
  Parquet part files, the final table) on a local cluster of one worker process. The cluster's
  start is timed apart and not counted (paid once per sweep, not per run); sending the package to
  the worker is counted;
* **sweep, 2 workers**: ``--runs`` points (default 1000) on two worker processes.

Printed: wall and CPU time of each, per run; the per-run CPU cost of the sweep (every process:
this one, which holds the client and the scheduler, the nanny and the worker) over the direct
run's (target <= 1.2x); the 2-worker sweep's runs per second. The variants of the comparison run in
``--repeat`` rounds (default 2), the best of each counts. Exit status 1 if a target is missed.

    python benchmarks/bench_system_sweep.py [--runs 1000] [--compare 40] [--stop-time 10]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

COST_TARGET = 1.2

from bench_sweep import _cpu, _family  # noqa: E402  (the CPU of a process family, as in benchmark (c))


def ks(n):
    return [80.0 + 40.0 * i / max(1, n - 1) for i in range(n)]


def direct(ssp: Path, points, stop_time):
    from pogofmu.ssp.master import simulate

    t0, c0 = time.perf_counter(), time.process_time()
    for k in points:
        simulate(ssp, stop_time=stop_time, echo_log=False, overrides={"PogoStick.k": k})
    return time.perf_counter() - t0, time.process_time() - c0


def _import_worker_side():
    import pogofmu.ssp.master  # noqa: F401
    import pogofmu.sweep.system  # noqa: F401


def swept(ssp: Path, points, stop_time, workers: int, out: Path):
    from pogofmu.sweep import close_cluster, open_cluster, run_sweep
    from pogofmu.sweep.system import SystemSettings, SystemSweep

    client, cluster = open_cluster(workers=workers)
    client.wait_for_workers(workers)
    client.run(_import_worker_side)
    pids = _family()
    try:
        sweep = SystemSweep(str(ssp), ["PogoStick.k"], [(k,) for k in points], SystemSettings(stop_time=stop_time),
                            str(out))
        t0, c0 = time.perf_counter(), _cpu(pids)
        run_sweep(sweep, client, overwrite=True, progress=False, log=lambda *a: None)
        wall, cpu = time.perf_counter() - t0, _cpu(pids) - c0
    finally:
        close_cluster(client, cluster)
    return wall, cpu


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ssp", default=str(ROOT / "dist" / "native" / "SpaceHopper.ssp"))
    ap.add_argument("--runs", type=int, default=1000, help="runs of the 2-worker sweep (default 1000)")
    ap.add_argument("--compare", type=int, default=100, help="runs of the direct / 1-worker comparison (default 100)")
    ap.add_argument("--stop-time", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args(argv)
    ssp = Path(args.ssp)
    if not ssp.is_file():
        print(f"{ssp}: no such file (python3 tasks.py build)", file=sys.stderr)
        return 2
    import pyarrow.parquet as pq

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        pts = ks(args.compare)
        best = {"direct": (float("inf"),) * 2, "sweep, 1 worker": (float("inf"),) * 2}
        for _ in range(args.repeat):
            for name in best:
                got = direct(ssp, pts, args.stop_time) if name == "direct" else \
                    swept(ssp, pts, args.stop_time, 1, tmp / "one.parquet")
                best[name] = tuple(min(a, b) for a, b in zip(best[name], got))
        print(f"SpaceHopper (native), {args.stop_time:g} s at 1 ms, {args.compare} runs:")
        print(f"  {'':20s}{'wall':>9s}{'per run':>10s}{'CPU':>9s}{'per run':>10s}")
        for name, (wall, cpu) in best.items():
            print(f"  {name:20s}{wall:8.2f}s{1e3 * wall / len(pts):8.1f}ms{cpu:8.2f}s{1e3 * cpu / len(pts):8.1f}ms")
        ratio = best["sweep, 1 worker"][1] / best["direct"][1]
        print(f"sweep per-run CPU / direct master run: {ratio:.3f} (target <= {COST_TARGET})")
        big = ks(args.runs)
        wall, cpu = swept(ssp, big, args.stop_time, 2, tmp / "big.parquet")
        rows = pq.read_table(tmp / "big.parquet", columns=["status"]).column("status").to_pylist()
        print(f"{args.runs} runs on 2 workers: {wall:.1f} s wall ({args.runs / wall:.2f} runs/s), {cpu:.1f} s CPU, "
              f"{rows.count('ok')} ok")
    return 0 if ratio <= COST_TARGET and rows.count("ok") == args.runs else 1


if __name__ == "__main__":
    sys.exit(main())
