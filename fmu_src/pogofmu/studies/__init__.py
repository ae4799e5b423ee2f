"""Studies built on the sweep (``pogofmu study NAME``), each writing CSV + PNG (+ the sweep's Parquet).

* ``work-precision`` — the paper's Figs 21-22 for PogoStick.fmu: the largest event-time error
  against the closed form over the 19 events of the default drop, against ``rel_tol`` (1e-3 ...
  1e-12), for method 5 (Dormand-Prince 5(4)) and 8 (DOP853), with ``max_step`` 0.01 s and
  unbounded (0), and the number of events located in the 10 s; and the work-accuracy diagram:
  the global error of the state at the stop time (against the closed form) against the work —
  flow evaluations, counted, and CPU time — for the FMU's engine and for scipy's ``solve_ivp``
  RK45 (ode45's pair) and DOP853 at the same tolerances, both integrating the same model
  functions with a restart loop at their own located events.
* ``soil`` — Monte Carlo of Penetrator.fmu over an uncertain Hunt-Crossley soil (K, n, c_r):
  distributions of the deepest penetration ``delta_max``, the first rebound height (apex of the
  mass after the first liftoff) and the number of hops (liftoffs) in the run.
* ``landing`` (:mod:`.landing`) — Monte Carlo of the SpaceHopper *system* (SSP, the master per
  run) over its leg's contact, its controller's gains and gravity: the first touchdown, the
  touchdown speed, the highest apex, the energy at the end.
* ``coupling`` (:mod:`.coupling`) — the first apex's error against the communication step, for
  every master algorithm.

Host-side code (fmpy, dask, pyarrow, matplotlib).
"""
from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path
from typing import Optional

from pogofmu.sweep import Settings, Sweep, SweepError, add_arguments, execute, make_points, parse_sample

TOLERANCES = [10.0 ** -k for k in range(3, 13)]  # 1e-3 ... 1e-12
SOIL_DEFAULTS = [  # the soil of the default drop (K = 1e4 N/m^1.5, n = 1.5, c_r = 0.5), made uncertain
    "K=lognormal(9.2103404,0.5)",  # median 1e4 N/m^n (ln 1e4 = 9.2103404), a factor 1.65 per sigma
    "n=uniform(1.2,1.8)",
    "c_r=uniform(0.2,0.8)",
]


def _read_table(path: Path):
    import pyarrow.parquet as pq

    return pq.read_table(path).to_pylist()


def _write_csv(path: Path, rows, fields):
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for r in rows:
            w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items() if k in fields})


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# =============================================================================================
# work-precision (Figs 21-22)
# =============================================================================================

def reference_times(path: Optional[Path] = None):
    """Closed-form event times [(name, t)] of the default PogoStick drop: computed
    (pogofmu.references.closed_form, 40-digit roots), or read from a CSV with ``event`` and ``time_s``
    columns (``--reference``)."""
    if path is None:
        from pogofmu.references.closed_form import events_as_floats

        return [(e["name"], e["time"]) for e in events_as_floats()]
    if not path.is_file():
        raise SweepError(f"--reference {path}: no such file (a CSV of the closed-form events, columns event "
                         f"and time_s; without --reference they are computed)")
    with path.open() as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    try:
        return [(r["event"], float(r["time_s"])) for r in rows]
    except (KeyError, ValueError, TypeError) as exc:
        raise SweepError(f"--reference {path}: not a table of events with columns event and time_s ({exc})") from None


def event_errors(event_t, event_name, ref):
    """Per located event (in order) its error against the reference event of the same index."""
    out = []
    for i, (t, name) in enumerate(zip(event_t, event_name)):
        if i < len(ref):
            out.append({"index": i + 1, "event": name, "time_s": t, "time_ref_s": ref[i][1],
                        "error_s": abs(t - ref[i][1]), "same_kind": name == ref[i][0]})
    return out


def slope(tols, errs):
    """Least-squares slope of log10(error) against log10(rel_tol)."""
    import numpy as np

    return float(np.polyfit(np.log10(tols), np.log10(errs), 1)[0])


STOP = 10.0  # [s] the default drop's run
ABS_TOL = 1e-12  # the FMU's default abs_tol, used by both solvers


def _counted(model):
    """The model with its flow wrapped to count evaluations: (model, counter list)."""
    from dataclasses import replace

    count = [0]
    if model.bind is not None:
        bind = model.bind

        def counted_bind(q, u, p):
            f = bind(q, u, p)

            def g(t, x):
                count[0] += 1
                return f(t, x)
            return g
        return replace(model, bind=counted_bind), count
    flow = model.flow

    def counted_flow(t, x, q, u, p):
        count[0] += 1
        return flow(t, x, q, u, p)
    return replace(model, flow=counted_flow), count


def engine_work(method: int, max_step: float, rel_tol: float, stop: float = STOP):
    """The FMU's engine (host-side: the same code, the same bits) on the default drop: flow
    evaluations, CPU seconds, events, and the mass state (y, ydot) at ``stop``."""
    import time

    from pogofmu.runtime.solver import Simulator
    from pogofmu.runtime.models import get

    model, count = _counted(get("PogoStick"))
    t0 = time.process_time()
    sim = Simulator(model, {"method": method, "max_step": max_step, "rel_tol": rel_tol, "abs_tol": ABS_TOL},
                    keep_history=True)
    sim.advance(stop)
    cpu = time.process_time() - t0
    names = [v.name for v in model.states]
    return {"n_flow": count[0], "cpu_s": cpu, "n_events": sim.n_events,
            "y": float(sim.x_out[names.index("y")]), "ydot": float(sim.x_out[names.index("ydot")])}


def scipy_work(method: str, max_step: float, rel_tol: float, stop: float = STOP):
    """scipy ``solve_ivp`` (``RK45`` or ``DOP853``) on the same model functions — the flow of the
    mode, the active guards as terminal events with their directions, the jumps applied in a
    restart loop — as a user of scipy would integrate the hybrid model: flow evaluations (its
    ``nfev``), CPU seconds, the located events [(name, t)] and (y, ydot) at ``stop``."""
    import time

    import numpy as np
    from scipy.integrate import solve_ivp

    from pogofmu.runtime.models import get

    model = get("PogoStick")
    p = model.params()
    u = tuple(float(v.start) for v in model.inputs)
    x, q = model.initial(p)
    t, nfev, events = 0.0, 0, []
    t0 = time.process_time()
    while t < stop:
        f = model.bind(q, u, p) if model.bind is not None else (lambda t, x, q=q: model.flow(t, x, q, u, p))
        active = [ev for ev in model.events if ev.active(q)]
        funcs = []
        for ev in active:
            def g(t, y, ev=ev, q=q):
                return ev.guard_t(t, list(y), q, u, p)
            g.terminal, g.direction = True, float(ev.direction)
            funcs.append(g)
        sol = solve_ivp(lambda t, y: f(t, list(y)), (t, stop), list(x), method=method, rtol=rel_tol, atol=ABS_TOL,
                        max_step=max_step or np.inf, events=funcs)
        nfev += sol.nfev
        if sol.status != 1:
            x = list(sol.y[:, -1])
            break
        k = min((i for i, te in enumerate(sol.t_events) if len(te)), key=lambda i: sol.t_events[i][0])
        t = float(sol.t_events[k][0])
        x, q = active[k].jump_t(t, list(sol.y_events[k][0]), q, u, p)
        events.append((active[k].name, t))
    cpu = time.process_time() - t0
    names = [v.name for v in model.states]
    return {"n_flow": int(nfev), "cpu_s": cpu, "events": events, "y": float(x[names.index("y")]),
            "ydot": float(x[names.index("ydot")])}


def work_precision(out: Path, fmu: Path, reference: Optional[Path] = None, workers=None, scheduler=None, progress=True):
    from pogofmu.references.closed_form import basic_state

    ref = reference_times(reference)
    y_ref, ydot_ref = (float(v) for v in basic_state(STOP))
    out.mkdir(parents=True, exist_ok=True)
    names, points = make_points([("method", [5, 8]), ("max_step", [0.01, 0.0]), ("rel_tol", TOLERANCES)])
    # the event times do not depend on the communication grid (README "How the solver works"): 0.1 s
    sweep = Sweep(str(fmu), names, points, Settings(stop_time=10.0, step=0.1, outputs=[], events=True),
                  str(out / "work_precision.parquet"))
    if execute(sweep, workers, scheduler, overwrite=True, progress=progress):
        raise SweepError("interrupted")
    rows, events = [], []
    for r in _read_table(out / "work_precision.parquet"):
        errs = event_errors(r["event_t"] or [], r["event_name"] or [], ref) if r["status"] == "ok" else []
        key = {"method": r["method"], "max_step": r["max_step"], "rel_tol": r["rel_tol"]}
        events += [{**key, **e} for e in errs]
        work = engine_work(r["method"], r["max_step"], r["rel_tol"])
        if work["n_events"] != r["n_events"]:  # the host-side run must be the FMU's
            raise SweepError(f"the engine run of {key} found {work['n_events']} events, the FMU {r['n_events']}")
        rows.append({**key, "status": r["status"], "n_events": r["n_events"], "n_reference": len(ref),
                     "max_event_error_s": max((e["error_s"] for e in errs), default=float("nan")),
                     "wall_s": r["wall_s"], "message": r["message"], "n_flow": work["n_flow"],
                     "cpu_s": work["cpu_s"], "y_error_m": abs(work["y"] - y_ref),
                     "ydot_error_m_s": abs(work["ydot"] - ydot_ref)})
    _write_csv(out / "work_precision.csv", rows, list(rows[0]))
    peer = []
    for method in ("RK45", "DOP853"):
        for max_step in (0.01, 0.0):
            for rel_tol in TOLERANCES:
                w = scipy_work(method, max_step, rel_tol)
                errs = event_errors([t for _, t in w["events"]], [n for n, _ in w["events"]], ref)
                peer.append({"solver": f"scipy {method}", "max_step": max_step, "rel_tol": rel_tol,
                             "n_events": len(w["events"]), "n_reference": len(ref),
                             "max_event_error_s": max((e["error_s"] for e in errs), default=float("nan")),
                             "n_flow": w["n_flow"], "cpu_s": w["cpu_s"], "y_error_m": abs(w["y"] - y_ref),
                             "ydot_error_m_s": abs(w["ydot"] - ydot_ref)})
    _write_csv(out / "work_precision_scipy.csv", peer, list(peer[0]))
    _work_figure(out / "work_precision_work.png", rows, peer, len(ref))
    _write_csv(out / "work_precision_events.csv", events, list(events[0]) if events else ["method"])
    curves = {}
    for r in rows:
        curves.setdefault((r["method"], r["max_step"]), []).append(r)
    plt = _plt()
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7.5, 8.0), sharex=True)
    for (method, max_step), rs in sorted(curves.items()):
        label = f"method {method}, max_step {'0.01 s' if max_step else 'unbounded'}"
        style = dict(marker="o" if method == 5 else "s", ls="-" if max_step else "--", lw=1.0, ms=4)
        full = [r for r in rs if r["n_events"] == len(ref)]
        ax1.loglog([r["rel_tol"] for r in full], [max(r["max_event_error_s"], 1e-17) for r in full],
                   label=label, **style)
        ax2.semilogx([r["rel_tol"] for r in rs], [r["n_events"] if r["n_events"] is not None else 0 for r in rs],
                     label=label, **style)
        fit = [r for r in full if r["max_event_error_s"] > 1e-13 and r["rel_tol"] >= 1e-10]
        if not max_step and len(fit) >= 3:  # with max_step 0.01 the step bound, not rel_tol, sets the error
            print(f"{label}: slope {slope([r['rel_tol'] for r in fit], [r['max_event_error_s'] for r in fit]):.2f} "
                  f"(log error vs log rel_tol, {len(fit)} tolerances above the round-off floor)")
    ax1.loglog(TOLERANCES, TOLERANCES, color="0.6", lw=0.8, label="error = rel_tol [s]")
    ax1.set_ylabel("largest event-time error [s]")
    ax1.set_title("PogoStick.fmu, default drop, 10 s: error against the closed form (Fig. 21)", fontsize=9)
    ax2.axhline(len(ref), color="0.6", lw=0.8)
    ax2.yaxis.set_major_locator(_integer_ticks())
    ax2.set_ylabel("events located in 10 s")
    ax2.set_xlabel("rel_tol")
    ax2.set_title(f"number of events (closed form: {len(ref)}) (Fig. 22)", fontsize=9)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "work_precision.png", dpi=110)
    plt.close(fig)
    print(f"wrote {out / 'work_precision.csv'}, {out / 'work_precision_events.csv'}, {out / 'work_precision.png'}, "
          f"{out / 'work_precision_scipy.csv'}, {out / 'work_precision_work.png'}")
    return rows


def _integer_ticks():
    from matplotlib.ticker import MaxNLocator

    return MaxNLocator(integer=True)


def _work_figure(path: Path, rows, peer, n_reference):
    """Work-accuracy (Fig. 21's other half): the global error of y at the stop time against flow
    evaluations and against CPU time, the FMU's engine beside scipy, every run that located every
    event (one that missed some has followed another trajectory)."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), sharey=True)
    curves = {}
    for r in rows:
        label = f"pogofmu method {r['method']}"
        curves.setdefault((label, r["max_step"]), []).append(r)
    for r in peer:
        curves.setdefault((r["solver"], r["max_step"]), []).append(r)
    for (label, max_step), rs in sorted(curves.items()):
        full = [r for r in rs if r["n_events"] == n_reference]
        style = dict(marker="o" if "5" in label or "RK45" in label else "s", ls="-" if max_step else "--", lw=1.0,
                     ms=4, color=("C0" if "5" in label else "C1") if label.startswith("pogofmu") else
                     ("C2" if "RK45" in label else "C3"))
        text = f"{label}, max_step {'0.01 s' if max_step else 'unbounded'}"
        for ax, key in ((axes[0], "n_flow"), (axes[1], "cpu_s")):
            ax.loglog([r[key] for r in full], [max(r["y_error_m"], 1e-17) for r in full], label=text, **style)
    axes[0].set_xlabel("flow evaluations")
    axes[1].set_xlabel("CPU time [s]")
    axes[0].set_ylabel("|y(10 s) - y_exact(10 s)| [m]")
    axes[0].set_title("PogoStick, default drop: global error against work (Fig. 21)", fontsize=9)
    axes[1].set_title("the same against CPU time (this machine)", fontsize=9)
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    axes[1].legend(fontsize=6.5)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# =============================================================================================
# soil Monte Carlo (Penetrator)
# =============================================================================================

def soil_metrics(row, g):
    """delta_max, first rebound height (apex of y after the first liftoff, ballistic: F_ext = 0) and
    number of hops (liftoffs) of one run of the sweep table."""
    if row["status"] != "ok":
        return {"delta_max_m": None, "rebound_height_m": None, "n_hops": None}
    names, states = row["event_name"], row["event_state"]
    lift = [dict(s) for n, s in zip(names, states) if n == "liftoff"]
    apex = lift[0]["y"] + lift[0]["ydot"] ** 2 / (2 * g) if lift else None
    return {"delta_max_m": row["delta_max_final"], "rebound_height_m": apex, "n_hops": len(lift)}


def soil(out: Path, fmu: Path, samples_spec, n_samples, seed, stop_time, workers=None, scheduler=None,
         progress=True):
    import numpy as np
    from fmpy import read_model_description

    out.mkdir(parents=True, exist_ok=True)
    samples = {s[0]: s for s in (parse_sample(t) for t in SOIL_DEFAULTS)}
    samples.update({s[0]: s for s in (parse_sample(t) for t in samples_spec)})
    names, points = make_points([], list(samples.values()), n_samples, seed)
    sweep = Sweep(str(fmu), names, points, Settings(stop_time=stop_time, step=0.01, outputs=["delta_max"],
                                                    events=True), str(out / "soil.parquet"))
    if execute(sweep, workers, scheduler, overwrite=True, progress=progress):
        raise SweepError("interrupted")
    g = float(next(v.start for v in read_model_description(str(fmu)).modelVariables if v.name == "g"))
    rows = []
    for r in _read_table(out / "soil.parquet"):
        rows.append({"run_id": r["run_id"], **{n: r[n] for n in names}, "status": r["status"],
                     **soil_metrics(r, g), "message": r["message"]})
    _write_csv(out / "soil.csv", rows, list(rows[0]))
    ok = [r for r in rows if r["status"] == "ok"]
    plt = _plt()
    fig, axes = plt.subplots(2, 2, figsize=(9, 7))
    specs = ", ".join(f"{n} ~ {d}{a}" for n, d, a in samples.values())
    for ax, key, label in ((axes[0, 0], "delta_max_m", "deepest penetration delta_max [m]"),
                           (axes[0, 1], "rebound_height_m", "first rebound height (apex of y) [m]"),
                           (axes[1, 0], "n_hops", "hops (liftoffs) in the run")):
        vals = np.array([r[key] for r in ok if r[key] is not None], dtype=float)
        if key == "n_hops" and len(vals):
            ax.hist(vals, bins=np.arange(vals.min() - 0.5, vals.max() + 1.5, 1.0), rwidth=0.85)
        elif len(vals):
            ax.hist(vals, bins=max(5, min(40, len(vals) // 5)))
        if len(vals):
            p5, p50, p95 = np.percentile(vals, [5, 50, 95])
            ax.set_title(f"median {p50:.4g}, 5-95 % [{p5:.4g}, {p95:.4g}]", fontsize=8)
            print(f"{label}: median {p50:.4g}, 5-95 % [{p5:.4g}, {p95:.4g}]")
        ax.set_xlabel(label)
        ax.set_ylabel("runs")
        ax.grid(True, alpha=0.3)
    ax = axes[1, 1]
    sc = ax.scatter([r["K"] for r in ok], [r["delta_max_m"] for r in ok], c=[r["n"] for r in ok], s=10)
    fig.colorbar(sc, ax=ax, label="n")
    ax.set_xscale("log")
    ax.xaxis.set_minor_formatter(plt.NullFormatter())
    ax.set_xlabel("K [N/m^n]")
    ax.set_ylabel("delta_max [m]")
    ax.grid(True, alpha=0.3)
    fig.suptitle(f"Penetrator.fmu, drop from 1.5 m, {stop_time:g} s, {len(ok)} of {len(rows)} runs ok "
                 f"(seed {seed})\n{specs}", fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "soil.png", dpi=110)
    plt.close(fig)
    print(f"wrote {out / 'soil.csv'}, {out / 'soil.png'}")
    return rows


def study_main(argv, prog="pogofmu study"):
    ap = argparse.ArgumentParser(prog=prog, description="studies: CSV + PNG")
    sub = ap.add_subparsers(dest="study", required=True)
    wp = sub.add_parser("work-precision", help="Figs 21-22: event-time error and events located vs rel_tol")
    wp.add_argument("--out", default="results/work-precision", help="output folder")
    wp.add_argument("--fmu", default="dist/PogoStick.fmu")
    wp.add_argument("--reference", default=None,
                    help="closed-form events as a CSV (columns event, time_s); default: computed")
    add_arguments(wp)
    so = sub.add_parser("soil", help="Monte Carlo of the Penetrator over an uncertain soil")
    so.add_argument("--out", default="results/soil", help="output folder")
    so.add_argument("--fmu", default="dist/Penetrator.fmu")
    so.add_argument("--samples", type=int, default=200, help="Monte Carlo samples (default 200)")
    so.add_argument("--seed", type=int, default=0)
    so.add_argument("--stop-time", type=float, default=10.0, help="[s] (default 10)")
    so.add_argument("--sample", action="append", default=[], metavar="NAME=DIST(a,b)",
                    help=f"replace a default distribution or add one (defaults: {' '.join(SOIL_DEFAULTS)})")
    add_arguments(so)
    from pogofmu.studies import coupling as coupling_study
    from pogofmu.studies import landing as landing_study

    coupling_study.add_parser(sub)
    landing_study.add_parser(sub)
    args = ap.parse_args(argv)
    try:
        if args.study == "coupling":
            try:
                return coupling_study.main(args)
            except coupling_study.StudyError as exc:
                raise SweepError(str(exc)) from None
        if args.study == "landing":
            return landing_study.main(args)
        if args.study == "work-precision":
            work_precision(Path(args.out), Path(args.fmu), Path(args.reference) if args.reference else None, args.workers, args.scheduler,
                           not args.no_progress)
        else:
            if not (math.isfinite(args.stop_time) and args.stop_time > 0):
                raise SweepError(f"--stop-time {args.stop_time!r}: must be a finite number > 0 [s]")
            soil(Path(args.out), Path(args.fmu), args.sample, args.samples, args.seed, args.stop_time,
                 args.workers, args.scheduler, not args.no_progress)
    except SweepError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0
