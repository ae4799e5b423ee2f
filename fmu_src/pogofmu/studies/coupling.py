"""``pogofmu study coupling``: the SpaceHopper's first-apex error against the communication step,
for every master algorithm, on the Moon and the Earth — one CSV, one log-log figure, the slopes.

The reference is the continuous-time closed loop (:mod:`pogofmu.references.closed_loop`: the thrust law
inside a scipy ODE); the first apex of each run is read from its first flight row after the
first contact whose held thrust is zero (``y + ydot^2/(2 g)``, exact in flight). Algorithms:

* ``gauss-seidel`` and ``jacobi`` with a fixed step (``--events off``), and libcosim's
  fixed-step (Jacobi) algorithm where libcosimpy is installed — the masters of today;
* ``fmi2-rollback`` and ``fmi3-early-return``: the event-synchronized master on the FMI 2.0 and
  the FMI 3.0 package (Gauss–Seidel), ``fmi2-rollback-jacobi`` and ``fmi3-early-return-jacobi``
  the same with Jacobi between the events;
* ``model-exchange``: the strongly coupled solution, ``--step`` its output grid only.

Host-side code; never imported inside an FMU.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import re
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

STEPS = (1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1)
STOP = {"moon": 2.1, "earth": 0.9, "ceres": 6.0}  # past the first apex; a whole number of every step
ALGORITHMS = {  # name: (package, simulate keywords)
    "gauss-seidel": ("fmi2", dict(events=False)),
    "jacobi": ("fmi2", dict(algorithm="jacobi", events=False)),
    "libcosim": ("fmi2", None),
    "fmi2-rollback": ("fmi2", dict(events=True)),
    "fmi3-early-return": ("fmi3", dict(events=True)),
    "fmi2-rollback-jacobi": ("fmi2", dict(algorithm="jacobi", events=True)),
    "fmi3-early-return-jacobi": ("fmi3", dict(algorithm="jacobi", events=True)),
    "model-exchange": ("fmi3", dict(algorithm="model-exchange")),
}
STYLES = {"gauss-seidel": ("o", "-"), "jacobi": ("s", "-"), "libcosim": ("x", "--"), "fmi2-rollback": ("^", "-"),
          "fmi3-early-return": ("v", "--"), "fmi2-rollback-jacobi": ("<", "-"), "fmi3-early-return-jacobi": (">", "--"),
          "model-exchange": ("D", "-")}  # (equal curves stay visible)
LABELS = {"gauss-seidel": "Gauss-Seidel, fixed step", "jacobi": "Jacobi, fixed step",
          "libcosim": "libcosim (Jacobi, fixed step)", "fmi2-rollback": "FMI 2.0 rollback (events synchronized)",
          "fmi3-early-return": "FMI 3.0 early return (events synchronized)",
          "fmi2-rollback-jacobi": "FMI 2.0 rollback, Jacobi (events synchronized)",
          "fmi3-early-return-jacobi": "FMI 3.0 early return, Jacobi (events synchronized)",
          "model-exchange": "model exchange (strongly coupled, CVODE)"}


class StudyError(Exception):
    pass


def parameter_values(package: Path, body: str) -> dict:
    """The values of the package's ``resources/<body>.ssv`` (read with the master's reader)."""
    from ..ssp.package import SSPError, read_ssv

    with tempfile.TemporaryDirectory() as tmp:
        with zipfile.ZipFile(package) as z:
            try:
                z.extract(f"resources/{body}.ssv", tmp)
            except KeyError:
                raise StudyError(f"{package} has no parameter set {body!r}") from None
        problems = []
        try:
            ps = read_ssv(Path(tmp) / "resources" / f"{body}.ssv", f"resources/{body}.ssv", problems)
        except SSPError as exc:
            raise StudyError(str(exc)) from None
    return {p.name: p.value for p in ps.parameters}


def libcosim_available() -> bool:
    try:
        import libcosimpy  # noqa: F401
    except ImportError:
        return False
    return True


def _libcosim_package(package: Path, body: str, dest: Path) -> Path:
    """The package with every ParameterBinding pointing at ``<body>.ssv`` (libcosim applies a
    component's first binding and has no option to choose a set)."""
    out = dest / f"{package.stem}-{body}.ssp"
    with zipfile.ZipFile(package) as z, zipfile.ZipFile(out, "w") as w:
        for item in z.infolist():
            data = z.read(item)
            if item.filename == "SystemStructure.ssd":
                text = data.decode()
                # the whole set or a component's part of it (resources/<body>.<Component>.ssv)
                text = re.sub(r'source="resources/(?:%s)((?:\.\w+)?)\.ssv"' % "|".join(STOP),
                              lambda m: f'source="resources/{body}{m.group(1)}.ssv"', text)
                data = text.encode()
            w.writestr(item, data)
    return out


def _run_libcosim(package: Path, body: str, step: float, stop: float, tmp: Path):
    n = int(round(stop / step))
    payload = json.dumps({"ssp": str(_libcosim_package(package, body, tmp)), "step": step, "n_steps": n,
                          "variables": {"PogoStick": ["y", "ydot", "s", "F_ext"]}})
    proc = subprocess.run([sys.executable, "-m", "pogofmu.ssp.libcosim_runner", "-"], input=payload, capture_output=True,
                          text=True, timeout=3600)
    if proc.returncode:
        raise StudyError(f"libcosim failed ({proc.returncode}): {proc.stderr.strip().splitlines()[-1:]}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    import numpy as np

    p = parameter_values(package, body)
    return {"PogoStick.y": np.r_[p["y_0"], out["samples"]["PogoStick.y"]],
            "PogoStick.ydot": np.r_[0.0, out["samples"]["PogoStick.ydot"]],
            "PogoStick.s": np.r_[0, out["samples"]["PogoStick.s"]],
            "PogoStick.F_ext": np.r_[0.0, out["samples"]["PogoStick.F_ext"]]}, n + 1


def run_study(out: Path, packages: dict, bodies, steps, algorithms, progress=True):
    from ..references.closed_loop import apex_of_run, first_apex
    from ..ssp import SSPError, simulate

    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory(prefix="pogofmu_coupling_") as tmp:
        for body in bodies:
            p = parameter_values(packages["fmi2"], body)
            ref = first_apex(p)
            stop = STOP[body]
            for algo in algorithms:
                pkg_key, kwargs = ALGORITHMS[algo]
                for h in steps:
                    t0 = time.process_time()
                    status, apex, n_rows = "ok", None, 0
                    try:
                        if algo == "libcosim":
                            res, n_rows = _run_libcosim(packages[pkg_key], body, h, stop, Path(tmp))
                        else:
                            res = simulate(packages[pkg_key], parameters=body, stop_time=stop, step=h,
                                           echo_log=False, **kwargs)
                            n_rows = res.rows
                        apex = apex_of_run(res, p["g"])
                        if apex is None:
                            status = "no flight row after the first contact"
                    except (SSPError, StudyError) as exc:
                        status = f"failed: {str(exc).splitlines()[0]}"
                    cpu = time.process_time() - t0
                    err = abs(apex - ref) if apex is not None else None
                    rows.append({"body": body, "algorithm": algo, "step_s": h, "first_apex_m": apex,
                                 "reference_m": ref, "error_m": err, "status": status, "cpu_s": cpu,
                                 "rows": n_rows})
                    if progress:
                        print(f"{body:6s} {algo:18s} h = {h:<7g} error = "
                              f"{'-' if err is None else f'{err:.3g} m':>10s}  ({status}, {cpu:.1f} s CPU)", flush=True)
    fields = list(rows[0])
    with (out / "coupling.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for r in rows:
            w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    slopes = fit_slopes(rows)
    for (body, algo), s in sorted(slopes.items()):
        print(f"slope {body:6s} {LABELS[algo]:50s} {'-' if s is None else f'{s:.2f}'}")
    draw(rows, slopes, out / "coupling.png", bodies, algorithms)
    print(f"wrote {out / 'coupling.csv'}, {out / 'coupling.png'}")
    return rows, slopes


ERROR_FLOOR = 1e-10  # m: below it an error is the solver's, not the coupling's (left out of the slope)


def fit_slopes(rows):
    """Least-squares slope of log(error) against log(step) per (body, algorithm), over the runs
    whose error lies above ERROR_FLOOR (None with fewer than two)."""
    out = {}
    keys = sorted({(r["body"], r["algorithm"]) for r in rows})
    for key in keys:
        pts = [(math.log10(r["step_s"]), math.log10(r["error_m"])) for r in rows
               if (r["body"], r["algorithm"]) == key and r["error_m"] is not None and r["error_m"] > ERROR_FLOOR]
        if len(pts) < 2:
            out[key] = None
            continue
        mx = sum(x for x, _ in pts) / len(pts)
        my = sum(y for _, y in pts) / len(pts)
        sxx = sum((x - mx) ** 2 for x, _ in pts)
        out[key] = sum((x - mx) * (y - my) for x, y in pts) / sxx if sxx > 0 else None
    return out


def draw(rows, slopes, path: Path, bodies, algorithms):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(bodies), figsize=(6.2 * len(bodies), 5.2), squeeze=False)
    for ax, body in zip(axes[0], bodies):
        for algo in algorithms:
            pts = [(r["step_s"], max(r["error_m"], 1e-13)) for r in rows
                   if r["body"] == body and r["algorithm"] == algo and r["error_m"] is not None]
            if not pts:
                continue
            s = slopes.get((body, algo))
            marker, line = STYLES[algo]
            ax.loglog(*zip(*pts), marker=marker, ls=line, ms=5, lw=1, mfc="none",
                      label=f"{LABELS[algo]} (slope {'-' if s is None else f'{s:.2f}'})")
        ax.axhline(ERROR_FLOOR, color="0.6", lw=0.8, ls=":")
        ax.set_xlabel("communication step h [s] (model exchange: output step)")
        ax.set_ylabel("first-apex error against the continuous closed loop [m]")
        ax.set_title(f"SpaceHopper on the {body.capitalize()}", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    fig.suptitle("Coupling error of the master algorithms (pogofmu study coupling)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _steps(text):
    try:
        steps = [float(a) for a in text.split(",") if a.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: a comma-separated list of steps in seconds") from None
    if not steps or not all(math.isfinite(h) and h > 0 for h in steps):
        raise argparse.ArgumentTypeError(f"{text!r}: every step must be a finite number > 0")
    return steps


def add_parser(sub):
    co = sub.add_parser("coupling", help="first-apex error vs communication step for every master algorithm")
    co.add_argument("--out", default="results/coupling", help="output folder")
    co.add_argument("--ssp", default="dist/SpaceHopper.ssp", help="the FMI 2.0 package")
    co.add_argument("--ssp-fmi3", default="dist/SpaceHopper-fmi3.ssp", help="the FMI 3.0 package")
    co.add_argument("--steps", type=_steps, default=list(STEPS), help="comma-separated steps [s] "
                    f"(default {','.join(f'{h:g}' for h in STEPS)})")
    co.add_argument("--bodies", default="moon,earth", help="parameter sets (default moon,earth)")
    co.add_argument("--algorithms", default=",".join(ALGORITHMS),
                    help=f"comma-separated, of {', '.join(ALGORITHMS)} (default: all; libcosim where installed)")
    co.add_argument("--quiet", action="store_true", help="no line per run")
    return co


def main(args) -> int:
    packages = {"fmi2": Path(args.ssp), "fmi3": Path(args.ssp_fmi3)}
    for key, path in packages.items():
        if not path.is_file():
            raise StudyError(f"--{'ssp' if key == 'fmi2' else 'ssp-fmi3'} {path}: no such file (build_fmu.py builds it)")
    bodies = [b for b in args.bodies.split(",") if b]
    for b in bodies:
        if b not in STOP:
            raise StudyError(f"--bodies: {b!r} is not one of {', '.join(STOP)}")
    algorithms = [a for a in args.algorithms.split(",") if a]
    for a in algorithms:
        if a not in ALGORITHMS:
            raise StudyError(f"--algorithms: {a!r} is not one of {', '.join(ALGORITHMS)}")
    if "libcosim" in algorithms and not libcosim_available():
        print("libcosim left out: libcosimpy is not installed (pip install libcosimpy)", file=sys.stderr)
        algorithms.remove("libcosim")
    for h in args.steps:
        for b in bodies:
            n = round(STOP[b] / h)
            if abs(n * h - STOP[b]) > 1e-9 * STOP[b]:
                raise StudyError(f"--steps: {h:g} s does not divide the {b} run of {STOP[b]:g} s into whole steps")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise StudyError(f"--out {out}: an existing file, not a folder")
    run_study(out, packages, bodies, args.steps, algorithms, progress=not args.quiet)
    return 0


__all__ = ["run_study", "fit_slopes", "add_parser", "main", "StudyError"]
