"""What a sweep is: its points (grids and Monte Carlo samples, parsed from the command line's
specifications), its settings, and the checks of both against the FMU before any worker starts."""
from __future__ import annotations

import hashlib
import itertools
import math
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Dict, List, Optional

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


class SweepError(Exception):
    """The sweep cannot be run as specified; the message names the option, its value and the rule."""


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


@dataclass
class Sweep:
    fmu: str
    names: List[str]
    points: List[tuple]
    settings: Settings
    out: str
    timeseries_dir: Optional[str] = None
    chunk_size: Optional[int] = None

    @property
    def label(self) -> str:
        return Path(self.fmu).stem

    def spec(self, sha: str) -> dict:
        """What identifies the sweep for --resume."""
        return {"fmu_sha256": sha, "names": self.names, "points": [list(p) for p in self.points],
                "settings": asdict(self.settings), "timeseries": bool(self.timeseries_dir)}


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


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
