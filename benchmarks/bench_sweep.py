#!/usr/bin/env python3
"""Benchmark (c): ``pogofmu sweep`` on Dask against bare ``fmpy.simulate_fmu`` runs (issue 11).

N PogoStick runs (default 1000), 10 s at ``output_interval`` 1e-3 (10 000 communication steps),
every output recorded, a grid over the stiffness ``k`` from 80 to 120 N/m (every run differs):

* **bare**: ``fmpy.simulate_fmu(..., start_values={"k": k}, ...)`` for every point in this
  process, one after the other, (i) on the ``.fmu`` with fmpy's defaults (validation and extraction
  per run: what a hand-written loop costs) and (ii) on the FMU extracted once with its model
  description read once — the same fmpy work a sweep worker does per run, the peer of the target;
* **sweep, 1 worker** and **sweep, 2 workers**: the same points through the sweep machinery
  (``pogofmu.sweep.run_sweep``: Dask tasks of chunks, summaries, Parquet part files, the final
  table) on a local cluster of 1 and of 2 worker processes. The cluster's start (about 1 s) is
  timed apart and not counted: it is paid once per sweep, not per run.

Printed: wall time of each, the per-run overhead of the sweep (1 worker) over bare
``simulate_fmu`` (ii) (target <= 10 %), and the speed-up of 2 workers over 1 (target >= 1.8x on 2
cores). Wall time, not CPU time: the point is parallel work. The machine may be shared: run it
alone for the figures of the README. Exit status 1 if a target is missed.

    python benchmarks/bench_sweep.py [--runs 1000] [--fmu dist/PogoStick.fmu]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import scipy.integrate  # noqa: F401  (before any FMU is loaded: avoids a teardown crash, README "Known issues")

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

STOP_TIME = 10.0
STEP = 1e-3
OVERHEAD_TARGET = 0.10
SPEEDUP_TARGET = 1.8


def bare(fmu: Path, ks, extracted: bool):
    """simulate_fmu per point; extracted: on the FMU extracted once, its model description read once
    (the fmpy work a sweep worker does, without the machinery around it)."""
    import shutil

    from fmpy import extract, read_model_description, simulate_fmu

    kwargs, path = {}, str(fmu)
    if extracted:
        path = extract(str(fmu))
        kwargs = {"model_description": read_model_description(path), "validate": False}
    t0 = time.perf_counter()
    for k in ks:
        simulate_fmu(path, start_values={"k": k}, stop_time=STOP_TIME, output_interval=STEP, **kwargs)
    wall = time.perf_counter() - t0
    if extracted:
        shutil.rmtree(path, ignore_errors=True)
    return wall


def swept(fmu: Path, ks, workers: int, tmp: Path):
    from pogofmu.sweep import Settings, Sweep, close_cluster, open_cluster, run_sweep

    t0 = time.perf_counter()
    client, cluster = open_cluster(workers=workers)
    client.wait_for_workers(workers)
    t_start = time.perf_counter() - t0
    try:
        sweep = Sweep(str(fmu), ["k"], [(k,) for k in ks], Settings(stop_time=STOP_TIME, step=STEP),
                      str(tmp / f"sweep-{workers}.parquet"))
        t0 = time.perf_counter()
        run_sweep(sweep, client, progress=False, log=lambda *a: None)
        wall = time.perf_counter() - t0
    finally:
        close_cluster(client, cluster)
    return wall, t_start


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000, help="number of runs (default 1000)")
    ap.add_argument("--fmu", default=str(ROOT / "dist" / "PogoStick.fmu"))
    args, _ = ap.parse_known_args(argv)  # tasks.py bench passes every script the same options
    fmu = Path(args.fmu)
    if not fmu.is_file():
        sys.exit(f"{fmu} missing: python3 tasks.py build")
    n = args.runs
    ks = [80.0 + 40.0 * i / max(1, n - 1) for i in range(n)]
    print(f"(c) sweep on Dask vs bare simulate_fmu: {n} PogoStick runs, {STOP_TIME:g} s at {STEP:g} s, "
          "every output recorded", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        t_user = bare(fmu, ks, extracted=False)
        print(f"  bare simulate_fmu(.fmu)     {t_user:8.2f} s  {1e3 * t_user / n:7.1f} ms/run   "
              "(fmpy's defaults: extracts and validates every run)", flush=True)
        t_bare = bare(fmu, ks, extracted=True)
        print(f"  bare simulate_fmu(dir)      {t_bare:8.2f} s  {1e3 * t_bare / n:7.1f} ms/run   "
              "(extracted once: the peer of the target)", flush=True)
        t1, s1 = swept(fmu, ks, 1, Path(tmp))
        print(f"  sweep, 1 worker             {t1:8.2f} s  {1e3 * t1 / n:7.1f} ms/run   (cluster start {s1:.2f} s)",
              flush=True)
        t2, s2 = swept(fmu, ks, 2, Path(tmp))
        print(f"  sweep, 2 workers            {t2:8.2f} s  {1e3 * t2 / n:7.1f} ms/run   (cluster start {s2:.2f} s)",
              flush=True)
    overhead = t1 / t_bare - 1.0
    speedup = t1 / t2
    ok_o, ok_s = overhead <= OVERHEAD_TARGET, speedup >= SPEEDUP_TARGET
    print(f"  sweep (1 worker) against the hand-written loop on the .fmu: {100 * (t1 / t_user - 1):+.1f} %")
    print(f"  per-run overhead of the sweep (1 worker) over bare simulate_fmu (extracted once): {100 * overhead:+.1f} % "
          f"(target <= {100 * OVERHEAD_TARGET:.0f} %: {'holds' if ok_o else 'MISSED'})")
    print(f"  speed-up 2 workers / 1 worker: {speedup:.2f}x (target >= {SPEEDUP_TARGET}x: "
          f"{'holds' if ok_s else 'MISSED'})")
    return 0 if ok_o and ok_s else 1


if __name__ == "__main__":
    sys.exit(main())
