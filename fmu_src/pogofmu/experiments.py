"""fmpy master script: simulate the default experiment of every FMU in dist/ and write results.

    python -m pogofmu.experiments [--dist dist] [--out results] [NAME ...]

For each FMU ``<Name>.fmu`` it writes ``results/<Name>/timeseries.csv`` (every output on the
default experiment's grid), ``results/<Name>/events.csv`` (the event table, read from the
outputs ``n_events``, ``t_last_event`` and ``last_event``) and one PNG per figure the model asks
for (time histories like the paper's Fig. 23, force-deflection loops, ...).

Host-side code: it needs fmpy and matplotlib, and is never imported inside an FMU.
"""
from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

from pogofmu.runtime.status import status_name



def simulate_default(fmu: Path, start_values=None, model=None, **kwargs):
    """fmpy simulation of the FMU's default experiment; raises if the run stops early.

    With a ``model`` that declares ``default_input`` the FMU's inputs follow it (sampled on the
    output grid) and are recorded beside the outputs."""
    from fmpy import read_model_description, simulate_fmu

    md = read_model_description(str(fmu))
    ex = md.defaultExperiment
    kwargs.setdefault("output_interval", float(ex.stepSize))
    kwargs.setdefault("debug_logging", True)  # pythonfmu forwards no message without it
    kwargs.setdefault("logger", print_problems)
    stop = kwargs.get("stop_time", float(ex.stopTime))
    if model is not None and model.default_input is not None and "input" not in kwargs:
        kwargs["input"] = default_input_signals(model, stop, kwargs["output_interval"], start_values)
        kwargs.setdefault("output", [v.name for v in model.all_outputs()] + [v.name for v in model.inputs])
    res = simulate_fmu(str(fmu), start_values=start_values or {}, **kwargs)
    if not math.isclose(res["time"][-1], stop, rel_tol=0, abs_tol=1e-9 * max(1.0, stop)):
        raise RuntimeError(f"{fmu.name}: simulation stopped at t = {res['time'][-1]} s before "
                           f"the stop time {stop} s (see the FMU's log messages above)")
    return res


def default_input_signals(model, stop: float, step: float, start_values=None):
    """The model's ``default_input(t, p)`` sampled every ``step`` up to ``stop``, as the structured
    array fmpy's ``simulate_fmu(input=...)`` takes (integer inputs as integers)."""
    import numpy as np

    p = model.params(**{k: v for k, v in (start_values or {}).items() if k in model.defaults()})
    t = np.linspace(0.0, stop, int(round(stop / step)) + 1)
    names = [v.name for v in model.inputs]
    dtype = [("time", np.float64)] + [(n, np.int32 if n in model.integer_inputs else np.float64) for n in names]
    values = [model.default_input(float(tk), p) for tk in t]
    return np.array([(tk,) + tuple(u[n] for n in names) for tk, u in zip(t, values)], dtype=dtype)


def print_problems(component, instance, status, category, message):
    """fmpy logger callback: print warnings and errors only (not the logEvents chatter)."""
    if status >= 1:
        label = status_name(status)
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


def _label(names, units):
    """``y, z [m]`` for one unit, ``E [J], s [-]`` for several; ``-`` for a dimensionless signal."""
    us = [units.get(n) or "-" for n in names]
    if len(set(us)) == 1:
        return f"{', '.join(names)} [{us[0]}]"
    return ", ".join(f"{n} [{u}]" for n, u in zip(names, us))


def draw_panel(ax, res, panel, units, integers):
    """One panel of a model's figure: a loop ``("vs", x, y[, rate, label+, label-])`` or signals
    against time; every y-axis labelled with its unit, integer signals with integer ticks."""
    from matplotlib.ticker import MaxNLocator

    if panel[0] == "vs":
        xn, yn = panel[1], panel[2]
        x, y = res[xn], res[yn]
        if len(panel) > 3:
            _signed_loop(ax, x, y, res[panel[3]], panel[4:6])
        else:
            ax.plot(x, y, lw=0.9)
        ax.set_xlabel(_label([xn], units))
        ax.set_ylabel(_label([yn], units))
    else:
        for name in panel:
            if name in integers:
                ax.step(res["time"], res[name], where="post", label=name, lw=0.9)
            else:
                ax.plot(res["time"], res[name], label=name, lw=0.9)
        if all(n in integers for n in panel):
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel(_label(panel, units))
        ax.set_xlabel("time [s]")
        if len(panel) > 1:
            ax.legend(loc="upper right", fontsize=8)
    ax.grid(True, alpha=0.3)


def _signed_loop(ax, x, y, rate, labels):
    """A loop in two colours by the sign of ``rate`` (labels for rate > 0 and rate < 0), an arrow
    on each branch's first run, and an inset magnifying the middle of the first rate > 0 run,
    where the two branches are seen apart (in a thin loop, such as Hunt-Crossley's, they touch
    at the scale of the whole loop)."""
    import numpy as np
    from matplotlib.ticker import MaxNLocator

    branches = []
    for sign, label, color in ((1, labels[0], "tab:red"), (-1, labels[1], "tab:blue")):
        on = np.sign(rate) == sign
        branches.append((np.where(on, x, np.nan), np.where(on, y, np.nan), color, label))
        ax.plot(branches[-1][0], branches[-1][1], lw=0.9, color=color, label=label)
        run = np.flatnonzero(on)
        if len(run) > 2:
            gaps = np.flatnonzero(np.diff(run) > 1)
            k = (run[0] + (run[gaps[0]] if len(gaps) else run[-1])) // 2
            branches[-1] += (k,)
            ax.annotate("", xy=(x[k + 1], y[k + 1]), xytext=(x[k], y[k]),
                        arrowprops=dict(arrowstyle="-|>", color=color, lw=1.2, mutation_scale=14))
    ax.legend(loc="upper left", fontsize=8)
    if len(branches[0]) < 5 or not np.all(np.isfinite([np.nanmin(x), np.nanmax(x)])):
        return
    k = branches[0][4]
    half = 0.04 * (np.nanmax(x) - np.nanmin(x))
    near = np.abs(x - x[k]) <= half
    if half <= 0 or not np.any(near & (rate < 0)):
        return
    ins = ax.inset_axes([0.64, 0.07, 0.34, 0.4])  # lower right: empty for a loop rising to the right
    for bx, by, color, label, *_ in branches:
        ins.plot(bx, by, lw=1.2, color=color)
    lo, hi = np.nanmin(y[near]), np.nanmax(y[near])
    ins.set_xlim(x[k] - half, x[k] + half)
    ins.set_ylim(lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo))
    ins.tick_params(labelsize=7)
    ins.xaxis.set_major_locator(MaxNLocator(3))
    ins.grid(True, alpha=0.3)
    ax.indicate_inset_zoom(ins, edgecolor="0.4")


def default_plots(model):
    """The figure of a model that names none: its outputs against time, one panel per unit (integer
    outputs on a panel of their own)."""
    integers = model.integer_outputs
    by_unit = {}
    for v in model.outputs:
        by_unit.setdefault("" if v.name in integers else v.unit or "-", []).append(v.name)
    panels = [tuple(names) for unit, names in by_unit.items() if unit != ""]
    panels += [tuple(names) for unit, names in by_unit.items() if unit == ""]
    return (tuple(panels[:6]),) if panels else ()


def figures(res, model, title: str):
    """The model's figures (matplotlib Figure objects, one per entry of ``model.plots``, or
    :func:`default_plots`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    units = {v.name: v.unit for v in model.all_outputs() + tuple(model.inputs)}
    integers = model.all_integer_outputs() | model.integer_inputs | {"s"}
    out = []
    for panels in model.plots or default_plots(model):
        height = sum(4.5 if panel[0] == "vs" else 2.4 for panel in panels) + 0.6
        fig, axes = plt.subplots(len(panels), 1, figsize=(8, height), squeeze=False)
        for ax, panel in zip(axes[:, 0], panels):
            draw_panel(ax, res, panel, units, integers)
        fig.suptitle(title, fontsize=10)
        fig.align_ylabels(axes[:, 0])
        fig.tight_layout()
        out.append(fig)
    return out


def plot_figures(res, model, out_dir: Path, title: str):
    import matplotlib.pyplot as plt

    files = []
    for i, fig in enumerate(figures(res, model, title), start=1):
        path = out_dir / f"figure{i}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        files.append(path)
    return files


_EXTRACTED = []  # folders of FMUs whose Python code this process has imported (kept while it runs)


def model_of(fmu: Path):
    """The HybridModel behind an FMU exported by pogofmu: one of the project's models (its modelName
    in the registry), else the model inside a Python-hosted FMU (its own code, loaded as the FMU's
    launcher loads it: under the build's private names), or None for any other FMU."""
    import tempfile
    import zipfile

    from fmpy import read_model_description

    from pogofmu.runtime.models import all_models

    try:
        name = read_model_description(str(fmu), validate=False).modelName
    except Exception:  # noqa: BLE001 - not an FMU of this project: no model
        return None
    if name in all_models():
        return all_models()[name]
    try:
        with zipfile.ZipFile(fmu) as z:
            if "resources/pogofmu_launch.txt" not in z.namelist():
                return None
            tmp = tempfile.TemporaryDirectory(prefix="pogofmu_model_")
            _EXTRACTED.append(tmp)
            z.extractall(tmp.name, [n for n in z.namelist() if n.startswith("resources/")])
        resources = str(Path(tmp.name) / "resources")
        sys.path.insert(0, resources)
        try:
            import importlib

            boot = importlib.import_module("pogofmu_boot")
            return boot.load(resources).model
        finally:
            sys.path.remove(resources)
    except Exception:  # noqa: BLE001 - an FMU whose code does not load here: outputs only
        return None


class RunError(Exception):
    """The run command cannot go on; the message says why."""


def run(dist: Path, out: Path, names=()):
    available = sorted(dist.glob("*.fmu"))
    if not available:
        raise RunError(f"no FMU in {dist}: build them first (python3 build_fmu.py, or python3 tasks.py run)")
    fmus = [f for f in available if not names or f.stem in names]
    unknown = [n for n in names if n not in {f.stem for f in available}]
    if unknown:
        raise RunError(f"no FMU named {', '.join(unknown)} in {dist}; the FMUs there are "
                       f"{', '.join(f.stem for f in available)}")
    out.mkdir(parents=True, exist_ok=True)
    summary = []
    for fmu in fmus:
        model = model_of(fmu)
        res = simulate_default(fmu, model=model)
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


def main(argv=None, prog="pogofmu run"):
    ap = argparse.ArgumentParser(prog=prog, description="simulate each FMU's default experiment with fmpy: "
                                 "results/<FMU>/{timeseries.csv, events.csv, figure*.png}")
    ap.add_argument("--dist", default="dist", help="folder of the built FMUs (default: dist in the current folder)")
    ap.add_argument("--out", default="results", help="output folder (default: results in the current folder)")
    ap.add_argument("names", nargs="*", help="FMU names (default: every FMU in --dist)")
    args = ap.parse_args(argv)
    try:
        run(Path(args.dist), Path(args.out), args.names)
    except RunError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    main()
