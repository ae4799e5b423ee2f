"""The sweep on Dask: the cluster (local or an existing scheduler), the chunks as tasks, the
parts written as chunks finish, the final table; an interruption leaves what is saved for --resume."""
from __future__ import annotations

import json
import math
import os
import shutil
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Optional

from .parquet import _done_ids, _parts_dir, _write_atomic, _write_timeseries, check_output, failed_runs, schema
from .runner import run_chunk
from .spec import Sweep, SweepError, prepare

# Dask settings of a local cluster: the worker's statistical profiler (a stack sample every 10 ms) and
# the monitors polling every 20-500 ms cost ~7 % of a PogoStick run's CPU time; a sweep needs none of them
QUIET_CLUSTER = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "500ms",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
}


def open_cluster(workers: Optional[int] = None, scheduler: Optional[str] = None):
    """A dask.distributed Client: to the scheduler at ``scheduler``, or to a new local cluster of
    ``workers`` processes (default: every core) with one thread each. Returns (client, cluster)."""
    import logging

    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="10s"), None
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise SweepError(f"--scheduler {scheduler!r}: cannot connect ({type(exc).__name__}: {exc}); give the "
                             f"scheduler's address, e.g. tcp://10.0.0.5:8786") from None
    if workers is not None and workers < 1:
        raise SweepError(f"--workers {workers}: must be >= 1")
    n = workers or os.cpu_count() or 1
    # the workers' logs are silenced: a run's failure is its row; a closing cluster's heartbeat errors are noise;
    # the scheduler's HTTP server (dashboard off) on a free port: several sweeps may run side by side
    with dask.config.set(QUIET_CLUSTER):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=logging.CRITICAL)
        return Client(cluster), cluster


POLL = 0.05  # [s] how often the loop looks for finished runs and for Ctrl-C while none finishes


class Interrupts:
    """Ctrl-C while the runs go: the signal is only noted, and :meth:`check` raises the
    ``KeyboardInterrupt`` at a point of the sweep's own loop (between two results), never inside
    the Dask client's code, where an exception raised at any bytecode can leave one of its locks or
    states half-changed (an interrupted sweep sometimes hung, its output never written). In the main
    thread only (where Python delivers signals); elsewhere nothing changes."""

    def __enter__(self):
        self.hit, self._prev = False, None
        if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is not None:
            self._prev = signal.signal(signal.SIGINT, self._note)
        return self

    def _note(self, signum, frame):
        self.hit = True

    def check(self):
        if self.hit:
            self.hit = False
            raise KeyboardInterrupt

    def __exit__(self, *exc):
        if self._prev is not None:
            signal.signal(signal.SIGINT, self._prev)
        return False


def close_cluster(client, cluster):
    client.close()
    if cluster is not None:
        cluster.close()


def check_workers(client):
    """Every worker can import what a run needs (else every run would fail with the same message)."""
    def probe():  # a local function: sent by value, so that it runs where pogofmu is missing too
        import importlib

        # the package first: a worker where it is missing (or hidden) must fail here, not find the runner cached
        for module in ("numpy", "scipy.integrate", "fmpy", "pogofmu.sweep", "pogofmu.sweep.runner",
                       "pogofmu.sweep.system", "pogofmu.ssp.master"):
            importlib.import_module(module)

    try:
        client.run(probe)
    except Exception as exc:  # noqa: BLE001
        raise SweepError(f"the cluster's workers cannot run a sweep ({type(exc).__name__}: {exc}): they need "
                         "pogofmu (with fmpy, numpy, scipy) installed (README: \"On a Dask cluster\")") from None


def load(sweep):
    """``(data, sha256, schema, task, write_series)`` of a sweep, checked before anything runs: an
    FMU's :class:`~.spec.Sweep` (its Dask task :func:`~.runner.run_chunk`, its time series as
    Parquet), or a system's :class:`~.system.SystemSweep`, which says its own."""
    if isinstance(sweep, Sweep):
        data, sha, md = prepare(sweep)
        return data, sha, schema(md, sweep.names, sweep.settings), run_chunk, _write_timeseries
    data, sha, sch = sweep.load()
    return data, sha, sch, sweep.task, sweep.write_series


def run_sweep(sweep: Sweep, client, resume=False, overwrite=False, progress=True, log=print):
    """Run every missing point of the sweep on the client's cluster; write sweep.out. Returns the
    number of runs done by this call. ``sweep``: a :class:`~.spec.Sweep` of an FMU or a
    :class:`~.system.SystemSweep` of an SSP package (:func:`load`)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from distributed import as_completed
    from tqdm import tqdm

    data, sha, sch, task, write_series = load(sweep)
    check_output(Path(sweep.out), sweep.timeseries_dir, overwrite, resume)
    spec = json.dumps(sweep.spec(sha), sort_keys=True)
    out = Path(sweep.out)
    parts = _parts_dir(out)
    ts_dir = Path(sweep.timeseries_dir) if sweep.timeseries_dir else None

    if resume:
        if out.exists() and not parts.exists():
            old = pq.read_schema(out).metadata or {}
            if old.get(b"pogofmu.sweep") != spec.encode():
                raise SweepError(f"--resume: {out} holds a different sweep (its file, points or settings differ)")
            log(f"{out}: all {len(sweep.points)} runs are done already")
            return 0
        if parts.exists():
            old = (parts / "spec.json").read_text() if (parts / "spec.json").exists() else ""
            if old != spec:
                raise SweepError(f"--resume: {parts} belongs to a different sweep (its file, points or settings "
                                 "differ); run that sweep's command again, or delete the folder")
    elif parts.exists() or out.exists():
        if not overwrite:
            what = f"{parts} (an interrupted sweep: --resume finishes it)" if parts.exists() else str(out)
            raise SweepError(f"{what} exists: give --resume or --overwrite")
        shutil.rmtree(parts, ignore_errors=True)
        out.unlink(missing_ok=True)
        if ts_dir is not None:
            shutil.rmtree(ts_dir, ignore_errors=True)
    parts.mkdir(parents=True, exist_ok=True)
    (parts / "spec.json").write_text(spec)

    done = _done_ids(parts)
    todo = [(i, p) for i, p in enumerate(sweep.points) if i not in done]
    if done:
        log(f"resuming {out}: {len(done)} of {len(sweep.points)} runs done, running the other {len(todo)}")
    if ts_dir is not None:  # a run that is redone must not leave an old series behind
        for i, _ in todo:
            shutil.rmtree(ts_dir / f"run_id={i}", ignore_errors=True)

    check_workers(client)
    n_workers = max(1, len(client.scheduler_info().get("workers", {})))
    # about 32 tasks per worker: a Dask task costs ~ms against ~0.1 s a run, and small chunks even out the tail
    size = sweep.chunk_size or max(1, min(64, math.ceil(len(todo) / (32 * n_workers))))
    chunks = [todo[k:k + size] for k in range(0, len(todo), size)]
    data_f = client.scatter(data, broadcast=True)
    submit = lambda chunk: client.submit(task, sha, data_f, sweep.names, chunk, sweep.settings,  # noqa: E731
                                         pure=False)
    futures = {}
    for chunk in chunks:
        futures[submit(chunk)] = chunk
    bar = tqdm(total=len(sweep.points), initial=len(done), unit="run", disable=not progress,
               desc=sweep.label, file=sys.stderr, smoothing=0.1)
    n_run = 0
    failed = 0
    stop = Interrupts()
    try:
        pending = as_completed(list(futures))
        with stop:
            while not pending.is_empty():
                stop.check()
                if not pending.has_ready():
                    time.sleep(POLL)
                    continue
                fut = next(pending)
                chunk = futures.pop(fut)
                if fut.status == "cancelled":  # the scheduler went away (or cancelled it): stop, --resume goes on
                    raise RuntimeError(f"the cluster cancelled the task of runs {chunk[0][0]}-{chunk[-1][0]} "
                                       "(scheduler lost?)")
                if fut.status == "error":  # a worker died running it (KilledWorker), or the task itself failed
                    exc = fut.exception()
                    fut.release()
                    if len(chunk) > 1:  # a worker died in this chunk: run its points one by one to find the culprit
                        bar.write(f"runs {chunk[0][0]}-{chunk[-1][0]} failed together ({type(exc).__name__}: {exc}); "
                                  "running them one by one")
                        for item in chunk:
                            f = submit([item])
                            futures[f] = [item]
                            pending.add(f)
                        continue
                    run_id, point = chunk[0]
                    results = [({"run_id": run_id, **dict(zip(sweep.names, point)), "status": "crashed",
                                 "message": f"the worker running this point failed: {type(exc).__name__}: "
                                            f"{exc}"}, None)]
                else:
                    results = fut.result()
                    fut.release()
                rows = []
                for row, res in results:
                    if ts_dir is not None and res is not None:
                        write_series(ts_dir, row["run_id"], res)
                    rows.append(row)
                    failed += row["status"] != "ok"
                table = pa.Table.from_pylist(rows, schema=sch)
                _write_atomic(table, parts / f"chunk-{rows[0]['run_id']:08d}.parquet")
                n_run += len(rows)
                bar.update(len(rows))
                if failed:
                    bar.set_postfix(failed=failed)
    except KeyboardInterrupt:
        bar.close()
        client.cancel(list(futures))
        log(f"\ninterrupted: {len(done) + n_run} of {len(sweep.points)} runs saved in {parts}; "
            "the same command with --resume runs the rest")
        raise
    except Exception as exc:  # a lost scheduler, a full disk, ...: what is saved stays saved
        bar.close()
        raise SweepError(f"the sweep stopped ({type(exc).__name__}: {exc}); {len(done) + n_run} of "
                         f"{len(sweep.points)} runs are saved in {parts}: the same command with --resume runs "
                         "the rest") from exc
    bar.close()

    tables = [pq.read_table(f, schema=sch) for f in sorted(parts.glob("chunk-*.parquet"))]
    table = pa.concat_tables(tables).sort_by("run_id") if tables else sch.empty_table()
    if table.num_rows != len(sweep.points):
        raise SweepError(f"internal: {table.num_rows} rows for {len(sweep.points)} points in {parts}")
    _write_atomic(table, out, metadata={"pogofmu.sweep": spec})
    shutil.rmtree(parts)
    bad = failed_runs(out)
    log(f"{out}: {table.num_rows} runs ({n_run} run now), {bad} failed" + (
        " (see the status and message columns)" if bad else ""))
    return n_run


def execute(sweep: Sweep, workers=None, scheduler=None, **kwargs):
    """Open the cluster, run the sweep, close the cluster (also on an interruption)."""
    load(sweep)  # a bad option fails before any worker starts
    check_output(Path(sweep.out), sweep.timeseries_dir, kwargs.get("overwrite", False), kwargs.get("resume", False))
    try:
        client, cluster = open_cluster(workers, scheduler)
    except KeyboardInterrupt:
        return 130
    try:
        run_sweep(sweep, client, **kwargs)
    except KeyboardInterrupt:
        return 130
    finally:
        close_cluster(client, cluster)
    return 0
