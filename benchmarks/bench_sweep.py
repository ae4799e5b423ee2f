#!/usr/bin/env python3
"""Benchmark (c): ``pogofmu sweep`` on Dask against bare ``fmpy.simulate_fmu`` runs.

N PogoStick runs (default 1000), 10 s at ``output_interval`` 1e-3 (10 000 communication steps),
every output recorded, a grid over the stiffness ``k`` from 80 to 120 N/m (every run differs):

* **bare**: ``fmpy.simulate_fmu(..., start_values={"k": k}, ...)`` for every point in this
  process, one after the other, (i) on the ``.fmu`` with fmpy's defaults (validation and extraction
  per run: what a hand-written loop costs) and (ii) on the FMU extracted once with its model
  description read once — the same fmpy work a sweep worker does per run, the peer of the target;
* **sweep, 1 worker** and **sweep, 2 workers**: the same points through the sweep machinery
  (``pogofmu.sweep.run_sweep``: Dask tasks of chunks, summaries, Parquet part files, the final
  table) on a local cluster of 1 and of 2 worker processes. The cluster's start (about 1 s, with
  the workers' imports of fmpy and scipy) is timed apart and not counted: it is paid once per
  sweep, not per run. Sending the FMU to the workers and extracting it there are counted.

* **native**: the native FMU (dist/native/PogoStick.fmu) the same ways — through fmpy's
  Python loop (bare, extracted once) and through the sweep, whose runner drives it by the FMU's
  own C stepping loop (``pogofmu_fmi2_run_grid``); its table must equal the Python-hosted FMU's
  sweep table to the bit (every column but the run's wall time).

Printed: wall and CPU time of each; the per-run overhead of the sweep (1 worker) over bare
``simulate_fmu`` (ii) in CPU time — every CPU second the sweep costs: the worker's, and this
process's, which holds the client and the scheduler (target <= 10 %; the wall-time figure is
printed too); the speed-up of 2 workers over 1 in wall time (target >= 1.8x on 2 cores); and
the sweep's CPU seconds per run of the Python-hosted FMU over the native one's (1 worker each:
target >= 10x).
The variants run in ``--repeat`` rounds (default 3), their order rotated from round to round; the
best wall and the best CPU time of each count. The CPU of a sweep is that of every process it
involves: this one (the client and the scheduler) and all it started (the nannies, the workers).
The CPU figure stands up to other load on the machine, the speed-up does not: run it alone for
the figures of the docs. Exit status 1 if a target is missed.

    python benchmarks/bench_sweep.py [--runs 1000] [--repeat 3] [--fmu dist/PogoStick.fmu]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path


HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

STOP_TIME = 10.0
STEP = 1e-3
OVERHEAD_TARGET = 0.10
SPEEDUP_TARGET = 1.8
NATIVE_TARGET = 10.0


def bare(fmu: Path, ks, extracted: bool):
    """simulate_fmu per point; extracted: on the FMU extracted once, its model description read once
    (the fmpy work a sweep worker does, without the machinery around it)."""
    import shutil

    from fmpy import extract, read_model_description, simulate_fmu

    kwargs, path = {}, str(fmu)
    if extracted:
        path = extract(str(fmu))
        kwargs = {"model_description": read_model_description(path), "validate": False}
    t0, c0 = time.perf_counter(), time.process_time()
    for k in ks:
        simulate_fmu(path, start_values={"k": k}, stop_time=STOP_TIME, output_interval=STEP, **kwargs)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if extracted:
        shutil.rmtree(path, ignore_errors=True)
    return wall, cpu


def _cpu(pids):
    """CPU time (user + system) of these processes so far [s]."""
    import psutil

    return sum(sum(psutil.Process(pid).cpu_times()[:2]) for pid in pids)


def _family():
    """This process (client and scheduler) and every process it started (the cluster's nannies and
    workers, anything they spawned): every CPU second of a sweep."""
    import psutil

    me = psutil.Process()
    return [me.pid, *(p.pid for p in me.children(recursive=True))]


def _import_worker_side():
    import fmpy.simulation  # noqa: F401

    import pogofmu.sweep  # noqa: F401


def swept(fmu: Path, ks, workers: int, tmp: Path, name: str = ""):
    from pogofmu.sweep import Settings, Sweep, close_cluster, open_cluster, run_sweep

    t0 = time.perf_counter()
    client, cluster = open_cluster(workers=workers)
    client.wait_for_workers(workers)
    client.run(_import_worker_side)  # a fresh worker process imports fmpy, scipy, pyarrow: part of its start
    t_start = time.perf_counter() - t0
    pids = _family()  # this process (client, scheduler), the nannies, the workers
    assert set(client.run(os.getpid).values()) <= set(pids)
    try:
        sweep = Sweep(str(fmu), ["k"], [(k,) for k in ks], Settings(stop_time=STOP_TIME, step=STEP),
                      str(tmp / f"sweep-{name}{workers}.parquet"))
        t0, c0 = time.perf_counter(), _cpu(pids)
        run_sweep(sweep, client, overwrite=True, progress=False, log=lambda *a: None)  # (a later round: the same table)
        wall, cpu = time.perf_counter() - t0, _cpu(pids) - c0
    finally:
        close_cluster(client, cluster)
    return wall, cpu, t_start


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000, help="number of runs (default 1000)")
    ap.add_argument("--fmu", default=str(ROOT / "dist" / "PogoStick.fmu"))
    ap.add_argument("--native-fmu", default=str(ROOT / "dist" / "native" / "PogoStick.fmu"))
    ap.add_argument("--repeat", type=int, default=3, help="rounds of every variant, rotated (default 3)")
    args, _ = ap.parse_known_args(argv)  # tasks.py bench passes every script the same options
    fmu, native = Path(args.fmu), Path(args.native_fmu)
    for path in (fmu, native):
        if not path.is_file():
            sys.exit(f"{path} missing: python3 tasks.py build")
    n = args.runs
    ks = [80.0 + 40.0 * i / max(1, n - 1) for i in range(n)]
    print(f"(c) sweep on Dask vs bare simulate_fmu: {n} PogoStick runs, {STOP_TIME:g} s at {STEP:g} s, "
          f"every output recorded; {args.repeat} rounds, the variants rotated, the best of each counted", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        variants = {
            "bare simulate_fmu(.fmu)": (lambda: (*bare(fmu, ks, extracted=False), None),
                                        "fmpy's defaults: extracts and validates every run"),
            "bare simulate_fmu(dir)": (lambda: (*bare(fmu, ks, extracted=True), None),
                                       "extracted once: the peer of the target"),
            "sweep, 1 worker": (lambda: swept(fmu, ks, 1, Path(tmp)),
                                "CPU of this process (client, scheduler), the nanny and the worker"),
            "sweep, 2 workers": (lambda: swept(fmu, ks, 2, Path(tmp)), "CPU of every process"),
            "native: bare simulate_fmu(dir)": (lambda: (*bare(native, ks, extracted=True), None),
                                               "the native FMU through fmpy's Python loop"),
            "native: sweep, 1 worker": (lambda: swept(native, ks, 1, Path(tmp), "native-"),
                                        "the FMU's own C stepping loop"),
        }
        names = list(variants)
        walls = {k: [] for k in names}
        cpus = {k: [] for k in names}
        starts = {k: [] for k in names}
        for r in range(args.repeat):
            for name in names[r % len(names):] + names[:r % len(names)]:
                wall, cpu, start = variants[name][0]()
                walls[name].append(wall), cpus[name].append(cpu), starts[name].append(start)
        print(f"  {'':32s}{'wall':>9s} {'per run':>10s} {'CPU':>9s} {'per run':>10s}")
        for name in names:
            wall, cpu = min(walls[name]), min(cpus[name])
            start = f"; cluster start {min(starts[name]):.2f} s" if starts[name][0] is not None else ""
            print(f"  {name:32s}{wall:8.2f}s {1e3 * wall / n:7.1f} ms {cpu:8.2f}s {1e3 * cpu / n:7.1f} ms  "
                  f"{variants[name][1]}{start}", flush=True)
        best = lambda d, k: min(d[k])  # noqa: E731
        t_user, c_user = best(walls, names[0]), best(cpus, names[0])
        t_bare, c_bare = best(walls, names[1]), best(cpus, names[1])
        t1, c1 = best(walls, names[2]), best(cpus, names[2])
        t2 = best(walls, names[3])
        c_n1 = best(cpus, names[5])
        same = _same_table(Path(tmp) / "sweep-1.parquet", Path(tmp) / "sweep-native-1.parquet")
    overhead = c1 / c_bare - 1.0
    speedup = t1 / t2
    ok_o, ok_s = overhead <= OVERHEAD_TARGET, speedup >= SPEEDUP_TARGET
    print(f"  sweep (1 worker) against the hand-written loop on the .fmu: wall {100 * (t1 / t_user - 1):+.1f} %, "
          f"CPU {100 * (c1 / c_user - 1):+.1f} %")
    print(f"  per-run overhead of the sweep (1 worker) over bare simulate_fmu (extracted once): CPU "
          f"{100 * overhead:+.1f} % (target <= {100 * OVERHEAD_TARGET:.0f} %: {'holds' if ok_o else 'MISSED'}); "
          f"wall {100 * (t1 / t_bare - 1):+.1f} %")
    print(f"  speed-up 2 workers / 1 worker: {speedup:.2f}x (target >= {SPEEDUP_TARGET}x: "
          f"{'holds' if ok_s else 'MISSED'})")
    native_ratio = c1 / c_n1
    ok_n = native_ratio >= NATIVE_TARGET and same
    print(f"  sweep CPU per run, Python-hosted / native FMU: {native_ratio:.1f}x (target >= {NATIVE_TARGET:g}x: "
          f"{'holds' if native_ratio >= NATIVE_TARGET else 'MISSED'}); the tables "
          f"{'are the same to the bit' if same else 'DIFFER'} (every column but wall_s)")
    return 0 if ok_o and ok_s and ok_n else 1


def _same_table(a: Path, b: Path) -> bool:
    import pyarrow.parquet as pq

    ta, tb = pq.read_table(a).drop(["wall_s"]), pq.read_table(b).drop(["wall_s"])
    return ta.schema.names == tb.schema.names and ta.to_pylist() == tb.to_pylist()


if __name__ == "__main__":
    sys.exit(main())
