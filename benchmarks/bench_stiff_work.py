#!/usr/bin/env python3
"""Benchmark: the work of the stiff method, counted — Rodas5P (the engine's ``method = 1``) against
Radau IIA of order 5 (scipy's ``Radau``, Hairer & Wanner's RADAU5 algorithm), in operations, not
seconds, so that neither Python's overhead nor the machine's load enters (issue 29: "choose from
measurements").

The Penetrator, 10 s from the default drop, on the stiff soils of bench_stiff.py (K = 1e6 N/m,
n = 1; K = 1e8, n = 1.5), rel_tol 1e-4 ... 1e-10, abs_tol 1e-12, on the same equations:

* **Rodas5P**: the C engine built with the Penetrator's generated C (exact Jacobian from the
  dual-number code), stopped at each contact as FMI 3.0's early return does (tests/native_engine.py).
  Per step attempt: one LU of ``W = I/(h γ) − J`` and 8 stages (8 flow evaluations, 8 solves);
  per Jacobian: 3 exact columns and one flow evaluation for ``∂f/∂t``.
* **Radau IIA**: scipy's ``solve_ivp(method="Radau")`` on the tests' independent right-hand side
  (tests/references.py), restarted at each contact; its own counters ``nfev`` (the right-hand
  side: three per simplified-Newton iteration, and those of its finite-difference Jacobians),
  ``njev``, ``nlu`` (scipy counts the real 3x3 and the complex 3x3 factorization of a step size
  one each), and its accepted steps.

Each row also gives the largest contact-time error (touchdowns and liftoffs) against DOP853 at
rtol 1e-13: the work is compared at the accuracy each method reaches.

    python benchmarks/bench_stiff_work.py
"""
from __future__ import annotations

import ctypes as C
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "fmu_src"))

import references  # noqa: E402  (the tests' independent references)
from native_engine import NativeEngine  # noqa: E402
from pogofmu.codegen.build import engine_library  # noqa: E402
from pogofmu.runtime.solver import SOLVER_PARAMETERS  # noqa: E402
from pogofmu.runtime.models import penetrator  # noqa: E402

T_END = 10.0
SOILS = [(1e6, 1.0), (1e8, 1.5)]
TOLS = [1e-4, 1e-6, 1e-8, 1e-10]
RODAS_STAGES = 8


def rodas_work(engine, K, n, rel_tol):
    """([(event, time)], steps, rejected, Jacobians) of the engine's Rodas5P to T_END."""
    model = penetrator.MODEL
    p = dict(model.defaults(), K=K, n=n)
    s = {q.name: q.default for q in SOLVER_PARAMETERS}
    s.update(method=1, rel_tol=rel_tol, abs_tol=1e-12, max_steps_per_second=1e8, max_steps_per_call=1e9)
    e, err = engine.start(model, p, s, [float(v.start) for v in model.inputs], 0.0, T_END)
    if e is None:
        raise SystemExit(err)
    stop, events = C.c_int(), []
    while True:
        if engine.lib.pg_engine_advance_to_event(e, T_END, C.byref(stop)):
            raise SystemExit(engine.message(e))
        if not stop.value:
            break
        t = engine.served(e)[0]
        if engine.lib.pg_engine_advance(e, t):
            raise SystemExit(engine.message(e))
        events.append((model.events[engine.last_event(e)[1]].name, t))
    steps, rejected, jacobians, _, _ = engine.stats(e)
    return [ev for ev in events if ev[0] != "max_penetration"], steps, rejected, jacobians


def radau_work(K, n, rel_tol):
    """([(event, time)], accepted steps, nfev, njev, nlu) of scipy's Radau, counted over the
    reference's restarts (its solve_ivp calls)."""
    counts = dict(steps=0, nfev=0, njev=0, nlu=0)
    real = references.solve_ivp

    def counted(*args, **kw):
        sol = real(*args, **kw)
        counts["steps"] += len(sol.t) - 1
        for key in ("nfev", "njev", "nlu"):
            counts[key] += getattr(sol, key)
        return sol
    references.solve_ivp = counted
    try:
        items = tuple(sorted(dict(references.PENETRATOR_DEFAULTS, K=K, n=n).items()))
        events, _ = references._reference_cached.__wrapped__(T_END, items, "Radau", rel_tol, 1e-12)
    finally:
        references.solve_ivp = real
    contacts = [(name, t) for name, t, _ in events if name != "max_penetration"]
    return contacts, counts["steps"], counts["nfev"], counts["njev"], counts["nlu"]


def error(got, ref):
    if [g[0] for g in got] != [r[0] for r in ref]:
        return "events differ"
    return f"{max(abs(g[1] - r[1]) for g, r in zip(got, ref)):.1e}"


def main():
    with tempfile.TemporaryDirectory(prefix="bench_stiff_work_") as tmp:
        engine = NativeEngine(engine_library(penetrator.MODEL, Path(tmp)))
        for K, n in SOILS:
            ref = references.penetrator_contacts(T_END, "DOP853", 1e-13, K=K, n=n)
            print(f"\nPenetrator, K = {K:g}, n = {n:g}, {T_END:g} s ({len(ref)} contact events); "
                  f"error: largest contact-time error (s) from DOP853 at rtol 1e-13\n")
            print("| rel_tol | Rodas5P: steps (rejected) | flow evals | Jacobians | LU (3x3 real) | error "
                  "| Radau IIA: steps | nfev | njev | nlu (3x3 real + complex) | error |")
            print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
            for tol in TOLS:
                ev, steps, rejected, jac = rodas_work(engine, K, n, tol)
                attempts = steps + rejected
                evals = RODAS_STAGES * attempts + jac
                r_ev, r_steps, nfev, njev, nlu = radau_work(K, n, tol)
                print(f"| {tol:g} | {steps} ({rejected}) | {evals} | {jac} | {attempts} | {error(ev, ref)} "
                      f"| {r_steps} | {nfev} | {njev} | {nlu} | {error(r_ev, ref)} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
