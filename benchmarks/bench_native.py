#!/usr/bin/env python3
"""Benchmark (g): the native FMUs (dist/native/) against their peers, in one run.

Every model's default experiment at a 1 ms communication grid, every output recorded in memory:

* ``dopri5``: the limit (PogoStick only) — a hand-written, self-contained C Dormand-Prince 5(4)
  of the basic pogo stick (``benchmarks/c/dopri5_pogostick.c``: no code of the project's engine,
  the same tolerances, events located on the interpolant, the grid served by interpolation), y
  recorded at every grid point; the best of its own ``HAND_REPEAT`` runs in one process (and, on a
  line below the table, its first run in a fresh process, as the C host's columns run);
* ``engine``: the native engine and the generated model (the native FMU's own C files, with its
  exact counts of states, discrete entries and outputs) driven by
  a plain C loop with no FMI layer (``benchmarks/c/engine_loop.c``), every output recorded — the
  cost of the FMI layer alone, no independent limit (the project's own code);
* ``native y``: the native FMU in the tests' C host (``tests/c_host/fmi2_host.c`` with
  ``-DRECORD_IN_MEMORY``, as benchmark (b) runs it), a fresh process with an empty environment,
  reading y only (what ``dopri5`` records: the user's measurement); ``native C``: the same, every
  output read;
* ``python C``: the Python-hosted FMU (dist/<Model>.fmu) in the same C host;
* ``native fmpy`` and ``floor-io``: the native FMU through ``fmpy.simulate_fmu`` and benchmark
  (b)'s FMI floor (the Python-hosted FMU with its ``do_step`` emptied: the project's launcher, the
  same outputs), simulated the same way.

The C programs time their own stepping loop (``CLOCK_PROCESS_CPUTIME_ID`` from the first step to
the last read: loading, instantiation and an interpreter's start-up are not in it) and the C
columns are that time per communication step; fmpy runs are timed whole, by this process's CPU
time (``time.process_time``). Each variant runs ``--repeat`` times, rotated; the best counts.

Targets (PogoStick): native y at most 2x the hand-written DOPRI5 per step; python C / native C at
least 20x per step; native fmpy at most 1.05x floor-io. native C / engine is printed for
information. The other models are rows for information. Exit status 1 if a target is missed. Builds into a temporary folder, never dist/.

Below the table, for information: the same hand-written program built with ``FMU_DUTIES``, doing
what the FMU must do besides (its seven states, as the FMU integrates them; every state and the 11
outputs at every grid point, checked finite, as the FMU reports a non-finite output from the step
that produced it) — where the rest of the native FMU's cost lies, not the limit.

With ``--instructions`` (valgrind's callgrind; counts that do not depend on the machine's load,
which moves the timed columns by up to 2x on the shared machines here) a line for information
after the table: the instructions per communication step of the PogoStick's ``native y``, of the
hand-written ``dopri5`` and of its ``FMU_DUTIES`` build, each a whole process of the default
experiment less one of 10 steps.

With ``--fmusim PATH`` (or ``$POGOFMU_FMUSIM``: the Reference-FMUs' C fmusim, docs/native.md "In
fmusim") a second table, for information: each FMI 2.0 FMU in fmusim writing its CSV, CPU seconds
of the fmusim process (a run of the default experiment less a run of 10 steps, per step), every
output recorded and only ``n_events`` — fmusim's own work per step (reading the variables,
writing the line) is in every column.

    python benchmarks/bench_native.py [--repeat 7] [--model PogoStick ...] [--instructions] [--fmusim PATH]
"""
from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
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
HAND_REPEAT = 20  # the hand-written DOPRI5's runs per process (its best counts)
TARGETS = {"native y / dopri5": 2.0, "python C / native C": 20.0, "native fmpy / floor-io": 1.05}
ENV = {"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8"}


def loop_cpu(cmd) -> float:
    """Run a C program of this benchmark; the CPU seconds of its stepping loop, as it prints them."""
    proc = subprocess.run(cmd, capture_output=True, text=True, env=ENV)
    found = re.search(r"loop cpu ([0-9.eE+-]+) s", proc.stdout)
    if proc.returncode or not found:
        raise SystemExit(f"{Path(cmd[0]).name} failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return float(found.group(1))


def host_run(host, stop: float, reals=None, ints=None) -> float:
    return loop_cpu([str(host.exe), str(host.dir), *host.args, repr(stop), repr(STEP),
                     host.reals if reals is None else reals, host.ints if ints is None else ints])


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


def instructions_per_step(cmd_of, stop: float) -> float:
    """Instructions per communication step: a run to ``stop`` less a run of 10 steps (loading,
    instantiation and the start cancel)."""
    n = round(stop / STEP)
    count = lambda t: bench_fmu.callgrind_instructions(cmd_of(t), env=ENV)  # noqa: E731
    return (count(stop) - count(10 * STEP)) / (n - 10)


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


class HandDopri5:
    """The hand-written C Dormand-Prince 5(4) of the basic pogo stick (benchmarks/c/dopri5_pogostick.c),
    compiled with the flags of the engine loop."""

    MODEL = "PogoStick"

    def __init__(self, dest: Path):
        from pogofmu.codegen.build import compile_c

        src = HERE / "c" / "dopri5_pogostick.c"
        self.exe = compile_c([src], dest / "dopri5_pogostick", shared=False)
        # for information: the same program doing the FMU's duties besides (its seven states, every
        # state and output at every point; dopri5_pogostick.c, FMU_DUTIES)
        self.duties_exe = compile_c([src], dest / "dopri5_pogostick_duties", shared=False, defines=["FMU_DUTIES"])

    def run(self, stop: float, repeat: int = HAND_REPEAT, duties: bool = False) -> float:
        return loop_cpu([str(self.duties_exe if duties else self.exe), repr(stop), repr(STEP), str(repeat)])


class Limit:
    """The engine loop of one model, compiled from the generated C and the engine's files."""

    def __init__(self, name: str, dest: Path):
        from pogofmu.codegen.build import ENGINE, ENGINE_SOURCES, LTO, compile_c, write_model_source
        from pogofmu.codegen.cmodel import specialization
        from pogofmu.runtime.solver import SOLVER_PARAMETERS
        from pogofmu.runtime.models import get

        model = get(name)
        folder = dest / f"limit_{name}"
        sources = [write_model_source(name, folder), *(ENGINE / s for s in ENGINE_SOURCES),
                   HERE / "c" / "engine_loop.c"]
        # the model's exact counts and its one model, as its native FMU's sizes header gives them, link-time
        # optimized as its Linux binary is
        self.exe = compile_c(sources, folder / "engine_loop", shared=False, include=[ENGINE],
                             defines=[f"{k}={v}" for k, v in specialization(model).items()],
                             extra=LTO)
        p = model.defaults()
        s = [par.default for par in SOLVER_PARAMETERS]
        self.args = [str(len(p)), *(repr(float(v)) for v in p.values()), str(len(s)), *(repr(float(v)) for v in s)]

    def run(self, stop: float) -> float:
        return loop_cpu([str(self.exe), repr(stop), repr(STEP), *self.args])


def main(argv=None):
    from fmpy import read_model_description

    from pogofmu import exporter as build

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--model", action="append", help="only this model (repeatable)")
    ap.add_argument("--instructions", action="store_true",
                    help="also count the PogoStick's instructions per step, native y and dopri5 (needs valgrind)")
    ap.add_argument("--fmusim", default=os.environ.get("POGOFMU_FMUSIM"),
                    help="the C fmusim of Reference-FMUs <= v0.0.39: also time the FMUs in it")
    args = ap.parse_args(argv)
    names = args.model or build.model_names()
    failed, hand_lines = [], []
    with tempfile.TemporaryDirectory(prefix="pogofmu-bench-native-") as tmp:
        dest = Path(tmp)
        with bench_fmu.quiet():
            for name in names:
                build.build_project(dest, [name], cache=ROOT / "build" / "native")
        host = bench_fmu.compile_c_host(dest)
        hand = HandDopri5(dest)
        print(f"(g) native FMUs, default experiments at {STEP:g} s; best of {args.repeat} rotated runs; C columns: "
              f"us per communication step of the stepping loop; dopri5: the hand-written C DOPRI5 (the limit, "
              f"best of {HAND_REPEAT} runs in one process each time), y recorded; engine: the project's engine "
              f"in a plain C loop; native y: the native FMU in the C host reading y; native C, python C: every "
              f"output read")
        head = (f"{'model':<14} {'steps':>6} {'dopri5':>7} {'engine':>7} {'native y':>8} {'native C':>8} "
                f"{'python C':>8} {'nat y/dopri5':>12} {'nat C/engine':>12} "
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
            y_vr = str(next(v.valueReference for v in md.modelVariables if v.name == "y"))
            runs = {
                "engine": lambda: limit.run(stop), "native C": lambda: host_run(c_native, stop),
                "native y": lambda: host_run(c_native, stop, y_vr, "-"),
                "python C": lambda: host_run(c_python, stop),
                "native fmpy": lambda: bench_fmu.simulate(native, stop, {})[0],
                "floor-io": lambda: bench_fmu.simulate(floor, stop, {})[0],
            }
            if name == hand.MODEL:
                runs["dopri5"] = lambda: hand.run(stop)
                runs["dopri5 first"] = lambda: hand.run(stop, 1)
                runs["dopri5 duties"] = lambda: hand.run(stop, duties=True)
            best = best_rotated(runs, args.repeat)
            us = {k: best[k] / n * 1e6 for k in ("engine", "native y", "native C", "python C", "dopri5",
                                                 "dopri5 first", "dopri5 duties") if k in best}
            ratios = {"native C / engine": us["native C"] / us["engine"],
                      "python C / native C": us["python C"] / us["native C"],
                      "native fmpy / floor-io": best["native fmpy"] / best["floor-io"]}
            if "dopri5" in us:
                ratios["native y / dopri5"] = us["native y"] / us["dopri5"]
            d5 = f"{us['dopri5']:>7.3f}" if "dopri5" in us else f"{'-':>7}"
            d5r = f"{ratios['native y / dopri5']:>11.2f}x" if "dopri5" in us else f"{'-':>12}"
            print(f"{name:<14} {n:>6} {d5} {us['engine']:>7.3f} {us['native y']:>8.3f} {us['native C']:>8.3f} "
                  f"{us['python C']:>8.3f} {d5r} {ratios['native C / engine']:>11.2f}x "
                  f"{ratios['python C / native C']:>9.1f}x "
                  f"{best['native fmpy']:>13.3f} {best['floor-io']:>10.3f} "
                  f"{ratios['native fmpy / floor-io']:>8.2f}x", flush=True)
            if "dopri5" in us:
                hand_lines.append(
                    f"{name}: the hand-written DOPRI5 in the first run of a fresh process (as the C host's columns "
                    f"run) {us['dopri5 first']:.3f} us per step; native y / that "
                    f"{us['native y'] / us['dopri5 first']:.2f}x")
                hand_lines.append(
                    f"{name}: the hand-written DOPRI5 doing the FMU's duties besides (its 7 states, every state and "
                    f"output at every point, checked finite; FMU_DUTIES) {us['dopri5 duties']:.3f} us per step; "
                    f"native y / that {us['native y'] / us['dopri5 duties']:.2f}x (for information)")
            if name == "PogoStick":
                hand_lines.append(
                    f"PogoStick: the native FMU against the hand-written limit, native y / dopri5 "
                    f"{ratios['native y / dopri5']:.2f}x (target <= {TARGETS['native y / dopri5']:g}x: "
                    f"{'holds' if ratios['native y / dopri5'] <= TARGETS['native y / dopri5'] else 'MISSED'})")
                if args.instructions:
                    if shutil.which("valgrind") is None:
                        raise SystemExit("--instructions needs valgrind (Debian package valgrind)")
                    i_native = instructions_per_step(
                        lambda t: [str(c_native.exe), str(c_native.dir), *c_native.args, repr(t), repr(STEP), y_vr, "-"],
                        stop)
                    i_hand = instructions_per_step(lambda t: [str(hand.exe), repr(t), repr(STEP), "1"], stop)
                    i_duties = instructions_per_step(lambda t: [str(hand.duties_exe), repr(t), repr(STEP), "1"], stop)
                    hand_lines.append(
                        f"PogoStick: instructions per communication step (callgrind): native y {i_native:.0f}, "
                        f"dopri5 {i_hand:.0f}, native y / dopri5 {i_native / i_hand:.2f}x; dopri5 with the FMU's "
                        f"duties {i_duties:.0f}, native y / that {i_native / i_duties:.2f}x (for information)")
                for what, target in TARGETS.items():
                    ok = ratios[what] >= target if what.startswith("python") else ratios[what] <= target
                    if not ok:
                        failed.append(f"{what} {ratios[what]:.2f}x (target {'>=' if what.startswith('python') else '<='} "
                                      f"{target:g}x)")
        for line in hand_lines:
            print(line)
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
