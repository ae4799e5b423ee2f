"""``pogofmu study landing``: the landing dispersion of the SpaceHopper, a system Monte Carlo.

The SpaceHopper (the PogoStick and its apex-height controller, SSP) hops on the Moon (parameter
set ``moon``). Uncertain: the ground contact of the leg (stiffness ``PogoStick.k`` and damping
``PogoStick.c``), the controller's gains (``HopController.K_D``, ``HopController.tau_E``) and the
gravity the plant feels (``PogoStick.g``; the controller keeps its model's 1.62 m/s²). Each sample
is one run of the SSP master (``pogofmu sweep SpaceHopper.ssp``, on Dask); the study reads from
every run the time of the first touchdown, the touchdown speed (the most negative ``ydot``), the
highest apex, the number of the PogoStick's events (touchdowns and liftoffs) and the energy at the
end, and draws their dispersion: ``landing.parquet`` (the sweep), ``landing.csv``, ``landing.png``.
"""
from __future__ import annotations

import math
from pathlib import Path

from pogofmu.sweep import SweepError, add_arguments, execute, make_points, parse_sample

from . import _plt, _read_table, _write_csv

LANDING_DEFAULTS = [
    "PogoStick.k=lognormal(4.6051702,0.15)",  # median 100 N/m (ln 100), a factor 1.16 per sigma
    "PogoStick.c=uniform(0.3,0.7)",  # [N s/m] around the nominal 0.5
    "HopController.K_D=uniform(0.7,1.3)",
    "HopController.tau_E=uniform(0.01,0.03)",  # [s] around the nominal 0.02
    "PogoStick.g=normal(1.62,0.03)",  # [m/s2] the plant's gravity, the controller's model keeps 1.62
]
SUMMARIES = ["PogoStick:first_event", "PogoStick:events", "PogoStick.ydot:min", "PogoStick.y:max",
             "PogoStick.y:t_max"]


def add_parser(sub):
    la = sub.add_parser("landing", help="landing dispersion of the SpaceHopper system (soil, gains, gravity)")
    la.add_argument("--out", default="results/landing", help="output folder")
    la.add_argument("--ssp", default="dist/native/SpaceHopper.ssp", help="the SSP package")
    la.add_argument("--parameters", default="moon", help="parameter set of the package (default moon)")
    la.add_argument("--samples", type=int, default=200, help="Monte Carlo samples (default 200)")
    la.add_argument("--seed", type=int, default=0)
    la.add_argument("--stop-time", type=float, default=10.0, help="[s] (default 10)")
    la.add_argument("--sample", action="append", default=[], metavar="Component.parameter=DIST(a,b)",
                    help=f"replace a default distribution or add one (defaults: {' '.join(LANDING_DEFAULTS)})")
    add_arguments(la)
    return la


def main(args) -> int:
    if not (math.isfinite(args.stop_time) and args.stop_time > 0):
        raise SweepError(f"--stop-time {args.stop_time!r}: must be a finite number > 0 [s]")
    landing(Path(args.out), Path(args.ssp), args.parameters, args.sample, args.samples, args.seed, args.stop_time,
            args.workers, args.scheduler, not args.no_progress)
    return 0


def landing(out: Path, ssp: Path, parameters, samples_spec, n_samples, seed, stop_time, workers=None,
            scheduler=None, progress=True):
    from pogofmu.sweep.system import SystemSettings, SystemSweep

    samples = {s[0]: s for s in (parse_sample(t) for t in LANDING_DEFAULTS)}
    samples.update({s[0]: s for s in (parse_sample(t) for t in samples_spec)})
    names, points = make_points([], list(samples.values()), n_samples, seed)
    settings = SystemSettings(parameters=parameters, stop_time=stop_time, step=1e-3, summaries=list(SUMMARIES))
    out.mkdir(parents=True, exist_ok=True)
    sweep = SystemSweep(str(ssp), names, points, settings, str(out / "landing.parquet"))
    if execute(sweep, workers, scheduler, overwrite=True, progress=progress):
        raise SweepError("interrupted")
    rows = []
    for r in _read_table(out / "landing.parquet"):
        ok = r["status"] == "ok"
        rows.append({"run_id": r["run_id"], **{n: r[n] for n in names}, "status": r["status"],
                     "first_touchdown_s": r["PogoStick:first_event"] if ok else None,
                     "touchdown_speed_m_s": -r["PogoStick.ydot:min"] if ok else None,
                     "highest_apex_m": r["PogoStick.y:max"] if ok else None,
                     "stick_events": r["PogoStick:events"] if ok else None,
                     "final_energy_J": r["PogoStick.E:final"] if ok else None, "message": r["message"]})
    _write_csv(out / "landing.csv", rows, list(rows[0]))
    figure(out / "landing.png", rows, samples, stop_time, parameters, seed)
    print(f"wrote {out / 'landing.csv'}, {out / 'landing.png'}")
    return rows


def figure(path: Path, rows, samples, stop_time, parameters, seed):
    import numpy as np

    ok = [r for r in rows if r["status"] == "ok"]
    plt = _plt()
    fig, axes = plt.subplots(2, 2, figsize=(9.5, 7.5))
    ax = axes[0, 0]
    t1 = np.array([r["first_touchdown_s"] for r in ok], dtype=float)
    g = np.array([r["PogoStick.g"] for r in ok], dtype=float)
    if len(ok):
        ax.scatter(g, t1, s=10, label="runs")
        gg = np.linspace(g.min(), g.max(), 50)
        # the fall from rest at y_0 = 1.2 m to touchdown at the leg's length x_i = 1 m (the moon set)
        ax.plot(gg, np.sqrt(2 * 0.2 / gg), "k--", lw=1, label="free fall from y_0 = 1.2 m to x_i = 1 m")
        ax.legend(fontsize=7)
    ax.set_xlabel("plant gravity g [m/s²]")
    ax.set_ylabel("first touchdown [s]")
    for ax, key, label in ((axes[0, 1], "touchdown_speed_m_s", "highest touchdown speed [m/s]"),
                           (axes[1, 0], "highest_apex_m", "highest apex of y [m]")):
        vals = np.array([r[key] for r in ok], dtype=float)
        if len(vals):
            ax.hist(vals, bins=max(5, min(40, len(vals) // 5)))
            p5, p50, p95 = np.percentile(vals, [5, 50, 95])
            ax.set_title(f"median {p50:.4g}, 5-95 % [{p5:.4g}, {p95:.4g}]", fontsize=8)
            print(f"{label}: median {p50:.4g}, 5-95 % [{p5:.4g}, {p95:.4g}]")
        ax.set_xlabel(label)
        ax.set_ylabel("runs")
    ax = axes[1, 1]
    if len(ok):
        sc = ax.scatter([r["HopController.K_D"] for r in ok], [r["highest_apex_m"] for r in ok],
                        c=[r["HopController.tau_E"] for r in ok], s=10)
        fig.colorbar(sc, ax=ax, label="HopController.tau_E [s]")
    ax.set_xlabel("HopController.K_D (the controller's energy gain)")
    ax.set_ylabel("highest apex of y [m]")
    for a in axes.ravel():
        a.grid(True, alpha=0.3)
    import textwrap

    specs = textwrap.fill(", ".join(f"{n} ~ {d}{a}" for n, d, a in samples.values()), 150)
    fig.suptitle(f"SpaceHopper ({parameters}), {stop_time:g} s, {len(ok)} of {len(rows)} runs ok (seed {seed})\n"
                 f"{specs}", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
