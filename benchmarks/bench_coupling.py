#!/usr/bin/env python3
"""Benchmark (f): the cost of exact events in the SSP master.

The SpaceHopper on the Moon, 30 s at a communication step of 1 ms, run by ``pogofmu.ssp.simulate``
on the built packages (dist/): for each package the fixed-step Gauss–Seidel master (``events=False``)
is the peer of the event-synchronized one (``events=True``) on the same FMUs —

* ``SpaceHopper.ssp`` (FMI 2.0): the rollback path;
* ``SpaceHopper-fmi3.ssp`` (FMI 3.0): the early-return path;
* the strongly coupled model exchange (FMI 3.0 FMUs, CVODE) on the same output grid, for
  information (its cost is not a target).

The variants run in turn, A B A B ..., ``--rounds`` times, each in this process with its CPU time
counted (``time.process_time``; the FMUs run inside it); the ratios are formed round by round and
the median is printed with the spread. Targets: early return at most 1.1x its peer, rollback at
most 1.5x; exit status 1 if a median misses its target.

On a shared machine CPU times of identical runs spread by 2x; ``--instructions`` counts instead
the instructions each variant executes per communication step (valgrind's callgrind, a fresh
process per run, the count of a run to ``--short`` seconds subtracted from one to
``--short + --window`` seconds, so that start-up and loading cancel; the window's events per
second are printed beside the 30 s run's, for a window to be representative): repeatable to the instruction,
whatever else the machine does, and slow (a few minutes).

    python benchmarks/bench_coupling.py [--rounds 5] [--stop-time 30] [--step 1e-3]
    python benchmarks/bench_coupling.py --instructions [--short 0.5] [--window 1]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "fmu_src"))

TARGETS = {"FMI 3.0 early return": 1.1, "FMI 2.0 rollback": 1.5}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--warmup", type=int, default=1, help="rounds run first and not counted")
    ap.add_argument("--stop-time", type=float, default=30.0)
    ap.add_argument("--step", type=float, default=1e-3)
    ap.add_argument("--dist", default=str(ROOT / "dist"))
    ap.add_argument("--instructions", action="store_true", help="count instructions per step (callgrind)")
    ap.add_argument("--short", type=float, default=0.5, help="[s] the shorter run of --instructions")
    ap.add_argument("--window", type=float, default=1.0, help="[s] how much longer the longer run of --instructions is")
    args = ap.parse_args(argv)
    if args.instructions:
        return count_instructions(Path(args.dist), args.short, args.step, args.window, args.stop_time)
    from pogofmu.ssp import simulate

    dist = Path(args.dist)
    fmi2, fmi3 = dist / "SpaceHopper.ssp", dist / "SpaceHopper-fmi3.ssp"
    variants = {
        "FMI 2.0 fixed step": dict(ssp=fmi2, events=False),
        "FMI 2.0 rollback": dict(ssp=fmi2, events=True),
        "FMI 3.0 fixed step": dict(ssp=fmi3, events=False),
        "FMI 3.0 early return": dict(ssp=fmi3, events=True),
        "FMI 3.0 model exchange": dict(ssp=fmi3, algorithm="model-exchange"),
    }
    peers = {"FMI 2.0 rollback": "FMI 2.0 fixed step", "FMI 3.0 early return": "FMI 3.0 fixed step",
             "FMI 3.0 model exchange": "FMI 3.0 fixed step"}
    cpu = {k: [] for k in variants}
    rows = {}
    for r in range(-args.warmup, args.rounds):
        for name, v in variants.items():
            if r < 0 and name.endswith("model exchange"):
                continue  # (warm-up: loading and extracting the FMUs once is enough)
            v = dict(v)
            ssp = v.pop("ssp")
            t0 = time.process_time()
            res = simulate(ssp, parameters="moon", stop_time=args.stop_time, step=args.step, echo_log=False, **v)
            if r >= 0:
                cpu[name].append(time.process_time() - t0)
            rows[name] = res.rows
        if r >= 0:
            print(f"round {r + 1}: " + ", ".join(f"{k} {cpu[k][-1]:.2f} s" for k in variants), flush=True)
    print(f"\nSpaceHopper, Moon, {args.stop_time:g} s at {args.step:g} s, {args.rounds} rounds (CPU seconds, "
          f"median [min, max]; ratio to the peer round by round)")
    print(f"{'variant':26s} {'CPU s':>22s} {'rows':>7s} {'ratio to peer':>26s} {'target':>7s}")
    failed = False
    for name in variants:
        c = cpu[name]
        text = f"{name:26s} {statistics.median(c):8.2f} [{min(c):.2f}, {max(c):.2f}] {rows[name]:7d}"
        if name in peers:
            ratios = [a / b for a, b in zip(c, cpu[peers[name]])]
            med = statistics.median(ratios)
            target = TARGETS.get(name)
            verdict = "" if target is None else ("  holds" if med <= target else "  MISSED")
            failed |= target is not None and med > target
            text += (f" {med:8.2f}x [{min(ratios):.2f}, {max(ratios):.2f}]"
                     f" {'' if target is None else f'<= {target:g}x'}{verdict}")
        print(text)
    return 1 if failed else 0


VARIANTS = {  # name: (package, simulate keywords as Python source), peer
    "FMI 2.0 fixed step": ("SpaceHopper.ssp", "events=False", None),
    "FMI 2.0 rollback": ("SpaceHopper.ssp", "events=True", "FMI 2.0 fixed step"),
    "FMI 3.0 fixed step": ("SpaceHopper-fmi3.ssp", "events=False", None),
    "FMI 3.0 early return": ("SpaceHopper-fmi3.ssp", "events=True", "FMI 3.0 fixed step"),
    "FMI 3.0 model exchange": ("SpaceHopper-fmi3.ssp", "algorithm='model-exchange'", "FMI 3.0 fixed step"),
}


def _callgrind(dist, package, keywords, stop, step):
    from bench_fmu import callgrind_instructions

    code = (f"import sys; sys.path.insert(0, {str(ROOT / 'fmu_src')!r}); from pogofmu.ssp import simulate; "
            f"simulate({str(dist / package)!r}, parameters='moon', stop_time={stop!r}, step={step!r}, "
            f"echo_log=False, {keywords})")
    return callgrind_instructions([sys.executable, "-c", code])


def _event_instants(dist, stop, step):
    import numpy as np

    from pogofmu.ssp import simulate

    res = simulate(dist / "SpaceHopper-fmi3.ssp", parameters="moon", stop_time=stop, step=step, echo_log=False)
    return len(set(np.asarray(res["time"])[np.asarray(res["event"]) != 0]))


def count_instructions(dist, short, step, window=1.0, stop_time=30.0):
    import shutil

    if shutil.which("valgrind") is None:
        print("--instructions needs valgrind (Debian package valgrind)", file=sys.stderr)
        return 2
    n = int(round(window / step))  # the second run is `window` simulated seconds longer
    in_window = _event_instants(dist, short + window, step) - _event_instants(dist, short, step)
    in_run = _event_instants(dist, stop_time, step)
    per_step = {}
    for name, (package, keywords, _) in VARIANTS.items():
        a = _callgrind(dist, package, keywords, short, step)
        b = _callgrind(dist, package, keywords, short + window, step)
        per_step[name] = (b - a) / n
        print(f"{name}: {per_step[name]:,.0f} instructions per step", flush=True)
    print(f"\nSpaceHopper, Moon, instructions per communication step of {step:g} s from t = {short:g} s to "
          f"{short + window:g} s, callgrind; event instants per second: {in_window / window:.2f} in the window, "
          f"{in_run / stop_time:.2f} in the {stop_time:g} s run")
    failed = False
    for name, (_, _, peer) in VARIANTS.items():
        text = f"{name:26s} {per_step[name]:12,.0f}"
        if peer is not None:
            ratio = per_step[name] / per_step[peer]
            target = TARGETS.get(name)
            text += f"   {ratio:.3f}x {peer}"
            if target is not None:
                text += f"   target <= {target:g}x: {'holds' if ratio <= target else 'MISSED'}"
                failed |= ratio > target
        print(text)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
