#!/usr/bin/env python3
"""Benchmark (g): the native FMUs (dist/native/) against their peers, in one run.

Every model's default experiment at a 1 ms communication grid, every output recorded in memory:

* ``limit``: the compiled limit — the native engine and the generated model (the native FMU's own
  C files) driven by a plain C loop with no FMI layer (``benchmarks/c/engine_loop.c``);
* ``native C``: the native FMU in the tests' C host (``tests/c_host/fmi2_host.c`` with
  ``-DRECORD_IN_MEMORY``, as benchmark (b) runs it), a fresh process with an empty environment;
* ``python C``: the Python-hosted FMU (dist/<Model>.fmu) in the same C host;
* ``native fmpy`` and ``floor-io``: the native FMU through ``fmpy.simulate_fmu`` and benchmark
  (b)'s FMI floor (the Python-hosted FMU with its ``do_step`` emptied: the project's launcher, the
  same outputs), simulated the same way.

The C programs time their own stepping loop (``CLOCK_PROCESS_CPUTIME_ID`` from the first step to
the last read: loading, instantiation and an interpreter's start-up are not in it) and the C
columns are that time per communication step; fmpy runs are timed whole, by this process's CPU
time (``time.process_time``). Each variant runs ``--repeat`` times, rotated; the best counts.

Targets (PogoStick): native C at most 2x the limit per step; python C / native C at
least 20x per step; native fmpy at most 1.05x floor-io. The other models are rows for
information. Exit status 1 if a target is missed. Builds into a temporary folder, never dist/.

With ``--fmusim PATH`` (or ``$POGOFMU_FMUSIM``: the Reference-FMUs' C fmusim, docs/native.md "In
fmusim") a second table, for information: each FMI 2.0 FMU in fmusim writing its CSV, CPU seconds
of the fmusim process (a run of the default experiment less a run of 10 steps, per step), every
output recorded and only ``n_events`` — fmusim's own work per step (reading the variables,
writing the line) is in every column.

    python benchmarks/bench_native.py [--repeat 7] [--model PogoStick ...] [--fmusim PATH]
"""
from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "fmu_src"))

import bench_fmu  # noqa: E402  (its floor FMUs, C host and fmpy runner)

STEP = 1e-3
TARGETS = {"native C / limit": 2.0, "python C / native C": 20.0, "native fmpy / floor-io": 1.05}
ENV = {"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8"}


def loop_cpu(cmd) -> float:
    """Run a C program of this benchmark; the CPU seconds of its stepping loop, as it prints them."""
    proc = subprocess.run(cmd, capture_output=True, text=True, env=ENV)
    found = re.search(r"loop cpu ([0-9.eE+-]+) s", proc.stdout)
    if proc.returncode or not found:
        raise SystemExit(f"{Path(cmd[0]).name} failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return float(found.group(1))


def host_run(host, stop: float) -> float:
    return loop_cpu([str(host.exe), str(host.dir), *host.args, repr(stop), repr(STEP), host.reals, host.ints])


def best_rotated(runs, repeat: int) -> dict:
    """Each run once untimed (imports, caches), then ``repeat`` rounds in an order rotated from
    round to round; the best time of each run."""
    for run in runs.values():
        run()
    keys, times = list(runs), {key: [] for key in runs}
    for i in range(repeat):
        for key in keys[i % len(keys):] + keys[:i % len(keys)]:
            times[key].append(runs[key]())
    return {key: min(v) for key, v in times.items()}


def child_cpu(cmd) -> float:
    """CPU seconds (user + system) of one child process run to its end."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run(cmd, capture_output=True, text=True, env=ENV)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}): {(proc.stdout + proc.stderr)[-2000:]}")
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def fmusim_table(fmusim: str, dest: Path, names, repeat: int):
    """us per communication step of each FMI 2.0 FMU in fmusim (module docstring)."""
    from fmpy import read_model_description

    print(f"\n(g, fmusim) {fmusim}: us of CPU per communication step, fmusim writing its CSV "
          f"(default experiment less 10 steps); best of {repeat} rotated runs")
    head = f"{'model':<14} {'native all':>10} {'python all':>10} {'py/nat all':>10} {'native 1':>9} {'python 1':>9} {'py/nat 1':>9}"
    print(head)
    print("-" * len(head))
    out = dest / "fmusim.csv"
    for name in names:
        native, python = dest / "native" / f"{name}.fmu", dest / f"{name}.fmu"
        stop = float(read_model_description(str(native)).defaultExperiment.stopTime)
        n = round(stop / STEP)

        def run(fmu, t, extra):
            return child_cpu([fmusim, "--stop-time", repr(t), "--output-interval", repr(STEP), *extra,
                              "--output-file", str(out), str(fmu)])

        cases = {(w, k, t): (lambda fmu=fmu, extra=extra, t=t: run(fmu, t, extra))
                 for w, fmu in (("native", native), ("python", python))
                 for k, extra in (("all", []), ("1", ["--output-variable", "n_events"]))
                 for t in (stop, 10 * STEP)}
        best = best_rotated(cases, repeat)
        us = {(w, k): (best[w, k, stop] - best[w, k, 10 * STEP]) / (n - 10) * 1e6
              for w in ("native", "python") for k in ("all", "1")}
        print(f"{name:<14} {us['native', 'all']:>10.2f} {us['python', 'all']:>10.2f} "
              f"{us['python', 'all'] / us['native', 'all']:>9.1f}x {us['native', '1']:>9.2f} "
              f"{us['python', '1']:>9.2f} {us['python', '1'] / us['native', '1']:>8.1f}x", flush=True)


class Limit:
    """The engine loop of one model, compiled from the generated C and the engine's files."""

    def __init__(self, name: str, dest: Path):
        from pogofmu.codegen.build import ENGINE, ENGINE_SOURCES, compile_c, write_model_source, write_pairs_source
        from pogofmu.runtime.engine import SOLVER_PARAMETERS
        from pogofmu.runtime.models import get

        model = get(name)
        folder = dest / f"limit_{name}"
        sources = [write_model_source(name, folder), write_pairs_source(folder),
                   *(ENGINE / s for s in ENGINE_SOURCES), HERE / "c" / "engine_loop.c"]
        self.exe = compile_c(sources, folder / "engine_loop", shared=False, include=[ENGINE])
        p = model.defaults()
        s = [par.default for par in SOLVER_PARAMETERS]
        self.args = [str(len(p)), *(repr(float(v)) for v in p.values()), str(len(s)), *(repr(float(v)) for v in s)]

    def run(self, stop: float) -> float:
        return loop_cpu([str(self.exe), repr(stop), repr(STEP), *self.args])


def main(argv=None):
    from fmpy import read_model_description

    from pogofmu import build

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--model", action="append", help="only this model (repeatable)")
    ap.add_argument("--fmusim", default=os.environ.get("POGOFMU_FMUSIM"),
                    help="the C fmusim of Reference-FMUs <= v0.0.39: also time the FMUs in it")
    args = ap.parse_args(argv)
    names = args.model or build.model_names()
    failed = []
    with tempfile.TemporaryDirectory(prefix="pogofmu-bench-native-") as tmp:
        dest = Path(tmp)
        with bench_fmu.quiet():
            for name in names:
                build.build_project(dest, [name], cache=ROOT / "build" / "native")
        host = bench_fmu.compile_c_host(dest)
        print(f"(g) native FMUs, default experiments at {STEP:g} s, every output recorded; best of {args.repeat} "
              f"rotated runs; C columns: us per communication step of the stepping loop")
        head = (f"{'model':<14} {'steps':>6} {'limit':>8} {'native C':>9} {'python C':>9} {'nat C/limit':>11} "
                f"{'py C/nat C':>10} {'native fmpy s':>13} {'floor-io s':>10} {'nat/floor':>9}")
        print(head)
        print("-" * len(head))
        for name in names:
            native, python = dest / "native" / f"{name}.fmu", dest / f"{name}.fmu"
            md = read_model_description(str(native))
            stop = float(md.defaultExperiment.stopTime)
            n = round(stop / STEP)
            limit = Limit(name, dest)
            c_native = bench_fmu.CHost(host, native, dest / "native")
            c_python = bench_fmu.CHost(host, python, dest)
            floor = bench_fmu.floor_of(python, dest)
            best = best_rotated({
                "limit": lambda: limit.run(stop), "native C": lambda: host_run(c_native, stop),
                "python C": lambda: host_run(c_python, stop),
                "native fmpy": lambda: bench_fmu.simulate(native, stop, {})[0],
                "floor-io": lambda: bench_fmu.simulate(floor, stop, {})[0],
            }, args.repeat)
            us = {k: best[k] / n * 1e6 for k in ("limit", "native C", "python C")}
            ratios = {"native C / limit": us["native C"] / us["limit"],
                      "python C / native C": us["python C"] / us["native C"],
                      "native fmpy / floor-io": best["native fmpy"] / best["floor-io"]}
            print(f"{name:<14} {n:>6} {us['limit']:>8.3f} {us['native C']:>9.3f} {us['python C']:>9.3f} "
                  f"{ratios['native C / limit']:>10.2f}x {ratios['python C / native C']:>9.1f}x "
                  f"{best['native fmpy']:>13.3f} {best['floor-io']:>10.3f} "
                  f"{ratios['native fmpy / floor-io']:>8.2f}x", flush=True)
            if name == "PogoStick":
                for what, target in TARGETS.items():
                    ok = ratios[what] >= target if what.startswith("python") else ratios[what] <= target
                    if not ok:
                        failed.append(f"{what} {ratios[what]:.2f}x (target {'>=' if what.startswith('python') else '<='} "
                                      f"{target:g}x)")
        if args.fmusim:
            fmusim_table(args.fmusim, dest, names, args.repeat)
    if failed:
        print("PogoStick target MISSED: " + "; ".join(failed))
        return 1
    print("PogoStick targets hold: " + ", ".join(f"{k} {'>=' if k.startswith('python') else '<='} {v:g}x"
                                                 for k, v in TARGETS.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
