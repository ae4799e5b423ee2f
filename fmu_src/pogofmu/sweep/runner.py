"""One run of a sweep point, in a Dask worker process: the FMU extracted once per worker, a fresh
instance per run, simulated by fmpy or by the FMU binary's own C loop; a failed run is a row."""
from __future__ import annotations

import atexit
import math
import shutil
import tempfile
import threading
import time
from pathlib import Path
from typing import Dict, Sequence

from pogofmu.fmpy_raw import Fmi2Callbacks
from pogofmu.runtime.eventlog import parse_event_log  # the FMU's event records, as data

from .spec import INTEGER_TYPES, SUMMARY_OUTPUTS, Settings, default_step, recorded_outputs, run_span


def _decode(b):
    return b.decode(errors="replace") if b else ""


class Runner:
    """One extracted FMU, run as often as asked; each run in a fresh instance."""

    def __init__(self, fmu: str):
        from fmpy import extract, read_model_description

        self.md = read_model_description(fmu)
        self.unzipdir = extract(fmu, unzipdir=str(scratch_folder("pogofmu-sweep-fmu-")))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.default_step = default_step(self.md)
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.c_loop = None  # known after the first instance: does the binary bring its own loop?
        self._slaves = threading.local()  # with a C loop: this thread's FMU object, its library kept loaded

    def _instantiate(self, logger, messages):
        """A fresh FMU instance for one run. With the C loop, the thread's FMU object (its library
        loaded and its functions bound once) instantiates again: fmpy's ``instantiate_fmu`` binds
        every function anew each time, which costs more than the run itself."""
        from fmpy.fmi2 import FMU2Slave
        from fmpy.simulation import instantiate_fmu

        slave = getattr(self._slaves, "fmu", None)
        if self.fmi3:
            if slave is None:
                fmu = instantiate_fmu(self.unzipdir, self.md, "CoSimulation", False, True, logger)
                if self._grid_loop(fmu) is not None:
                    self._slaves.fmu = fmu
                return fmu
            slave.instantiate(visible=False, loggingOn=True, logMessage=logger)
            return slave
        fmu = slave
        if fmu is None:
            fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                            modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=None)
        # (fmpy's one FMI 2.0 proxy target: pogofmu.fmpy_raw.Fmi2Callbacks; kept with the instance)
        fmu.pogofmu_callbacks = Fmi2Callbacks(lambda status, category, text: messages.append((status, category, text)))
        fmu.instantiate(visible=False, callbacks=fmu.pogofmu_callbacks.struct, loggingOn=True)
        if slave is None and self._grid_loop(fmu) is not None:
            self._slaves.fmu = fmu
        return fmu

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

        def logger(environment, status, category, message):  # fmi3LogMessageCallback: an instance's own
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
        fmu = self._instantiate(logger, messages)
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


_COPIES: Dict[str, Path] = {}
_COPIES_LOCK = threading.Lock()


def scratch_folder(prefix: str) -> Path:
    """A new folder for this process's copies. In a Dask worker it lies in the worker's own local
    directory, which Dask removes when the worker ends: a process worker is stopped without running
    ``atexit``, so a folder of its own in the system's temporary folder would be left behind, one per
    worker and sweep. Elsewhere (the threads of the calling process) a temporary folder removed at exit."""
    base = None
    try:
        from distributed import get_worker

        base = get_worker().local_directory
    except (ImportError, ValueError):  # not in a Dask worker
        pass
    folder = Path(tempfile.mkdtemp(prefix=prefix, dir=base))
    atexit.register(shutil.rmtree, folder, True)
    return folder


def worker_copy(key: str, data: bytes, name: str) -> Path:
    """The worker's copy, as a file ``name``, of the bytes that hash to ``key`` (the FMU or the SSP
    package a sweep scattered): written once per worker, removed when the worker ends."""
    with _COPIES_LOCK:
        if key not in _COPIES:
            path = scratch_folder("pogofmu-sweep-") / name
            path.write_bytes(data)
            _COPIES[key] = path
        return _COPIES[key]


_RUNNERS: Dict[str, Runner] = {}
_RUNNERS_LOCK = threading.Lock()


def _runner(key: str, data: bytes) -> Runner:
    """The worker's Runner of the FMU whose bytes hash to key (written and extracted once)."""
    with _RUNNERS_LOCK:
        if key not in _RUNNERS:
            _RUNNERS[key] = Runner(str(worker_copy(key, data, "model.fmu")))
        return _RUNNERS[key]


def run_chunk(key: str, data: bytes, names: Sequence[str], chunk, settings: Settings):
    """Dask task: run [(run_id, point), ...]; returns [(row, timeseries or None), ...]."""
    runner = _runner(key, data)
    out = []
    for run_id, point in chunk:
        row, res = runner.run(dict(zip(names, point)), settings)
        out.append(({"run_id": run_id, **dict(zip(names, point)), **row}, res))
    return out
