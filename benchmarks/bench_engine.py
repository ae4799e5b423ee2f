#!/usr/bin/env python3
"""Benchmark (a): the engine alone against a scipy ``solve_ivp`` restart loop of the same model.

For every case of ``benchmarks/cases/`` (see its docstring to add one): the engine
(``pogofmu.runtime.solver.Simulator`` on the model, no FMI) and the case's scipy loop (terminal events,
restart loop) integrate the case's experiment at ``rel_tol = 1e-9``, ``abs_tol = 1e-12``,
``max_step = 0.01``; engine method 5 (Dormand-Prince 5(4)) against ``RK45``, method 8 (DOP853)
against ``DOP853``.  The runs alternate (engine, scipy, scipy, engine, ...) so that load from other
processes hits both alike; the best CPU time (``time.process_time``: the work of this process,
less disturbed by other processes on a shared machine than wall time) of ``--repeat`` runs of
each counts (the median is
printed too).  The event error is the largest ``|t_i - t_ref_i|`` against the case's reference
event times (both sequences must match the reference in count and kind).

A second peer, for information: scipy's Fortran integrators ``ode('dopri5')`` /
``ode('dop853')`` (Hairer's codes, the faster scipy choice) on the model's own functions — a
``solout`` callback watches the active guards after every accepted step, a crossing in its
direction is located by secant iterations on re-integrations from the step's start (the
Fortran codes expose no dense output to scipy), the jump is applied and the integration
restarted — timed and scored the same way (columns ``ode s``, ``ode/engine``, ``ode err s``).

Targets (judged on cases with ``targets=True``): the engine at least 2x faster than
scipy, with an event error no larger; other cases are rows for information.  A case with
``compare_to`` is also timed against that case's engine time (PogoStickMem with a
linear law at most 1.3x PogoStick).  Exit status 1 if a target is missed.

    python benchmarks/bench_engine.py [--repeat 9] [--case PogoStick ...]
"""
from __future__ import annotations

import argparse
import gc
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from cases import all_cases, event_error  # noqa: E402

RTOL, ATOL, MAX_STEP = 1e-9, 1e-12, 0.01
PAIRS = ((5, "RK45"), (8, "DOP853"))  # engine method -> scipy method
SPEED_TARGET = 2.0


def run_engine(model, p, stop_time):
    from pogofmu.runtime.solver import Simulator

    sim = Simulator(model, p, t_stop=stop_time, keep_history=True)  # the event times are compared
    sim.advance(stop_time)
    return [(ev.time, ev.name) for ev in sim.events]


ODE = {5: "dopri5", 8: "dop853"}


def ode_loop(model, p, stop_time, integrator, rtol, atol, max_step):
    """Events ``[(time, name)]`` of ``model`` with scipy's Fortran ``ode(integrator)`` (see the module
    docstring): the model's flow, guards and jumps, a restart at each event."""
    from scipy.integrate import ode

    u = tuple(float(v.start) for v in model.inputs)
    x, q = model.initial(p)
    t, events = 0.0, []

    def solver(q, t0, x0, solout=None):
        f = model.bind(q, u, p) if model.bind is not None else (lambda t, y: model.flow(t, y, q, u, p))
        r = ode(lambda t, y: f(t, list(y))).set_integrator(integrator, rtol=rtol, atol=atol, max_step=max_step,
                                                          nsteps=10 ** 7)
        if solout is not None:
            r.set_solout(solout)
        return r.set_initial_value(list(x0), t0)

    while t < stop_time:
        active = [(k, ev) for k, ev in enumerate(model.events) if ev.active(q)]
        seen = {"prev": None, "hit": None}

        def solout(ts, ys, active=active, q=q):
            g = [ev.guard(list(ys), q, u, p) for _, ev in active]
            prev = seen["prev"]
            seen["prev"] = (ts, list(ys), g)
            if prev is not None:
                for j, (_, ev) in enumerate(active):
                    before, after = prev[2][j], g[j]
                    if (ev.direction < 0 and before > 0.0 >= after) or (ev.direction > 0 and before < 0.0 <= after):
                        seen["hit"] = (j, prev, (ts, list(ys), g))
                        return -1
            return 0
        r = solver(q, t, x, solout)
        r.integrate(stop_time)
        if seen["hit"] is None:
            break
        j, (ta, ya, ga), (tb, yb, gb) = seen["hit"]
        ev = active[j][1]
        ga_j, gb_j = ga[j], gb[j]
        for _ in range(60):  # secant (Illinois) on the guard along re-integrations from ta
            tm = tb - gb_j * (tb - ta) / (gb_j - ga_j)
            if not ta < tm < tb:
                tm = 0.5 * (ta + tb)
            ym = list(solver(q, ta, ya).integrate(tm))
            gm = ev.guard(ym, q, u, p)
            if (gm > 0.0) == (gb_j > 0.0) and gm != 0.0:
                tb, yb, gb_j = tm, ym, gm
                ga_j *= 0.5
            else:
                ta, ya, ga_j = tm, ym, gm
            if tb - ta <= 1e-14 * max(1.0, abs(tb)):
                break
        t = tb
        x, q = ev.jump(list(yb), q, u, p)
        events.append((t, ev.name))
    return events


def timed(fn):
    gc.collect()
    t0 = time.process_time()
    result = fn()
    return time.process_time() - t0, result


def bench_case(case, repeat):
    model = case.load_model()
    reference = case.reference_events()
    rows = []
    for method, scipy_method in PAIRS:
        # the model's parameters and the solver's settings in one table, as an FMU's (Simulator splits them)
        p = {**case.params, "method": method, "rel_tol": RTOL, "abs_tol": ATOL, "max_step": MAX_STEP}
        full = case.full_params()
        engine = lambda: run_engine(model, p, case.stop_time)  # noqa: E731
        peer = lambda: case.scipy_loop(full, case.stop_time, scipy_method, RTOL, ATOL, MAX_STEP)  # noqa: E731
        p_model = model.params(**case.params)
        fortran = lambda: ode_loop(model, p_model, case.stop_time, ODE[method], RTOL, ATOL, MAX_STEP)  # noqa: E731
        t_engine, t_peer, t_ode = [], [], []
        ev_engine = ev_peer = ev_ode = None
        for i in range(repeat):
            order = ((engine, t_engine), (peer, t_peer), (fortran, t_ode))
            for fn, times in (order if i % 2 == 0 else order[::-1]):
                dt, events = timed(fn)
                times.append(dt)
                if fn is engine:
                    ev_engine = events
                elif fn is peer:
                    ev_peer = events
                else:
                    ev_ode = [(tt, name) for tt, name in events]
        err_engine = event_error(ev_engine, reference)
        err_peer = event_error(ev_peer, reference)
        best_e, best_p = min(t_engine), min(t_peer)
        rows.append(dict(
            case=case.name, pair=f"{method} vs {scipy_method}", t_engine=best_e, t_peer=best_p,
            med_engine=statistics.median(t_engine), med_peer=statistics.median(t_peer),
            ratio=best_p / best_e, err_engine=err_engine, err_peer=err_peer,
            n_engine=len(ev_engine), n_peer=len(ev_peer), n_ref=len(reference),
            t_ode=min(t_ode), err_ode=event_error(ev_ode, reference), n_ode=len(ev_ode),
            fast=best_p / best_e >= SPEED_TARGET,
            accurate=err_engine <= err_peer and err_engine != float("inf")))
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=15, help="timed runs of each solver (best counts)")
    ap.add_argument("--case", action="append", help="run only this case (name or FMU; repeatable)")
    args = ap.parse_args(argv)

    cases = all_cases(args.case)
    print(f"(a) engine alone vs scipy solve_ivp restart loop: rel_tol {RTOL:g}, abs_tol {ATOL:g}, "
          f"max_step {MAX_STEP:g}; best of {args.repeat} alternating runs (median in brackets)")
    for case in cases:
        print(f"  {case.name}: {case.stop_time:g} s, params {case.params or 'default'}; "
              f"reference: {case.reference_label}")
    head = (f"{'case':<14} {'method':<13} {'engine s':>17} {'scipy s':>17} {'scipy/engine':>12} "
            f"{'engine err s':>12} {'scipy err s':>12} {'events e/s/ref':>14}  {'>=2x':>4} {'err<=':>5}"
            f"  {'ode s':>7} {'ode/engine':>10} {'ode err s':>10} {'ode ev':>6}")
    print(head)
    print("-" * len(head))
    missed = []
    best_engine = {}  # (case, method) -> best engine time
    for case in cases:
        for r in bench_case(case, args.repeat):
            best_engine[(case.name, r["pair"])] = r["t_engine"]
            judged = case.targets
            print(f"{r['case']:<14} {r['pair']:<13} "
                  f"{r['t_engine']:>7.4f} ({r['med_engine']:.4f}) {r['t_peer']:>7.4f} ({r['med_peer']:.4f}) "
                  f"{r['ratio']:>11.2f}x {r['err_engine']:>12.2e} {r['err_peer']:>12.2e} "
                  f"{r['n_engine']:>4}/{r['n_peer']}/{r['n_ref']:<5}  "
                  f"{verdict(r['fast'], judged):>4} {verdict(r['accurate'], judged):>5}"
                  f"  {r['t_ode']:>7.4f} {r['t_ode'] / r['t_engine']:>9.2f}x {r['err_ode']:>10.2e} {r['n_ode']:>6}",
                  flush=True)
            if judged and not r["fast"]:
                missed.append(f"{r['case']} {r['pair']}: {r['ratio']:.2f}x < {SPEED_TARGET:g}x")
            if judged and not r["accurate"]:
                missed.append(f"{r['case']} {r['pair']}: event error {r['err_engine']:.2e} > "
                              f"scipy's {r['err_peer']:.2e}")
    for case in cases:
        if not case.compare_to:
            continue
        for pair in (f"{m} vs {s}" for m, s in PAIRS):
            if (case.compare_to, pair) not in best_engine:
                continue
            ratio = best_engine[(case.name, pair)] / best_engine[(case.compare_to, pair)]
            ok = ratio <= case.max_ratio
            print(f"composition cost: {case.name} / {case.compare_to}, engine method {pair.split()[0]}: "
                  f"{ratio:.2f}x (target <= {case.max_ratio:g}x: {'yes' if ok else 'NO'})")
            if not ok:
                missed.append(f"{case.name}: {ratio:.2f}x {case.compare_to} > {case.max_ratio:g}x")
    if missed:
        print("targets MISSED: " + "; ".join(missed))
        return 1
    print(f"targets hold: engine >= {SPEED_TARGET:g}x faster than scipy with an event error no larger "
          f"(rows marked yes/NO; '-' rows are for information)")
    return 0


def verdict(ok, judged):
    return ("yes" if ok else "NO") if judged else "-"


if __name__ == "__main__":
    sys.exit(main())
