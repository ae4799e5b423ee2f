"""fmpy master script: simulate the default experiment of every FMU in dist/ and write results.

    python -m pogofmu.master [--dist dist] [--out results] [NAME ...]

For each FMU ``<Name>.fmu`` it writes ``results/<Name>/timeseries.csv`` (every output on the
default experiment's grid), ``results/<Name>/events.csv`` (the event table, read from the
outputs ``n_events``, ``t_last_event`` and ``last_event``) and one PNG per figure the model asks
for (time histories like the paper's Fig. 23, force-deflection loops, ...).

Host-side code: it needs fmpy and matplotlib, and is never imported inside an FMU.
"""
from __future__ import annotations

import argparse
import csv
import importlib
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def simulate_default(fmu: Path, start_values=None, **kwargs):
    """fmpy simulation of the FMU's default experiment; raises if the run stops early."""
    import scipy.integrate  # noqa: F401  (see README: avoids a teardown crash of scipy-using FMUs)
    from fmpy import read_model_description, simulate_fmu

    md = read_model_description(str(fmu))
    ex = md.defaultExperiment
    kwargs.setdefault("output_interval", float(ex.stepSize))
    kwargs.setdefault("debug_logging", True)  # pythonfmu forwards no message without it
    kwargs.setdefault("logger", print_problems)
    res = simulate_fmu(str(fmu), start_values=start_values or {}, **kwargs)
    stop = kwargs.get("stop_time", float(ex.stopTime))
    if not math.isclose(res["time"][-1], stop, rel_tol=0, abs_tol=1e-9 * max(1.0, stop)):
        raise RuntimeError(f"{fmu.name}: simulation stopped at t = {res['time'][-1]} s before "
                           f"the stop time {stop} s (see the FMU's log messages above)")
    return res


def print_problems(component, instance, status, category, message):
    """fmpy logger callback: print warnings and errors only (not the logEvents chatter)."""
    if status >= 1:
        label = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"][min(status, 5)]
        text = message.decode(errors="replace") if message else ""
        print(f"[{label}] {instance.decode(errors='replace') if instance else ''}: {text}", flush=True)


def event_table(res, event_names):
    """Rows (index, time, event, mode s after) from the event outputs sampled on the grid.

    Where more than one event falls into one output interval only the latest is known exactly;
    the row then says how many happened in that interval.
    """
    rows = []
    n_prev = 0
    for k in range(len(res)):
        n = int(res["n_events"][k])
        if n > n_prev:
            code = int(res["last_event"][k])
            name = event_names[code - 1] if 0 < code <= len(event_names) else str(code)
            note = "" if n - n_prev == 1 else f"{n - n_prev} events in this output interval; latest shown"
            rows.append({"index": n, "time_s": repr(float(res["t_last_event"][k])), "event": name,
                         "s_after": int(res["s"][k]) if "s" in res.dtype.names else "", "note": note})
            n_prev = n
    return rows


def write_csv(path: Path, res):
    names = res.dtype.names
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(names)
        for row in res:
            w.writerow([repr(v) for v in row.item()])


def plot_figures(res, model, out_dir: Path, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    units = {v.name: v.unit for v in model.all_outputs()}
    files = []
    for i, panels in enumerate(model.plots, start=1):
        fig, axes = plt.subplots(len(panels), 1, figsize=(8, 2.4 * len(panels) + 0.6), squeeze=False)
        for ax, panel in zip(axes[:, 0], panels):
            if panel[0] == "vs":
                _, xn, yn = panel
                ax.plot(res[xn], res[yn], lw=0.9)
                ax.set_xlabel(f"{xn} [{units.get(xn, '')}]")
                ax.set_ylabel(f"{yn} [{units.get(yn, '')}]")
            else:
                for name in panel:
                    if name == "s" or name in model.all_integer_outputs():
                        ax.step(res["time"], res[name], where="post", label=name, lw=0.9)
                    else:
                        ax.plot(res["time"], res[name], label=name, lw=0.9)
                unit = {units.get(n, "") for n in panel}
                ax.set_ylabel(", ".join(panel) + (f" [{unit.pop()}]" if len(unit) == 1 and "" not in unit else ""))
                ax.set_xlabel("time [s]")
                if len(panel) > 1:
                    ax.legend(loc="upper right", fontsize=8)
            ax.grid(True, alpha=0.3)
        fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        path = out_dir / f"figure{i}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        files.append(path)
    return files


def model_of(fmu: Path):
    """The HybridModel behind an FMU built by this project (from its slave class)."""
    src = ROOT / "fmu_src"
    if str(src) not in sys.path:
        sys.path.insert(0, str(src))
    from pogofmu.fmi import HybridSlave

    for script in sorted(src.glob("slave_*.py")):
        module = importlib.import_module(script.stem)
        for obj in vars(module).values():
            if isinstance(obj, type) and issubclass(obj, HybridSlave) and obj.__name__ == fmu.stem:
                return obj.model
    return None


def run(dist: Path, out: Path, names=()):
    out.mkdir(parents=True, exist_ok=True)
    fmus = sorted(dist.glob("*.fmu"))
    if names:
        fmus = [f for f in fmus if f.stem in names]
    if not fmus:
        raise SystemExit(f"no FMU in {dist}: run build_fmu.py first")
    summary = []
    for fmu in fmus:
        model = model_of(fmu)
        res = simulate_default(fmu)
        d = out / fmu.stem
        d.mkdir(exist_ok=True)
        write_csv(d / "timeseries.csv", res)
        if model is None:  # an FMU that is not a HybridModel of this project: outputs only
            summary.append((fmu.stem, res["time"][-1], "-"))
            continue
        rows = event_table(res, [ev.name for ev in model.events])
        with (d / "events.csv").open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=["index", "time_s", "event", "s_after", "note"])
            w.writeheader()
            w.writerows(rows)
        plot_figures(res, model, d, f"{fmu.stem}: default experiment (fmpy, step {res['time'][1] - res['time'][0]:g} s)")
        summary.append((fmu.stem, res["time"][-1], len(rows)))
        print(f"{fmu.stem}: simulated to t = {res['time'][-1]:g} s, {len(rows)} events -> {d}")
    return summary


def main(argv=None):
    ap = argparse.ArgumentParser(description="simulate every FMU's default experiment with fmpy")
    ap.add_argument("--dist", default=str(ROOT / "dist"))
    ap.add_argument("--out", default=str(ROOT / "results"))
    ap.add_argument("names", nargs="*")
    args = ap.parse_args(argv)
    run(Path(args.dist), Path(args.out), args.names)


if __name__ == "__main__":
    main()
