"""Parameter sweeps and Monte Carlo runs of an FMU on Dask, one Parquet row per run.

    pogofmu sweep dist/PogoStick.fmu --grid k=50:200:4 --grid c=0.1,0.5 --out k_c.parquet
    pogofmu sweep dist/Penetrator.fmu --sample K=lognormal(9.21,0.5) --samples 200 --seed 1 --out soil.parquet

The runs are the shipped FMU artefact simulated by fmpy (``simulate_fmu``) in Dask worker
processes — or, for an FMU whose binary exports ``pogofmu_fmi2_run_grid`` / ``pogofmu_fmi3_run_grid``
(the native FMUs, dist/native/ and dist/native/fmi3/), by that function: fmpy's communication loop
written in C over the FMU's own FMI functions (native/pg_run_grid.h, once for both versions), the
same rows to the bit without fmpy's Python per step (``Runner.run``). FMI 2.0 and FMI 3.0 FMUs of
one model give the same table; a local cluster (``--workers W``, one thread each) or an existing one
(``--scheduler tcp://host:8786``). The FMU file is sent to the workers once and extracted once
per worker; each run gets a fresh FMU instance (0.7 ms, while extracting costs ~8 ms a run).
Runs go in chunks, one Dask task per chunk, so that scheduling costs little against the runs.

Every finished chunk is written at once as a part file next to the output
(``OUT.parquet.parts/``); when every run is done the parts are joined, ordered by ``run_id``,
into ``OUT.parquet`` and the part folder is removed. ``--resume`` reads the parts of an
interrupted sweep, checks that it is the same sweep (FMU file, points, settings) and runs only
the missing points. A run that fails (a parameter the FMU refuses, a leg that bottoms out, an
event storm, even a worker that dies) is a row with ``status`` and the FMU's own ``message``.

Host-side code: fmpy, numpy, dask.distributed, pyarrow, tqdm; never imported inside an FMU.
"""
from __future__ import annotations

import atexit
import hashlib
import itertools
import json
import math
import os
import re
import shutil
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from pogofmu.runtime.eventlog import parse_event_log  # the FMU's event records, as data

SUMMARY_OUTPUTS = ("n_events", "t_last_event")  # FMU outputs that get a column of their own
# the types a sweep sets and records: FMI 2.0's and FMI 3.0's names of a real and of an integer
REAL_TYPES = ("Real", "Float64", "Float32")
INTEGER_TYPES = ("Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
DISTRIBUTIONS = {  # name -> (numpy Generator method, argument names, rule on the arguments)
    "uniform": ("uniform", ("low", "high"), lambda a, b: a < b, "low < high"),
    "loguniform": (None, ("low", "high"), lambda a, b: 0 < a < b, "0 < low < high"),
    "normal": ("normal", ("mean", "sd"), lambda m, s: s > 0, "sd > 0"),
    "lognormal": ("lognormal", ("mu", "sigma"), lambda m, s: s > 0, "sigma > 0"),
}


# Dask settings of a local cluster: the worker's statistical profiler (a stack sample every 10 ms) and
# the monitors polling every 20-500 ms cost ~7 % of a PogoStick run's CPU time; a sweep needs none of them
QUIET_CLUSTER = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "500ms",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
}


class SweepError(Exception):
    """The sweep cannot be run as specified; the message names the option, its value and the rule."""


# =============================================================================================
# the points: grids and samples
# =============================================================================================

def _number(text: str, what: str) -> float:
    """A finite number (``nan``, ``inf`` and ``1e400``, which overflows to inf, are refused here,
    before any worker starts)."""
    try:
        value = float(text)
    except ValueError:
        raise SweepError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise SweepError(f"{what}: {text.strip()!r} is not a finite number")
    return value


def parse_grid(spec: str):
    """``NAME=a:b:n`` (n values from a to b, evenly spaced) or ``NAME=v1,v2,...`` -> (name, values)."""
    name, sep, rhs = spec.partition("=")
    name = name.strip()
    if not sep or not name or not rhs.strip():
        raise SweepError(f"--grid {spec!r}: expected NAME=a:b:n or NAME=v1,v2,...")
    if ":" in rhs:
        parts = rhs.split(":")
        if len(parts) != 3:
            raise SweepError(f"--grid {spec!r}: a range is a:b:n (start, stop, number of values)")
        a, b = (_number(p, f"--grid {spec!r}") for p in parts[:2])
        n = _number(parts[2], f"--grid {spec!r}")
        if n != int(n) or n < 1 or (n == 1 and a != b):
            raise SweepError(f"--grid {spec!r}: the number of values n = {parts[2]} must be an integer >= 1 "
                             "(n = 1 only with a = b)")
        n = int(n)
        # rounded to 15 significant digits: 0.2:1.0:3 is 0.2, 0.6, 1.0, not 0.6000000000000001
        values = [float(f"{a + (b - a) * i / (n - 1):.15g}") for i in range(n)] if n > 1 else [a]
        if n > 1:
            values[0], values[-1] = a, b  # exact end points
    else:
        values = [_number(v, f"--grid {spec!r}") for v in rhs.split(",")]
    return name, values


_SAMPLE = re.compile(r"^\s*([A-Za-z_][\w.\[\]]*)\s*=\s*([a-z]+)\s*\((.*)\)\s*$")


def parse_sample(spec: str):
    """``NAME=DIST(a,b)`` with DIST one of uniform, loguniform, normal, lognormal -> (name, dist, args)."""
    m = _SAMPLE.match(spec)
    if not m:
        raise SweepError(f"--sample {spec!r}: expected NAME=DIST(a,b) with DIST one of {', '.join(DISTRIBUTIONS)}")
    name, dist, args = m.group(1), m.group(2), m.group(3)
    if dist not in DISTRIBUTIONS:
        raise SweepError(f"--sample {spec!r}: unknown distribution {dist!r} (one of {', '.join(DISTRIBUTIONS)})")
    _, arg_names, rule, rule_text = DISTRIBUTIONS[dist]
    values = [_number(a, f"--sample {spec!r}") for a in args.split(",")] if args.strip() else []
    if len(values) != len(arg_names):
        raise SweepError(f"--sample {spec!r}: {dist} takes {len(arg_names)} arguments ({', '.join(arg_names)})")
    if not rule(*values):
        raise SweepError(f"--sample {spec!r}: {dist}({', '.join(f'{n}={v!r}' for n, v in zip(arg_names, values))}) "
                         f"breaks the rule {rule_text}")
    return name, dist, tuple(values)


def draw(samples, n: int, seed: Optional[int]):
    """n values of every sampled parameter, drawn from numpy's default_rng(seed) in the order given.

    Column after column: parameter 1 gets the first n draws, parameter 2 the next n, ...; the same
    seed and the same --sample list give the same points on any machine.
    """
    import numpy as np

    rng = np.random.default_rng(seed)
    columns = []
    for name, dist, args in samples:
        method = DISTRIBUTIONS[dist][0]
        if dist == "loguniform":
            vals = np.exp(rng.uniform(math.log(args[0]), math.log(args[1]), n))
        else:
            vals = getattr(rng, method)(*args, n)
        columns.append([float(v) for v in vals])
    return [tuple(col[i] for col in columns) for i in range(n)]


def make_points(grids, samples=(), n_samples=None, seed=None):
    """(names, points): the Cartesian product of the grids (first grid varies slowest), and for
    each grid point the n_samples Monte Carlo samples (if any --sample is given)."""
    names = [g[0] for g in grids] + [s[0] for s in samples]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise SweepError(f"parameter(s) {', '.join(dup)} given more than once (in --grid / --sample)")
    if samples and not n_samples:
        raise SweepError("--sample needs --samples N (the number of Monte Carlo samples, >= 1)")
    if n_samples and not samples:
        raise SweepError(f"--samples {n_samples}: there is no --sample NAME=DIST(...) to draw")
    if n_samples is not None and n_samples < 1:
        raise SweepError(f"--samples {n_samples}: must be >= 1")
    grid_points = list(itertools.product(*(g[1] for g in grids)))
    sample_points = draw(samples, n_samples, seed) if samples else [()]
    points = [gp + sp for gp in grid_points for sp in sample_points]
    if not names:
        raise SweepError("nothing to sweep: give at least one --grid NAME=... or --sample NAME=DIST(...)")
    return names, points


# =============================================================================================
# one run (in a worker process)
# =============================================================================================

@dataclass
class Settings:
    stop_time: Optional[float] = None  # None: the FMU's default experiment
    step: Optional[float] = None  # communication step; None: the default experiment's
    outputs: Optional[List[str]] = None  # None: every output of the FMU
    events: bool = False  # record the event log (needs the FMU parameter log_events)
    timeseries: bool = False  # return the recorded outputs on the grid too
    fixed: Dict[str, float] = field(default_factory=dict)  # start values common to every run


def recorded_outputs(md, outputs=None):
    """The outputs a run records: those asked for (default: every output) and n_events, t_last_event."""
    names = [v.name for v in md.modelVariables if v.causality == "output"] if outputs is None else list(outputs)
    have = {v.name for v in md.modelVariables}
    return names + [n for n in SUMMARY_OUTPUTS if n in have and n not in names]


def run_span(md, stop_time=None):
    """``(start, stop)`` of a run: the default experiment's start time (else 0), the stop time
    given, else the default experiment's (else start + 1 s, fmpy's default)."""
    ex = md.defaultExperiment
    start = float(ex.startTime) if ex is not None and ex.startTime is not None else 0.0
    stop = float(stop_time) if stop_time is not None else (
        float(ex.stopTime) if ex is not None and ex.stopTime is not None else start + 1.0)
    return start, stop


def default_step(md):
    """The default experiment's step as it is (fmpy alone would coarsen it to <= 1000 points)."""
    ex = md.defaultExperiment
    return float(ex.stepSize) if ex is not None and ex.stepSize is not None else None


def _decode(b):
    return b.decode(errors="replace") if b else ""


class Runner:
    """One extracted FMU, run as often as asked; each run in a fresh instance."""

    def __init__(self, fmu: str):
        from fmpy import extract, read_model_description

        self.md = read_model_description(fmu)
        self.unzipdir = extract(fmu)
        atexit.register(shutil.rmtree, self.unzipdir, True)
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.default_step = default_step(self.md)
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.c_loop = None  # known after the first instance: does the binary bring its own loop?
        self._slaves = threading.local()  # with a C loop: this thread's FMU object, its library kept loaded

    def _instantiate(self, logger):
        """A fresh FMU instance for one run. With the C loop, the thread's FMU object (its library
        loaded and its functions bound once) instantiates again: fmpy's ``instantiate_fmu`` binds
        every function anew each time, which costs more than the run itself."""
        from fmpy.simulation import instantiate_fmu

        slave = getattr(self._slaves, "fmu", None)
        if slave is None:
            fmu = instantiate_fmu(self.unzipdir, self.md, "CoSimulation", False, True, logger)
            if self._grid_loop(fmu) is not None:
                self._slaves.fmu = fmu
            return fmu
        if self.fmi3:
            slave.instantiate(visible=False, loggingOn=True, logMessage=logger)
            return slave
        from ctypes import byref

        from fmpy import calloc, free
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                               fmi2CallbackLoggerTYPE)
        from fmpy.logging import addLoggerProxy

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(callbacks))
        slave.instantiate(visible=False, callbacks=callbacks, loggingOn=True)
        return slave

    def _free(self, fmu):
        if getattr(self._slaves, "fmu", None) is fmu:  # the instance only: the library stays for the next run
            (fmu.fmi3FreeInstance if self.fmi3 else fmu.fmi2FreeInstance)(fmu.component)
        else:
            fmu.freeInstance()

    def _grid_loop(self, fmu):
        """The FMU binary's ``pogofmu_fmi2_run_grid`` / ``pogofmu_fmi3_run_grid`` (a ctypes
        function), or None."""
        if self.c_loop is None:
            import ctypes

            fn = getattr(fmu.dll, f"pogofmu_fmi{3 if self.fmi3 else 2}_run_grid", None)
            if fn is not None:
                fn.restype = ctypes.c_int
                fn.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                               ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_size_t,
                               ctypes.c_void_p, ctypes.c_size_t, ctypes.POINTER(ctypes.c_size_t)]
            self.c_loop = fn or False
        return self.c_loop or None

    def _c_recordable(self, record):
        """Whether the C loop records these outputs (reals as 64-bit floats, integers as 32-bit)."""
        return all(self.vars[n].type in ("Real", "Float64", "Integer", "Int32") for n in record)

    def _simulate_in_c(self, loop, fmu, start_values, stop_time, step, record):
        """What ``simulate_fmu`` does for a co-simulation FMU without inputs (FMI 3.0: without
        event mode) — set up, start values in both phases, initialize, the loop (here in the
        FMU's C), terminate — and its result array (the same columns, types and rows)."""
        import ctypes

        import numpy as np
        from fmpy.fmi1 import FMICallException
        from fmpy.simulation import apply_start_values, settable_in_initialization_mode, settable_in_instantiated

        ex = self.md.defaultExperiment
        start, stop = run_span(self.md, stop_time)
        tolerance = float(ex.tolerance) if ex is not None and ex.tolerance is not None else None
        if self.fmi3:
            rest = apply_start_values(fmu, self.md, dict(start_values), settable=settable_in_instantiated)
            fmu.enterInitializationMode(tolerance=tolerance, startTime=start, stopTime=stop)
        else:
            fmu.setupExperiment(tolerance=tolerance, startTime=start, stopTime=stop)
            rest = apply_start_values(fmu, self.md, dict(start_values), settable=settable_in_instantiated)
            fmu.enterInitializationMode()
        apply_start_values(fmu, self.md, rest, settable=settable_in_initialization_mode)
        fmu.exitInitializationMode()
        names = set(record)
        reals = [v for v in self.md.modelVariables if v.name in names and v.type in ("Real", "Float64")]
        ints = [v for v in self.md.modelVariables if v.name in names and v.type in ("Integer", "Int32")]
        rvr = (ctypes.c_uint32 * max(1, len(reals)))(*[v.valueReference for v in reals])
        ivr = (ctypes.c_uint32 * max(1, len(ints)))(*[v.valueReference for v in ints])
        max_rows = int(math.ceil((stop - start) / step * (1 + 1e-9))) + 2
        out = np.empty((max_rows, 1 + len(reals) + len(ints)))
        rows = ctypes.c_size_t(0)
        status = loop(fmu.component, start, stop, step, rvr, len(reals), ivr, len(ints),
                      out.ctypes.data, max_rows, ctypes.byref(rows))
        if status > 1:
            raise FMICallException(function="fmi3DoStep" if self.fmi3 else "fmi2DoStep", status=status)
        fmu.terminate()
        table = out[:rows.value]
        res = np.empty(rows.value, dtype=[("time", np.float64), *((v.name, np.float64) for v in reals),
                                          *((v.name, np.int32) for v in ints)])
        for k, name in enumerate(res.dtype.names):
            res[name] = table[:, k]
        return res

    def run(self, point: Dict[str, float], settings: Settings):
        """Simulate one point; returns (row, result array or None). Never raises for a failed run."""
        import numpy as np
        from fmpy import simulate_fmu
        from fmpy.fmi1 import FMICallException

        messages = []  # this run's log (a worker with several threads runs several at once)

        def logger(component, instance, status, category, message):
            messages.append((status, _decode(category), _decode(message)))

        if self.fmi3:  # fmi3LogMessageCallback: (instanceEnvironment, status, category, message)
            def logger(environment, status, category, message):  # noqa: F811
                messages.append((status, _decode(category), _decode(message)))

        start = dict(settings.fixed)
        start.update(point)
        if settings.events:
            start["log_events"] = 1
        for name, value in start.items():
            if self.vars[name].type in INTEGER_TYPES:
                start[name] = int(value)
        record = recorded_outputs(self.md, settings.outputs)
        row = {"status": "ok", "message": ""}
        res = None
        t0 = time.perf_counter()
        fmu = self._instantiate(logger)
        try:
            loop = self._grid_loop(fmu)
            if loop is not None and (settings.step or self.default_step) and self._c_recordable(record):
                res = self._simulate_in_c(loop, fmu, start, settings.stop_time, settings.step or self.default_step,
                                          record)
            else:
                res = simulate_fmu(self.unzipdir, model_description=self.md, fmu_instance=fmu,
                                   start_values=start, stop_time=settings.stop_time,
                                   output_interval=settings.step or self.default_step, output=record, validate=False)
            self._free(fmu)
            stop = run_span(self.md, settings.stop_time)[1]
            if not math.isclose(res["time"][-1], stop, rel_tol=0, abs_tol=1e-9 * max(1.0, abs(stop))):
                row.update(status="incomplete", message=f"the run stopped at t = {res['time'][-1]!r} s "
                                                        f"before the stop time {stop!r} s")
        except FMICallException as exc:
            # fmi2Error leaves the instance usable enough to free; after fmi2Fatal nothing may be called
            if exc.status == 3:
                self._free(fmu)
            row.update(status="error" if exc.status == 3 else "fatal", message=_problem(messages, str(exc)))
            res = None
        except Exception as exc:  # noqa: BLE001 (a run never takes the sweep down)
            row.update(status="error", message=_problem(messages, f"{type(exc).__name__}: {exc}"))
            res = None
        row["wall_s"] = time.perf_counter() - t0
        for name in record:
            if name in SUMMARY_OUTPUTS:
                row[name] = None if res is None else res[name][-1].item()
            else:
                col = None if res is None else res[name]
                row[f"{name}_final"] = None if col is None else col[-1].item()
                row[f"{name}_min"] = None if col is None else np.min(col).item()
                row[f"{name}_max"] = None if col is None else np.max(col).item()
        if settings.events:
            ev = parse_event_log(messages)
            row["event_t"] = [e["time"] for e in ev]
            row["event_name"] = [e["name"] for e in ev]
            row["event_state"] = [list(e["state"].items()) for e in ev]
        return row, (res if settings.timeseries else None)


def _problem(messages, text):
    """The FMU's own error/warning messages (the reason), then what failed."""
    return "; ".join([m[2] for m in messages if m[0] >= 2] + [text])


_RUNNERS: Dict[str, Runner] = {}
_RUNNERS_LOCK = threading.Lock()


def _runner(key: str, data: bytes) -> Runner:
    """The worker's Runner of the FMU whose bytes hash to key (written and extracted once)."""
    with _RUNNERS_LOCK:
        if key not in _RUNNERS:
            folder = Path(tempfile.mkdtemp(prefix="pogofmu-sweep-"))
            atexit.register(shutil.rmtree, folder, True)
            path = folder / "model.fmu"
            path.write_bytes(data)
            _RUNNERS[key] = Runner(str(path))
        return _RUNNERS[key]


def run_chunk(key: str, data: bytes, names: Sequence[str], chunk, settings: Settings):
    """Dask task: run [(run_id, point), ...]; returns [(row, timeseries or None), ...]."""
    runner = _runner(key, data)
    out = []
    for run_id, point in chunk:
        row, res = runner.run(dict(zip(names, point)), settings)
        out.append(({"run_id": run_id, **dict(zip(names, point)), **row}, res))
    return out


# =============================================================================================
# the table
# =============================================================================================

def check_names(md, names, settings: Settings):
    """Every swept or fixed name is a parameter of the FMU; every output is an output."""
    vars_ = {v.name: v for v in md.modelVariables}
    params = sorted(n for n, v in vars_.items() if v.causality == "parameter")
    for n in list(names) + list(settings.fixed):
        if n not in vars_ or vars_[n].causality != "parameter":
            raise SweepError(f"{n!r} is not a parameter of {md.modelName} (parameters: {', '.join(params)})")
        if vars_[n].type not in REAL_TYPES + INTEGER_TYPES:
            raise SweepError(f"parameter {n} of {md.modelName} is {vars_[n].type}: only reals and integers can be "
                             f"swept ({', '.join(REAL_TYPES + INTEGER_TYPES)})")
    outs = sorted(n for n, v in vars_.items() if v.causality == "output")
    for n in settings.outputs or ():
        if n not in vars_ or vars_[n].causality != "output":
            raise SweepError(f"--outputs: {n!r} is not an output of {md.modelName} (outputs: {', '.join(outs)})")
    if settings.events and "log_events" not in vars_:
        raise SweepError(f"--events needs the parameter log_events, which {md.modelName} does not have")
    for name, text in (("--stop-time", settings.stop_time), ("--step", settings.step)):
        if text is not None and not (math.isfinite(text) and text > 0):
            raise SweepError(f"{name} {text!r}: must be a finite number > 0 [s]")
    start, stop = run_span(md, settings.stop_time)
    if not stop > start:
        raise SweepError(f"--stop-time {stop!r}: must be later than the start time {start!r} s of {md.modelName}")
    step = settings.step or default_step(md)
    if step is not None and step > stop - start:
        raise SweepError(f"--step {step!r}: longer than the run ({start!r} s to the stop time {stop!r} s); the "
                         f"communication step must be at most the stop time minus the start time")


def check_point_types(md, names, points):
    """Integer parameters take integral values only (a grid 1:3:3 is fine, 1.5 is not)."""
    vars_ = {v.name: v for v in md.modelVariables}
    for j, n in enumerate(names):
        if vars_[n].type in INTEGER_TYPES:
            bad = [p[j] for p in points if p[j] != int(p[j])]
            if bad:
                raise SweepError(f"parameter {n} is an Integer: value {bad[0]!r} is not integral")


def schema(md, names, settings: Settings):
    import pyarrow as pa

    vars_ = {v.name: v for v in md.modelVariables}
    typ = lambda n: pa.int64() if vars_[n].type in INTEGER_TYPES + ("Boolean", "Enumeration") else pa.float64()  # noqa: E731
    fields = [("run_id", pa.int64())] + [(n, typ(n)) for n in names]
    fields += [("status", pa.string()), ("message", pa.string()), ("wall_s", pa.float64())]
    for n in recorded_outputs(md, settings.outputs):
        if n in SUMMARY_OUTPUTS:
            fields.append((n, typ(n)))
        else:
            fields += [(f"{n}_{s}", typ(n)) for s in ("final", "min", "max")]
    if settings.events:
        fields += [("event_t", pa.list_(pa.float64())), ("event_name", pa.list_(pa.string())),
                   ("event_state", pa.list_(pa.map_(pa.string(), pa.float64())))]
    return pa.schema(fields)


def _write_atomic(table, path: Path, metadata=None):
    import pyarrow.parquet as pq

    if metadata:
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **metadata})
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)


def _write_timeseries(folder: Path, run_id: int, res):
    import pyarrow as pa

    part = folder / f"run_id={run_id}"
    part.mkdir(parents=True, exist_ok=True)
    table = pa.table({n: res[n] for n in res.dtype.names})
    _write_atomic(table, part / "part-0.parquet")


# =============================================================================================
# the sweep (client side)
# =============================================================================================

@dataclass
class Sweep:
    fmu: str
    names: List[str]
    points: List[tuple]
    settings: Settings
    out: str
    timeseries_dir: Optional[str] = None
    chunk_size: Optional[int] = None

    def spec(self, sha: str) -> dict:
        """What identifies the sweep for --resume."""
        return {"fmu_sha256": sha, "names": self.names, "points": [list(p) for p in self.points],
                "settings": asdict(self.settings), "timeseries": bool(self.timeseries_dir)}


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _parts_dir(out: Path) -> Path:
    return out.with_name(out.name + ".parts")


def _done_ids(parts: Path):
    import pyarrow.parquet as pq

    done = set()
    for f in sorted(parts.glob("chunk-*.parquet")):
        done.update(pq.read_table(f, columns=["run_id"]).column("run_id").to_pylist())
    return done


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


def close_cluster(client, cluster):
    client.close()
    if cluster is not None:
        cluster.close()


def prepare(sweep: Sweep):
    """Check the sweep against the FMU before anything runs; returns (FMU bytes, sha256, model description)."""

    fmu = Path(sweep.fmu)
    if not fmu.is_file():
        raise SweepError(f"FMU {fmu}: no such file (build it with build_fmu.py, or python3 tasks.py build)")
    try:
        data = fmu.read_bytes()
    except OSError as exc:
        raise SweepError(f"FMU {fmu}: cannot be read ({exc.strerror or exc})") from None
    md = read_fmu_description(fmu)
    check_names(md, sweep.names, sweep.settings)
    check_point_types(md, sweep.names, sweep.points)
    return data, _sha256(data), md


def read_fmu_description(fmu: Path):
    """fmpy's model description of ``fmu``, or a SweepError saying what the file is instead."""
    import zipfile

    from fmpy import read_model_description

    if not zipfile.is_zipfile(fmu):
        raise SweepError(f"FMU {fmu}: not an FMU (not a zip archive)")
    with zipfile.ZipFile(fmu) as z:
        if "modelDescription.xml" not in z.namelist():
            raise SweepError(f"FMU {fmu}: not an FMU (a zip archive without modelDescription.xml)")
    try:
        return read_model_description(str(fmu), validate=False)
    except Exception as exc:  # noqa: BLE001 - lxml's XMLSyntaxError, fmpy's own checks, ...
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise SweepError(f"FMU {fmu}: its modelDescription.xml cannot be read ({first})") from None


def check_output(out: Path, timeseries, overwrite: bool, resume: bool):
    """The output is a regular file in a writable folder (or does not exist yet); its ``.parts``
    folder and the timeseries folder are folders; an existing output is replaced only with
    ``--overwrite``, and only if it is a regular file: a device, a folder or a link to one is never
    replaced. Checked before any worker starts."""
    out = Path(out)
    if out.exists() or out.is_symlink():
        if not out.is_file() or out.is_symlink():
            kind = "a folder" if out.is_dir() else "a symbolic link" if out.is_symlink() else \
                "not a regular file (a device, a pipe or a socket)"
            raise SweepError(f"--out {out}: {kind}; give the path of a Parquet file to write (an existing output "
                             f"is replaced only if it is a regular file, with --overwrite)")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise SweepError(f"--out {out}: the folder {parent} does not exist")
    try:
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise SweepError(f"--out {out}: the folder {parent} cannot be written ({exc.strerror or exc})") from None
    parts = _parts_dir(out)
    if (parts.exists() or parts.is_symlink()) and (not parts.is_dir() or parts.is_symlink()):
        raise SweepError(f"{parts} exists and is not a folder of the sweep's parts: remove it or choose another --out")
    if timeseries:
        ts = Path(timeseries)
        if ts.exists() and (not ts.is_dir() or ts.is_symlink()):
            raise SweepError(f"--timeseries {ts}: exists and is not a folder")
        if ts.is_dir() and overwrite and not resume:
            foreign = [p.name for p in ts.iterdir() if not (p.is_dir() and p.name.startswith("run_id="))]
            if foreign:
                raise SweepError(f"--timeseries {ts}: holds {', '.join(sorted(foreign)[:3])}, which a sweep did not "
                                 f"write; --overwrite replaces only a sweep's own run_id=* folders")


def check_workers(client):
    """Every worker can import what a run needs (else every run would fail with the same message)."""
    def probe():  # a local function: sent by value, so that it runs where pogofmu is missing too
        import importlib

        for module in ("numpy", "scipy.integrate", "fmpy", "pogofmu.sweep"):
            importlib.import_module(module)

    try:
        client.run(probe)
    except Exception as exc:  # noqa: BLE001
        raise SweepError(f"the cluster's workers cannot run a sweep ({type(exc).__name__}: {exc}): they need "
                         "pogofmu (with fmpy, numpy, scipy) installed (README: \"On a Dask cluster\")") from None


def run_sweep(sweep: Sweep, client, resume=False, overwrite=False, progress=True, log=print):
    """Run every missing point of the sweep on the client's cluster; write sweep.out. Returns the
    number of runs done by this call."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from distributed import as_completed
    from tqdm import tqdm

    data, sha, md = prepare(sweep)
    check_output(Path(sweep.out), sweep.timeseries_dir, overwrite, resume)
    sch = schema(md, sweep.names, sweep.settings)
    spec = json.dumps(sweep.spec(sha), sort_keys=True)
    out = Path(sweep.out)
    parts = _parts_dir(out)
    ts_dir = Path(sweep.timeseries_dir) if sweep.timeseries_dir else None

    if resume:
        if out.exists() and not parts.exists():
            old = pq.read_schema(out).metadata or {}
            if old.get(b"pogofmu.sweep") != spec.encode():
                raise SweepError(f"--resume: {out} holds a different sweep (FMU file, points or settings differ)")
            log(f"{out}: all {len(sweep.points)} runs are done already")
            return 0
        if parts.exists():
            old = (parts / "spec.json").read_text() if (parts / "spec.json").exists() else ""
            if old != spec:
                raise SweepError(f"--resume: {parts} belongs to a different sweep (FMU file, points or settings "
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
    submit = lambda chunk: client.submit(run_chunk, sha, data_f, sweep.names, chunk, sweep.settings,  # noqa: E731
                                         pure=False)
    futures = {}
    for chunk in chunks:
        futures[submit(chunk)] = chunk
    bar = tqdm(total=len(sweep.points), initial=len(done), unit="run", disable=not progress,
               desc=Path(sweep.fmu).stem, file=sys.stderr, smoothing=0.1)
    n_run = 0
    failed = 0
    try:
        pending = as_completed(list(futures))
        for fut in pending:
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
                             "message": f"the worker running this point failed: {type(exc).__name__}: {exc}"}, None)]
            else:
                results = fut.result()
                fut.release()
            rows = []
            for row, res in results:
                if ts_dir is not None and res is not None:
                    _write_timeseries(ts_dir, row["run_id"], res)
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


def add_arguments(ap):
    """The options of a sweep shared by ``pogofmu sweep`` and the studies (cluster and output)."""
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, help="local worker processes (default: every core)")
    g.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")


def sweep_main(argv, prog="pogofmu sweep"):
    import argparse

    ap = argparse.ArgumentParser(prog=prog, description=(
        "Run an FMU for every point of a grid (Cartesian product) and/or for Monte Carlo samples on "
        "Dask; one Parquet row per run."))
    ap.add_argument("fmu", help="the FMU file, e.g. dist/PogoStick.fmu")
    ap.add_argument("--grid", action="append", default=[], metavar="NAME=a:b:n|NAME=v1,v2,...",
                    help="n values from a to b, or a list; several --grid span the Cartesian product")
    ap.add_argument("--sample", action="append", default=[], metavar="NAME=DIST(a,b)",
                    help="uniform(low,high), loguniform(low,high), normal(mean,sd), lognormal(mu,sigma) "
                         "(mu, sigma of log NAME)")
    ap.add_argument("--samples", type=int, help="number of Monte Carlo samples (per grid point)")
    ap.add_argument("--seed", type=int, default=0, help="seed of numpy's default_rng (default 0)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a parameter value common to every run")
    ap.add_argument("--stop-time", type=float, help="[s] (default: the FMU's default experiment)")
    ap.add_argument("--step", type=float, help="communication step [s] (default: the default experiment's)")
    ap.add_argument("--outputs", help="comma-separated outputs to summarize (default: every output)")
    ap.add_argument("--events", action="store_true", help="record every event (time, kind, state) from the "
                                                          "FMU's event log (sets log_events = 1)")
    ap.add_argument("--timeseries", metavar="DIR", help="also write every run's outputs on the grid to a "
                                                        "Parquet dataset partitioned by run_id")
    ap.add_argument("--chunk-size", type=int, help="runs per Dask task (default: about 32 tasks per worker, "
                                                   "at most 64 runs)")
    ap.add_argument("--out", required=True, help="the Parquet file to write")
    ap.add_argument("--resume", action="store_true", help="finish an interrupted sweep (same command)")
    ap.add_argument("--overwrite", action="store_true", help="replace an existing output")
    add_arguments(ap)
    args = ap.parse_args(argv)
    try:
        if args.chunk_size is not None and args.chunk_size < 1:
            raise SweepError(f"--chunk-size {args.chunk_size}: must be >= 1")
        if not 0 <= args.seed < 2 ** 63:
            raise SweepError(f"--seed {args.seed}: must be a whole number >= 0 (numpy's default_rng)")
        fixed = {}
        for s in args.set:
            name, sep, value = s.partition("=")
            if not sep or not name.strip():
                raise SweepError(f"--set {s!r}: expected NAME=VALUE")
            if name.strip() in fixed:
                raise SweepError(f"--set {s!r}: {name.strip()} is set twice")
            fixed[name.strip()] = _number(value, f"--set {s!r}")
        names, points = make_points([parse_grid(g) for g in args.grid], [parse_sample(s) for s in args.sample],
                                    args.samples, args.seed)
        both = sorted(set(names) & set(fixed))
        if both:
            raise SweepError(f"{', '.join(both)}: both swept (--grid/--sample) and fixed (--set); give one")
        outputs = None
        if args.outputs is not None:
            outputs = [o.strip() for o in args.outputs.split(",") if o.strip()]
            if not outputs:
                raise SweepError(f"--outputs {args.outputs!r}: names no output (comma-separated output names)")
        settings = Settings(stop_time=args.stop_time, step=args.step, events=args.events, outputs=outputs,
                            timeseries=bool(args.timeseries), fixed=fixed)
        sweep = Sweep(args.fmu, names, points, settings, args.out, args.timeseries, args.chunk_size)
        if args.workers is not None and args.workers < 1:
            raise SweepError(f"--workers {args.workers}: must be >= 1")
        status = execute(sweep, args.workers, args.scheduler, resume=args.resume, overwrite=args.overwrite,
                         progress=not args.no_progress)
        return status or (1 if failed_runs(Path(args.out)) else 0)
    except SweepError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def failed_runs(out: Path) -> int:
    """The runs of a written sweep whose status is not ``ok``."""
    import pyarrow.parquet as pq

    statuses = pq.read_table(out, columns=["status"]).column("status").to_pylist()
    return len(statuses) - statuses.count("ok")


def execute(sweep: Sweep, workers=None, scheduler=None, **kwargs):
    """Open the cluster, run the sweep, close the cluster (also on an interruption)."""
    prepare(sweep)  # a bad option fails before any worker starts
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
