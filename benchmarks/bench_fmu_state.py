#!/usr/bin/env python3
"""Benchmark (c): fmi2GetFMUstate as events accumulate.

The built PogoStick FMU (dist/, through fmpy's FMU2Slave) hops elastically (``c = 0``,
``k = 1e6``, a 0.1 mm drop: ~165 events per simulated second) until ``--events`` events have
happened; at a tenth of them and at all of them, ``fmi2GetFMUstate`` + ``fmi2FreeFMUstate`` is timed
(best CPU time of ``--repeat`` calls).  The subject is the ratio late/early: the state must not
grow with the event count (an engine that keeps every event in its state slowed the call from 72 ms
to 558 ms between 2.6k and 25.8k events).  Run with ``log_events = 0`` (the
default: constant memory) and, for information, ``log_events = 1`` (full history kept on
purpose).  Exit status 1 if the ratio of the default run exceeds 2.

    python benchmarks/bench_fmu_state.py [--events 25000] [--repeat 20]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from support import Instance  # noqa: E402

PARAMS = dict(c=0.0, k=1e6, y_0=1.0001, z_0=1e-4)


def time_get_state(inst, repeat):
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        s = inst.fmu.getFMUstate()
        best = min(best, time.process_time() - t0)
        inst.fmu.freeFMUstate(s)
    return best


def run(n_events, repeat, log_events):
    inst = Instance("PogoStick").init(log_events=log_events, **PARAMS)
    out = {}
    try:
        for target in (n_events // 10, n_events):
            while inst.get("n_events") < target:
                inst.step(0.1)
            inst.messages.clear()  # the event log of log_events = 1 is not what is measured
            out[inst.get("n_events")] = time_get_state(inst, repeat)
    finally:
        inst.close()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--events", type=int, default=25000)
    ap.add_argument("--repeat", type=int, default=20)
    args = ap.parse_args(argv)
    ok = True
    for log_events in (0, 1):
        (n1, t1), (n2, t2) = sorted(run(args.events, args.repeat, log_events).items())
        ratio = t2 / t1 if t1 > 0 else float("nan")
        verdict = "" if log_events else (" (target <= 2: hold)" if ratio <= 2 else " (target <= 2: MISSED)")
        ok &= bool(log_events or ratio <= 2)
        print(f"fmi2GetFMUstate, log_events={log_events}: {t1 * 1e3:.3f} ms at {n1} events, "
              f"{t2 * 1e3:.3f} ms at {n2} events: ratio {ratio:.2f}{verdict}", flush=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
