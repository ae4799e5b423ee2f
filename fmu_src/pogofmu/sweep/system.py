"""Sweeps of a whole system: the SSP master run for every point, in Dask workers, one Parquet row
per run (``pogofmu sweep SYSTEM.ssp``).

    pogofmu sweep dist/native/SpaceHopper.ssp --parameters moon --grid PogoStick.k=80:120:3 \\
        --sample HopController.h_target=normal(1.5,0.05) --samples 20 --summary PogoStick.y:max --out hop.parquet

A point sets ``Component.parameter`` values over the selected parameter set, exactly as
``pogofmu ssp run --set Component.parameter=VALUE`` does: each run is that command's run (the
same :func:`pogofmu.ssp.master.simulate`, the same options), so a row holds the bits of a direct
run of its point. The package is sent to the workers once and written once per worker.

A row: ``run_id``, the swept values, ``status`` / ``message`` / ``wall_s``, the final value of
every output connector (``Component.connector:final``), the number of event instants the master
synchronized (``events``) and, per component, the number of them that were its events
(``Component:events``), then the ``--summary`` columns:

* ``Component.connector:KIND`` with KIND ``min``, ``max``, ``final``, ``initial``, ``mean`` (the
  time average, trapezoidal over every row, the left and right limits at an event included),
  ``t_min`` / ``t_max`` (the first time of the extreme);
* ``Component:KIND`` with KIND ``first_event``, ``last_event`` (the time of the component's
  first or last event; empty without one) or ``events``.

A run that fails (a parameter a component refuses, an event storm, ...) is a row with ``status``
``error`` and the master's one-line message. ``--timeseries DIR`` writes every run's rows, the
CSV ``pogofmu ssp run`` writes, to ``DIR/run_id=N/timeseries.csv``.
"""
from __future__ import annotations

import hashlib
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Dict, List, Optional

from .spec import SweepError

CONNECTOR_KINDS = ("min", "max", "final", "initial", "mean", "t_min", "t_max")
COMPONENT_KINDS = ("first_event", "last_event", "events")
SERIES_FILE = "timeseries.csv"


@dataclass
class SystemSettings:
    """The options of ``pogofmu ssp run`` a system sweep takes, and what each row records."""
    parameters: Optional[str] = None  # resources/NAME.ssv (None: the bindings of the .ssd)
    stop_time: Optional[float] = None  # None: the .ssd's default experiment
    step: float = 1e-3
    algorithm: str = "gauss-seidel"
    events: bool = True
    event_tolerance: Optional[float] = None  # None: the master's default
    inputs: Optional[str] = None  # None: the master's default
    rel_tol: float = 1e-10
    abs_tol: float = 1e-12
    fixed: Dict[str, float] = field(default_factory=dict)  # Component.parameter values of every run
    summaries: List[str] = field(default_factory=list)  # "Component.connector:KIND" / "Component:KIND"
    timeseries: bool = False

    def options(self) -> dict:
        """The keyword arguments of :func:`pogofmu.ssp.master.simulate` (but the overrides)."""
        from pogofmu.ssp.master import DEFAULT_EVENT_TOLERANCE, DEFAULT_INPUTS

        return dict(parameters=self.parameters, stop_time=self.stop_time, step=self.step, algorithm=self.algorithm,
                    events=self.events, rel_tol=self.rel_tol, abs_tol=self.abs_tol,
                    event_tolerance=DEFAULT_EVENT_TOLERANCE if self.event_tolerance is None else self.event_tolerance,
                    inputs=DEFAULT_INPUTS if self.inputs is None else self.inputs)


def one_line(exc) -> str:
    """The master's message on one line (a validation lists its problems on lines of their own)."""
    return " ".join(line.strip() for line in str(exc).splitlines() if line.strip())


def parse_summary(spec: str):
    """``Component.connector:KIND`` -> (component, connector, kind); ``Component:KIND`` -> (component, None, kind)."""
    target, sep, kind = spec.rpartition(":")
    kind = kind.strip()
    target = target.strip()
    if not sep or not target:
        raise SweepError(f"--summary {spec!r}: expected Component.connector:KIND ({', '.join(CONNECTOR_KINDS)}) "
                         f"or Component:KIND ({', '.join(COMPONENT_KINDS)})")
    comp, dot, con = target.partition(".")
    if dot:
        if kind not in CONNECTOR_KINDS:
            raise SweepError(f"--summary {spec!r}: {kind!r} is no summary of a connector (one of "
                             f"{', '.join(CONNECTOR_KINDS)})")
        return comp, con, kind
    if kind not in COMPONENT_KINDS:
        raise SweepError(f"--summary {spec!r}: {kind!r} is no summary of a component (one of "
                         f"{', '.join(COMPONENT_KINDS)}; a connector's: Component.connector:KIND)")
    return comp, None, kind


def _is_integer(type_name) -> bool:
    from pogofmu.ssp.package import REAL

    return type_name not in REAL


@dataclass
class SystemSweep:
    """A sweep of an SSP package: the cluster machinery (:func:`.cluster.run_sweep`) asks it for its
    bytes, checks and schema (:meth:`load`), its Dask task and its time series files."""
    ssp: str
    names: List[str]
    points: List[tuple]
    settings: SystemSettings
    out: str
    timeseries_dir: Optional[str] = None
    chunk_size: Optional[int] = None

    @property
    def label(self) -> str:
        return Path(self.ssp).stem

    columns: List[str] = field(default_factory=list, init=False, repr=False)  # a row's values (set by load)

    @property
    def task(self):
        """The Dask task of a chunk of points (after :meth:`load`, which knows the row's columns)."""
        import functools

        return functools.partial(run_system_chunk, columns=list(self.columns))

    def spec(self, sha: str) -> dict:
        """What identifies the sweep for --resume."""
        return {"ssp_sha256": sha, "names": self.names, "points": [list(p) for p in self.points],
                "settings": asdict(self.settings), "timeseries": bool(self.timeseries_dir)}

    def load(self):
        """Check the sweep against the package before anything runs (every name, value, option
        and summary); returns (package bytes, sha256, Parquet schema)."""
        import zipfile

        from pogofmu.ssp.master import check_options, time_span
        from pogofmu.ssp.package import SSPError, read_ssd, unpack
        from pogofmu.ssp.validate import apply_overrides, validate

        path = Path(self.ssp)
        if not path.is_file():
            raise SweepError(f"SSP {path}: no such file (build it with build_fmu.py, or python3 tasks.py build)")
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise SweepError(f"SSP {path}: cannot be read ({exc.strerror or exc})") from None
        if not zipfile.is_zipfile(path):
            raise SweepError(f"SSP {path}: not an SSP package (not a zip archive)")
        s = self.settings
        try:
            check_options(s.step, s.stop_time, None, **{k: v for k, v in s.options().items()
                                                       if k not in ("parameters", "stop_time", "step")})
            with tempfile.TemporaryDirectory(prefix="pogofmu-sweep-") as tmp:
                system = read_ssd(unpack(path, Path(tmp)))
                selected = validate(system, s.parameters)
                time_span(system, None, s.stop_time, s.step)
                for j, name in enumerate(self.names):  # every swept name, with its first value
                    apply_overrides(system, selected, {name: self.points[0][j]})
                    comp, _, param = name.partition(".")
                    if _is_integer(system.components[comp].variables[param].type):
                        bad = [p[j] for p in self.points if p[j] != int(p[j])]
                        if bad:
                            raise SweepError(f"parameter {name} is an integer: value {bad[0]!r} is not integral")
                apply_overrides(system, selected, s.fixed)
                schema = self._schema(system)
                values = schema.names[len(self.names) + 4:]  # (after run_id, the names, status, message, wall_s)
                self.columns = values
                return data, hashlib.sha256(data).hexdigest(), schema
        except SSPError as exc:
            raise SweepError(f"SSP {path}: {one_line(exc)}") from None

    def _schema(self, system):
        import pyarrow as pa

        typ = lambda t: pa.int64() if _is_integer(t) else pa.float64()  # noqa: E731
        fields = [("run_id", pa.int64())]
        for name in self.names:
            comp, _, param = name.partition(".")
            fields.append((name, typ(system.components[comp].variables[param].type)))
        fields += [("status", pa.string()), ("message", pa.string()), ("wall_s", pa.float64())]
        for cname, comp in system.components.items():
            fields += [(f"{cname}.{c.name}:final", typ(c.type)) for c in comp.connectors.values()
                       if c.kind == "output"]
        fields.append(("events", pa.int64()))
        fields += [(f"{cname}:events", pa.int64()) for cname in system.components]
        have = {f[0] for f in fields}
        for spec in self.settings.summaries:
            comp, con, kind = parse_summary(spec)
            if comp not in system.components:
                raise SweepError(f"--summary {spec!r}: {comp!r} is not a component of system {system.name!r} "
                                 f"(components: {', '.join(system.components)})")
            if con is not None and con not in system.components[comp].connectors:
                raise SweepError(f"--summary {spec!r}: {con!r} is not a connector of Component {comp} (connectors: "
                                 f"{', '.join(system.components[comp].connectors)})")
            column = f"{comp}.{con}:{kind}" if con is not None else f"{comp}:{kind}"
            if column in have:
                continue
            have.add(column)
            if con is None:
                fields.append((column, pa.int64() if kind == "events" else pa.float64()))
            else:
                ctype = system.components[comp].connectors[con].type
                fields.append((column, pa.float64() if kind in ("mean", "t_min", "t_max") else typ(ctype)))
        return pa.schema(fields)

    def write_series(self, folder: Path, run_id: int, data):
        """A run's CSV (the bytes a worker sent) as ``folder/run_id=N/timeseries.csv``."""
        part = folder / f"run_id={run_id}"
        part.mkdir(parents=True, exist_ok=True)
        tmp = part / (SERIES_FILE + ".tmp")
        tmp.write_bytes(data)
        tmp.replace(part / SERIES_FILE)


# ---- in a worker ----------------------------------------------------------------------------

def summarize(series, t, columns, sources):
    """A row's values (the schema's ``columns``) from a run's table: ``series`` maps a recorded
    column (``Component.connector``) to its array over the rows, at times ``t``; ``sources`` are
    the master's ``[(t, components)]`` of every event instant."""
    import numpy as np

    out = {}
    for col in columns:
        target, _, kind = col.rpartition(":")
        if not target and col == "events":
            out["events"] = len(sources)
            continue
        if "." not in target:  # Component:KIND
            times = [ts for ts, comps in sources if target in comps]
            out[col] = len(times) if kind == "events" else (
                (times[0] if kind == "first_event" else times[-1]) if times else None)
            continue
        v = series[target]
        if kind == "final":
            x = v[-1]
        elif kind == "initial":
            x = v[0]
        elif kind == "min":
            x = v.min()
        elif kind == "max":
            x = v.max()
        elif kind == "t_min":
            x = t[int(np.argmin(v))]
        elif kind == "t_max":
            x = t[int(np.argmax(v))]
        else:  # mean: trapezoidal (a left and a right limit share their time: the jump has no area)
            span = t[-1] - t[0]
            x = float(np.sum(0.5 * (v[1:] + v[:-1]) * np.diff(t)) / span) if span > 0 else float(v[0])
        out[col] = x.item() if hasattr(x, "item") else x
    return out


def run_point(ssp: Path, point: Dict[str, float], settings: SystemSettings, columns: List[str]):
    """One run of the system at ``point``; returns (row, CSV bytes or None). Never raises for a
    failed run: its row says why."""
    import contextlib
    import io

    from pogofmu.ssp.master import simulate
    from pogofmu.ssp.package import SSPError
    from pogofmu.ssp.record import CSVStream

    overrides = dict(settings.fixed)
    overrides.update(point)
    row = {"status": "ok", "message": ""}
    series = None
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="pogofmu-run-") as tmp:
        csv_path = Path(tmp) / SERIES_FILE
        sink = None
        if settings.timeseries:
            def sink(names, types, units, span):
                return CSVStream(csv_path, names, types, units, span)
        try:
            # the FMUs' own messages (a warning, the reason of a failure) are the run's, not the worker's
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                rec = simulate(ssp, echo_log=False, sink=sink, overrides=overrides, **settings.options())
            if settings.timeseries:
                series = csv_path.read_bytes()
                table = _read_csv(csv_path, rec.names)
            else:
                table = {n: rec[n] for n in rec.names}
            row.update(summarize(table, table["time"], columns, rec.event_sources))
        except SSPError as exc:
            row.update(status="error", message=one_line(exc))
        except Exception as exc:  # noqa: BLE001 - a run never takes the sweep down
            row.update(status="error", message=f"{type(exc).__name__}: {exc}")
    row["wall_s"] = time.perf_counter() - t0
    return row, series


def _read_csv(path: Path, names):
    """The columns of a run's CSV, as written (the CSV holds each float's shortest repr: read
    back, it is the same double)."""
    import numpy as np
    import pyarrow.csv as pcsv

    table = pcsv.read_csv(path)
    return {n: np.asarray(table.column(n).to_numpy()) for n in names}


def run_system_chunk(key: str, data: bytes, names, chunk, settings: SystemSettings, columns=None):
    """Dask task: run [(run_id, point), ...] of the package whose bytes hash to ``key``; returns
    [(row, CSV bytes or None), ...]."""
    from .runner import worker_copy

    ssp = worker_copy(key, data, "system.ssp")
    out = []
    for run_id, point in chunk:
        values = dict(zip(names, point))
        row, series = run_point(ssp, values, settings, columns)
        out.append(({"run_id": run_id, **values, **row}, series))
    return out
