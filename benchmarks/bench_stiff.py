#!/usr/bin/env python3
"""Benchmark: the stiff methods (issue 29) — a work-precision table on stiff soils, in one run.

The Penetrator (10 s from the default drop) on a stiff soil (K = 1e6 N/m, n = 1; K = 1e8, n = 1.5),
over rel_tol 1e-4 ... 1e-10 (abs_tol 1e-12), for:

* ``auto``, ``rodas5p``, ``dopri5``: the native FMU (dist/native/Penetrator.fmu, FMI 2.0
  co-simulation) in fmpy with method = 0, 1, 5 (extracted once; communication step 0.1 s,
  log_events = 1 for the event times; fmpy's instantiation and its loop over the
  communication points are in these columns, the reading of modelDescription.xml is not);
* ``radau``, ``bdf``, ``lsoda``: scipy's solve_ivp on the same equations (tests/references.py,
  Python right-hand side, the contacts as terminal events);
* ``cvode``: fmpy's CVode on the FMI 3.0 model exchange FMU (dist/native/fmi3/Penetrator.fmu;
  event times from the FMU's output t_last_event at every 1 ms output point).

CPU seconds (``time.process_time`` of the whole run, best of ``--repeat``) against the largest
contact-time error (touchdowns and liftoffs, in order) from scipy Radau at rtol 1e-12;
``events differ`` where the run found other events. Targets (issue 29; K = 1e6, rel_tol 1e-8):
auto within 1e-8 s of the reference, at most 1/20 of dopri5's CPU and 1/10 of lsoda's. Exit
status 1 if one is missed. Needs dist/ (``python3 tasks.py build``).

    python benchmarks/bench_stiff.py [--repeat 3] [--quick]
"""
from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "tests"))

from references import _reference_cached, PENETRATOR_DEFAULTS  # noqa: E402  (the tests' references)

DIST = ROOT / "dist"
T_END = 10.0
SOILS = [(1e6, 1.0), (1e8, 1.5)]
TOLS = [1e-4, 1e-6, 1e-8, 1e-10]
EVENT = re.compile(r"event \d+ (\w+) at t = ([0-9.eE+-]+) s")


def scipy_contacts(method, rtol, K, n, atol=1e-12):
    items = tuple(sorted(dict(PENETRATOR_DEFAULTS, K=K, n=n).items()))
    events, _ = _reference_cached.__wrapped__(T_END, items, method, rtol, atol)
    return [(name, t) for name, t, _ in events if name != "max_penetration"]


_UNZIPPED = {}


def unzipped(path):
    """The FMU extracted, its modelDescription.xml read and validated, once: fmpy would do both at
    every run (~10 ms that are no solver's work; scipy's columns do not pay for parsing either).
    Keyword arguments for ``simulate_fmu``."""
    from fmpy import extract, read_model_description

    if path not in _UNZIPPED:
        folder = extract(str(path))
        _UNZIPPED[path] = dict(filename=folder, model_description=read_model_description(folder, validate=True),
                               validate=False)
    return _UNZIPPED[path]


def fmu_contacts(method, rtol, K, n, fmu=DIST / "native" / "Penetrator.fmu", t_end=T_END):
    from fmpy import simulate_fmu

    messages = []

    def logger(component, instance, status, category, message):
        messages.append(message.decode())

    soil = {"K": K, "n": n} if K is not None else {}
    simulate_fmu(**unzipped(fmu), stop_time=t_end, output_interval=0.1, debug_logging=True, logger=logger,
                 start_values={"method": method, "rel_tol": rtol, **soil, "log_events": 1,
                               "max_steps_per_second": 1e7, "max_steps_per_call": 1e8})
    found = [EVENT.search(m) for m in messages]
    return [(f.group(1), float(f.group(2))) for f in found if f and f.group(1) != "max_penetration"]


def cvode_contacts(rtol, K, n):
    from fmpy import simulate_fmu

    res = simulate_fmu(**unzipped(DIST / "native" / "fmi3" / "Penetrator.fmu"), fmi_type="ModelExchange", solver="CVode",
                       relative_tolerance=rtol, stop_time=T_END, output_interval=1e-3, start_values={"K": K, "n": n},
                       output=["t_last_event", "last_event", "n_events"])
    out, seen = [], 0
    names = {1: "touchdown", 2: "liftoff", 3: "max_penetration"}  # last_event: index + 1
    for t_last, last, count in zip(res["t_last_event"], res["last_event"], res["n_events"]):
        if count > seen:
            seen = count
            name = names.get(int(last), str(last))
            if name != "max_penetration":
                out.append((name, float(t_last)))
    return out


def error(got, ref):
    if [a for a, _ in got] != [a for a, _ in ref]:
        return None
    return max(abs(a - b) for (_, a), (_, b) in zip(got, ref))


def timed(fn, repeat):
    best, value = float("inf"), None
    for _ in range(repeat):
        t0 = time.process_time()
        value = fn()
        best = min(best, time.process_time() - t0)
    return best, value


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="rel_tol 1e-8 only, best of two")
    args = ap.parse_args(argv)
    tols, repeat = ([1e-8], 2) if args.quick else (TOLS, args.repeat)
    if not (DIST / "native" / "Penetrator.fmu").exists():
        raise SystemExit("dist/native/Penetrator.fmu missing: run python3 tasks.py build first")
    runs = {
        "auto": lambda r, K, n: fmu_contacts(0, r, K, n),
        "rodas5p": lambda r, K, n: fmu_contacts(1, r, K, n),
        "dopri5": lambda r, K, n: fmu_contacts(5, r, K, n),
        "radau": lambda r, K, n: scipy_contacts("Radau", r, K, n),
        "bdf": lambda r, K, n: scipy_contacts("BDF", r, K, n),
        "lsoda": lambda r, K, n: scipy_contacts("LSODA", r, K, n),
        "cvode": lambda r, K, n: cvode_contacts(r, K, n),
    }
    table = {}
    fmu_contacts(5, 1e-6, 1e4, 1.5)  # warm-up: fmpy's first run loads its libraries
    for K, n in SOILS:
        ref = scipy_contacts("Radau", 1e-12, K, n, atol=1e-15)
        print(f"\nPenetrator, soil K = {K:g} N/m^n, n = {n:g}, {T_END:g} s ({len(ref)} contact events); "
              f"CPU s / largest contact-time error s")
        print(f"{'rel_tol':>8} " + " ".join(f"{name:>20}" for name in runs))
        for r in tols:
            cells = []
            for name, fn in runs.items():
                try:
                    cpu, got = timed(lambda: fn(r, K, n), 1 if name in ("dopri5", "radau", "bdf") else repeat)
                    err = error(got, ref)
                    table[K, n, r, name] = (cpu, err)
                    cells.append(f"{cpu:8.3f} / " + (f"{err:8.1e}" if err is not None else "ev.differ"))
                except Exception as exc:  # a run that fails is a cell, not the end of the table
                    table[K, n, r, name] = (None, None)
                    cells.append(f"{'failed: ' + type(exc).__name__:>20}")
            print(f"{r:8.0e} " + " ".join(f"{c:>20}" for c in cells), flush=True)
    # the targets
    auto, dop, lsoda = (table.get((1e6, 1.0, 1e-8, k)) for k in ("auto", "dopri5", "lsoda"))
    ok = True
    print("\ntargets (K = 1e6, n = 1, rel_tol 1e-8, 10 s):")
    if auto and auto[0] is not None:
        for text, good in ((f"auto contacts within 1e-8 s: {auto[1]:.2g} s", auto[1] is not None and auto[1] < 1e-8),
                           (f"auto / dopri5 CPU <= 1/20: {auto[0] / dop[0]:.4f}", auto[0] * 20 <= dop[0]),
                           (f"auto / lsoda CPU <= 1/10: {auto[0] / lsoda[0]:.4f}", auto[0] * 10 <= lsoda[0])):
            print(f"  {'ok  ' if good else 'MISS'} {text}")
            ok &= good
    else:
        ok = False
    # the Python-hosted FMU (its model's Python functions called back from the engine), over 2 s
    hosted = DIST / "Penetrator.fmu"
    cpu0, ev0 = timed(lambda: fmu_contacts(0, 1e-8, 1e6, 1.0, hosted, 2.0), repeat)
    cpu5, _ = timed(lambda: fmu_contacts(5, 1e-8, 1e6, 1.0, hosted, 2.0), 1)
    gap = error(ev0, fmu_contacts(0, 1e-8, 1e6, 1.0, t_end=2.0))
    print("targets, the Python-hosted FMU (K = 1e6, n = 1, rel_tol 1e-8, 2 s):")
    for text, good in ((f"auto / dopri5 CPU <= 1/10: {cpu0:.3f} / {cpu5:.3f} s = {cpu0 / cpu5:.4f}", cpu0 * 10 <= cpu5),
                       (f"contacts within 1e-9 s of the native FMU's: {gap}", gap is not None and gap <= 1e-9)):
        print(f"  {'ok  ' if good else 'MISS'} {text}")
        ok &= good
    # a non-stiff default experiment: method 0 never switches, so it must cost about what 5 does
    stick = DIST / "native" / "PogoStick.fmu"
    c0 = c5 = float("inf")  # interleaved, best of 9 each: a run is ~20 ms, the machine's noise as much
    for _ in range(9):
        t, e0 = timed(lambda: fmu_contacts(0, 1e-6, None, None, stick, 10.0), 1)
        c0 = min(c0, t)
        t, e5 = timed(lambda: fmu_contacts(5, 1e-6, None, None, stick, 10.0), 1)
        c5 = min(c5, t)
    gap = error(e0, e5)
    print("targets, PogoStick's default experiment (non-stiff, native FMU, whole fmpy run):")
    for text, good in ((f"auto / dopri5 CPU <= 1.2: {c0 / c5:.3f}", c0 <= 1.2 * c5),
                       (f"the same events within 1e-9 s: {len(e0)} events, {gap}", gap is not None and gap <= 1e-9)):
        print(f"  {'ok  ' if good else 'MISS'} {text}")
        ok &= good
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
