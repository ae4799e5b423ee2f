"""The command line of the SSP master: ``run`` and ``check``."""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from .algorithms import INPUTS
from .master import ALGORITHMS, DEFAULT_EVENT_TOLERANCE, DEFAULT_INPUTS, simulate
from .package import SSPError, read_ssd, unpack
from .plot import plot
from .record import CSVStream
from .validate import selectable_sets, validate

def prepare_out(out: Path, *files: Path):
    """The output folder, created, and proven writable before the first step (never after the run)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise SSPError(f"output folder {str(out)!r} (--out) is an existing file, not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise SSPError(f"output folder {str(out)!r} (--out) cannot be written: {exc.strerror or exc}") from None
    for f in files:
        if f.is_dir():
            raise SSPError(f"output file {str(f)!r} is a folder: remove it or choose another --out")


def run(ssp, parameters=None, stop_time=None, step=1e-3, out=None, algorithm="gauss-seidel", progress=True,
        **options):
    """The ``run`` command: simulate, streaming ``<out>/<set>.csv``, then draw ``<out>/<set>.png``;
    ``options`` go to :func:`~.master.simulate` (``events``, ``event_tolerance``, ``rel_tol``, ...).

    The package, the numbers and the output folder are all checked before the first step."""
    ssp = Path(ssp)
    out = Path(out) if out is not None else Path("results") / ssp.stem
    tag = parameters or "default"
    csv_path, png_path = out / f"{tag}.csv", out / f"{tag}.png"
    opened = []

    def open_csv(names, types, units, span):  # called once the package and the numbers are valid
        prepare_out(out, csv_path, png_path)
        try:
            opened.append(CSVStream(csv_path, names, types, units, span, threads=options.get("threads", 1)))
        except OSError as exc:
            raise SSPError(f"cannot write {csv_path}: {exc.strerror or exc}") from None
        return opened[0]

    try:
        rec = simulate(ssp, parameters, stop_time, step, algorithm=algorithm, progress=progress, sink=open_csv,
                       **options)
    except SSPError as exc:
        if opened and opened[0].rows:
            s = opened[0]
            raise SSPError(f"{exc}\n  the {s.rows} rows up to t = {s.last_time:.10g} s are in {s.incomplete}") from None
        raise
    try:
        how = algorithm if algorithm == "model-exchange" else \
            f"{algorithm}, {'events synchronized' if rec.events else 'fixed step'}"
        plot(rec, png_path, f"{rec.system} ({rec.parameter_set}): {how}, output step {step:g} s", rec.connections)
    except OSError as exc:
        raise SSPError(f"cannot write {png_path}: {exc.strerror or exc} (the results are in {csv_path})") from None
    print(f"{rec.system}: simulated to t = {rec.last_time:.6g} s{warned(rec.warnings)} -> {csv_path}, {png_path}")
    return rec, csv_path, png_path


def warned(warnings) -> str:
    """The last line's count of the components' warnings, and the first of them (a warning printed
    amid the progress lines says the result may not be what the model meant: a bounce that let the
    ball through its floor)."""
    if not warnings:
        return ""
    name, text = warnings[0]
    text = text[len(name) + 2:] if text.startswith(name + ": ") else text  # (an FMU that names itself)
    first = text if len(text) <= 200 else text[:200] + "..."
    count = f"{len(warnings)} warning" + ("s" if len(warnings) > 1 else "")
    return f", with {count} of the components (printed above; the first: {name}: {first})"


def parse_sets(texts) -> dict:
    """``--set Component.parameter=VALUE`` options -> ``{"Component.parameter": value}`` (checked
    against the system by :func:`~.validate.apply_overrides`)."""
    import math

    out = {}
    for text in texts:
        name, sep, value = text.partition("=")
        name = name.strip()
        if not sep or "." not in name or not value.strip():
            raise SSPError(f"--set {text!r}: expected COMPONENT.PARAMETER=VALUE, e.g. PogoStick.k=120")
        try:
            number = float(value)
        except ValueError:
            raise SSPError(f"--set {text!r}: {value.strip()!r} is not a number") from None
        if not math.isfinite(number):
            raise SSPError(f"--set {text!r}: {value.strip()!r} is not a finite number")
        if name in out:
            raise SSPError(f"--set {text!r}: {name} is set twice")
        out[name] = number
    return out


def _on_off(text):
    if text not in ("on", "off"):
        raise argparse.ArgumentTypeError(f"{text!r}: on or off")
    return text == "on"


def _threads(text):
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: a whole number of threads >= 1") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: a whole number of threads >= 1")
    return n


def main(argv=None, prog="pogofmu ssp"):
    """The command line (``run`` / ``check``); returns the exit status. ``prog`` names the command
    in the usage text (a console command forwarding here may pass its own)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--debug", action="store_true",
                        help="show the Python traceback of an unexpected error (also: POGOFMU_DEBUG=1)")
    ap = argparse.ArgumentParser(prog=prog, description="SSP master built on fmpy")
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", parents=[common], help="simulate an .ssp (events synchronized, or strongly coupled)")
    r.add_argument("ssp")
    r.add_argument("--parameters", help="parameter set: resources/NAME.ssv (default: the .ssd's bindings)")
    r.add_argument("--stop-time", type=float, help="default: the .ssd's DefaultExperiment stopTime")
    r.add_argument("--step", type=float, default=1e-3,
                   help="communication step = output grid [s] (default 1e-3)")
    r.add_argument("--algorithm", choices=ALGORITHMS, default="gauss-seidel",
                   help="gauss-seidel (default) or jacobi co-simulation; model-exchange: the components' "
                        "equations integrated together (FMI 3.0 model exchange, CVODE)")
    r.add_argument("--events", type=_on_off, default=True, metavar="on|off",
                   help="on (default): every component is brought to each event instant; off: a fixed "
                        "communication step (libcosim's algorithm)")
    r.add_argument("--event-tolerance", type=float, default=DEFAULT_EVENT_TOLERANCE,
                   help="[s] bisection tolerance of an event of an FMI 2.0 FMU of another tool (a change of a "
                        "discrete output; this project's FMUs report the exact time)")
    r.add_argument("--inputs", choices=INPUTS, default=DEFAULT_INPUTS,
                   help="Gauss-Seidel: interpolate (default): a component that can interpolate its inputs "
                        "(FMI 2.0 canInterpolateInputs) gets each real input from a component already stepped "
                        "as the line between its values at the step's start and end; hold: every input held "
                        "over a step")
    r.add_argument("--rel-tol", type=float, default=1e-10, help="model-exchange integrator's relative tolerance")
    r.add_argument("--abs-tol", type=float, default=1e-12, help="model-exchange integrator's absolute tolerance")
    r.add_argument("--threads", type=_threads, default=1, metavar="N",
                   help="step the independent components of a macro step (none feeding another: e.g. a "
                        "mirror's actuators) on N threads (default 1); the results are those of 1 thread, to the bit")
    r.add_argument("--record", metavar="PATTERN",
                   help="the columns to record: glob patterns over component.connector, comma-separated "
                        "(e.g. 'Actuator_*.z,Reconstructor.piston_rms'; default: every connector)")
    r.add_argument("--set", action="append", default=[], metavar="COMPONENT.PARAMETER=VALUE",
                   help="a parameter value over the parameter set, e.g. PogoStick.k=120 (repeatable)")
    r.add_argument("--out", help="output folder (default results/<SSP name>)")
    r.add_argument("--quiet", action="store_true", help="no progress lines")
    c = sub.add_parser("check", parents=[common],
                       help="validate an .ssp (structure, FMUs, units, parameter sets) without running")
    c.add_argument("ssp")
    c.add_argument("--parameters")
    args = ap.parse_args(argv)
    try:
        if args.command == "check":
            with tempfile.TemporaryDirectory() as tmp:
                system = read_ssd(unpack(Path(args.ssp), Path(tmp)))
                validate(system, args.parameters)
                print(f"{args.ssp}: system {system.name!r} is valid: components {system.update_order()}, "
                      f"{len(system.connections)} connections, parameter sets "
                      f"{selectable_sets(system)}")
            return 0
        run(args.ssp, args.parameters, args.stop_time, args.step, args.out, args.algorithm, not args.quiet,
            events=args.events, event_tolerance=args.event_tolerance, rel_tol=args.rel_tol, abs_tol=args.abs_tol,
            threads=args.threads, record=args.record, inputs=args.inputs, overrides=parse_sets(args.set))
    except SSPError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the last resort: one line, never a traceback by default
        if args.debug or os.environ.get("POGOFMU_DEBUG", "") not in ("", "0"):
            raise
        print(f"error: unexpected {type(exc).__name__}: {exc} -- this is a bug of pogofmu, please report it "
              f"(run again with --debug or POGOFMU_DEBUG=1 for the traceback)", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())

