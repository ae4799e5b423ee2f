"""``pogofmu sweep``: the command line, parsed into a Sweep and run (errors are one line)."""
from __future__ import annotations

import sys
from pathlib import Path

from .cluster import execute
from .parquet import failed_runs
from .spec import Settings, Sweep, SweepError, _number, make_points, parse_grid, parse_sample

def add_arguments(ap):
    """The options of a sweep shared by ``pogofmu sweep`` and the studies (cluster and output)."""
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--workers", type=int, help="local worker processes (default: every core)")
    g.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")


def _is_system(argv) -> bool:
    """Whether the positional argument is an SSP package (``*.ssp``): a system sweep."""
    takes_value = {"--grid", "--sample", "--samples", "--seed", "--set", "--stop-time", "--step", "--outputs",
                   "--timeseries", "--chunk-size", "--out", "--workers", "--scheduler", "--parameters",
                   "--algorithm", "--events", "--event-tolerance", "--inputs", "--rel-tol", "--abs-tol", "--summary"}
    skip = False
    for a in argv:
        if skip:
            skip = False
            continue
        if a.startswith("-"):
            skip = a in takes_value
            continue
        return a.lower().endswith(".ssp")
    return False


def sweep_main(argv, prog="pogofmu sweep"):
    import argparse

    argv = list(argv)
    system = _is_system(argv)
    ap = argparse.ArgumentParser(prog=prog, description=(
        "Run an FMU, or a system (an .ssp, with the SSP master), for every point of a grid (Cartesian "
        "product) and/or for Monte Carlo samples on Dask; one Parquet row per run. "
        + ("This is the system sweep's help." if system else
           "A system's options (--parameters, --algorithm, --summary, ...): pogofmu sweep SYSTEM.ssp --help.")))
    ap.add_argument("fmu", metavar="FMU|SSP", help="the FMU file, e.g. dist/PogoStick.fmu, or an SSP package, "
                                                   "e.g. dist/native/SpaceHopper.ssp (its names are Component.parameter)")
    ap.add_argument("--grid", action="append", default=[], metavar="NAME=a:b:n|NAME=v1,v2,...",
                    help="n values from a to b, or a list; several --grid span the Cartesian product")
    ap.add_argument("--sample", action="append", default=[], metavar="NAME=DIST(a,b)",
                    help="uniform(low,high), loguniform(low,high), normal(mean,sd), lognormal(mu,sigma) "
                         "(mu, sigma of log NAME)")
    ap.add_argument("--samples", type=int, help="number of Monte Carlo samples (per grid point)")
    ap.add_argument("--seed", type=int, default=0, help="seed of numpy's default_rng (default 0)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a parameter value common to every run")
    ap.add_argument("--stop-time", type=float, help="[s] (default: the FMU's or the system's default experiment)")
    if system:
        from pogofmu.ssp.algorithms import INPUTS
        from pogofmu.ssp.cli import _on_off
        from pogofmu.ssp.master import ALGORITHMS, DEFAULT_EVENT_TOLERANCE, DEFAULT_INPUTS

        ap.add_argument("--step", type=float, default=1e-3, help="communication step = output grid [s] (default 1e-3)")
        ap.add_argument("--parameters", help="parameter set: resources/NAME.ssv (default: the .ssd's bindings)")
        ap.add_argument("--algorithm", choices=ALGORITHMS, default="gauss-seidel", help="as pogofmu ssp run")
        ap.add_argument("--events", type=_on_off, default=True, metavar="on|off", help="as pogofmu ssp run")
        ap.add_argument("--event-tolerance", type=float, default=DEFAULT_EVENT_TOLERANCE, help="as pogofmu ssp run")
        ap.add_argument("--inputs", choices=INPUTS, default=DEFAULT_INPUTS, help="as pogofmu ssp run")
        ap.add_argument("--rel-tol", type=float, default=1e-10, help="as pogofmu ssp run (model exchange)")
        ap.add_argument("--abs-tol", type=float, default=1e-12, help="as pogofmu ssp run (model exchange)")
        ap.add_argument("--summary", action="append", default=[], metavar="COMPONENT.CONNECTOR:KIND|COMPONENT:KIND",
                        help="a column of every row: min, max, final, initial, mean, t_min, t_max of a connector; "
                             "first_event, last_event, events of a component")
        ap.add_argument("--timeseries", metavar="DIR", help="also write every run's CSV (as pogofmu ssp run writes "
                                                            "it) to DIR/run_id=N/timeseries.csv")
    else:
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
        if args.workers is not None and args.workers < 1:
            raise SweepError(f"--workers {args.workers}: must be >= 1")
        if system:
            from .system import SystemSettings, SystemSweep

            settings = SystemSettings(parameters=args.parameters, stop_time=args.stop_time, step=args.step,
                                      algorithm=args.algorithm, events=args.events,
                                      event_tolerance=args.event_tolerance, inputs=args.inputs, rel_tol=args.rel_tol,
                                      abs_tol=args.abs_tol, fixed=fixed, summaries=list(args.summary),
                                      timeseries=bool(args.timeseries))
            # a run's CSV travels to the client with its row: few runs per task
            chunk = args.chunk_size or (4 if args.timeseries else None)
            sweep = SystemSweep(args.fmu, names, points, settings, args.out, args.timeseries, chunk)
        else:
            outputs = None
            if args.outputs is not None:
                outputs = [o.strip() for o in args.outputs.split(",") if o.strip()]
                if not outputs:
                    raise SweepError(f"--outputs {args.outputs!r}: names no output (comma-separated output names)")
            settings = Settings(stop_time=args.stop_time, step=args.step, events=args.events, outputs=outputs,
                                timeseries=bool(args.timeseries), fixed=fixed)
            sweep = Sweep(args.fmu, names, points, settings, args.out, args.timeseries, args.chunk_size)
        status = execute(sweep, args.workers, args.scheduler, resume=args.resume, overwrite=args.overwrite,
                         progress=not args.no_progress)
        return status or (1 if failed_runs(Path(args.out)) else 0)
    except SweepError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
