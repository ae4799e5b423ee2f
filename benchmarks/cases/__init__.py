"""Benchmark cases: one module per model, each defining ``CASE = Case(...)``.

Every ``benchmarks/bench_*.py`` script runs every case found here, so a new model gets its rows
in both benchmark tables by adding **one file** to this folder.

How to add a case (e.g. ``pogostick_mem.py`` for PogoStickMem)
----------------------------------------------------------------
1. Copy ``pogostick.py`` to ``<your_model>.py`` in this folder.
2. Set ``name`` (row label), ``fmu`` (the FMU's name, i.e. the slave class that ``build_fmu.py``
   builds, e.g. ``"PogoStickMem"``), ``model`` (``"module:ATTRIBUTE"`` of the
   :class:`~pogofmu.runtime.model.HybridModel`, e.g. ``"pogofmu.runtime.models.pogo_stick_mem:MODEL"``) and
   ``params`` (overrides of the model's parameter defaults; ``{}`` = the default experiment; do
   not put solver knobs here, the benchmarks set them).
3. Rewrite ``scipy_loop``: the same model written *as a Python user would* with
   ``scipy.integrate.solve_ivp`` -- one right-hand side per mode, the guards as **terminal**
   event functions with ``.direction`` set, and a restart loop that applies the jump at
   ``sol.t_events`` / ``sol.y_events`` and calls ``solve_ivp`` again.  It must integrate the
   *same ODE system* as the model (same states, including quadratures such as ``W_leg``, so
   that both solvers' error control sees the same vector) and return the list of events as
   ``(time, event_name)`` with the model's event names.  Its signature is
   ``scipy_loop(p, stop_time, method, rtol, atol, max_step)``: ``p`` is the full parameter
   dict (model defaults updated with ``params``), ``method`` a ``solve_ivp`` method name.
4. Set ``reference``: a callable ``reference(case)`` returning the exact event sequence
   ``[(time, event_name), ...]`` up to ``stop_time``:

   * a closed form: :func:`closed_form_reference` (the basic stick's events computed by
     ``pogofmu.references.closed_form``), or :func:`csv_reference` for a CSV with ``event`` and ``time_s``
     columns;
   * no closed form: an independent model, not the peer's own loop (a mistake in the peer would
     otherwise make it look exact): :func:`tests_reference` takes the scipy model of the test
     suite (``tests/test_mem.py``, ``test_sma.py``, ``test_penetrator.py``, DOP853 at rtol 1e-13);
     ``tight_scipy_reference()`` (the case's own ``scipy_loop`` at ``rtol=1e-13``) is left for a
     new model until it has one; say which in ``reference_label``.  The "event error" is then
     the distance to that much tighter solution (meaningful down to ~1e-11 s).

5. Targets: benchmark (a)'s (>= 2x faster than scipy with an event error no larger) are judged
   on cases with ``targets=True`` (PogoStick); other rows are printed for information.
   Benchmark (b) judges its targets (the FMU against its own FMI floor) on every case.  ``compare_to``/``max_ratio`` set a relative target on the engine time
   (PogoStickMem with a linear law against PogoStick: composing elements costs <= 1.3x).

The event error of a run is the largest ``|t_i - t_ref_i|`` over the events; a run whose event
sequence (count and names, in order) differs from the reference has an infinite error.

Run one case only: ``python benchmarks/bench_engine.py --case PogoStick`` (same for
``bench_fmu.py``).
"""
from __future__ import annotations

import csv
import importlib
import pkgutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Tuple

Events = List[Tuple[float, str]]



@dataclass(frozen=True)
class Case:
    """One benchmark case: a model, its parameters, a scipy peer and the exact event times."""

    name: str  # row label
    fmu: str  # FMU built by build_fmu.py (the slave class name), e.g. "PogoStick"
    model: str  # "module:ATTRIBUTE" of the HybridModel, e.g. "pogofmu.runtime.models.pogo_stick:MODEL"
    scipy_loop: Callable[..., Events]  # (p, stop_time, method, rtol, atol, max_step) -> events
    reference: Callable[["Case"], Events]  # (case) -> exact events [(time, name), ...] up to stop_time
    reference_label: str  # where the reference comes from (printed with the results)
    params: Dict[str, float] = field(default_factory=dict)  # overrides of the model's defaults
    stop_time: float = 10.0
    targets: bool = False  # judge this row against benchmark (a)'s targets (else: a row for information)
    compare_to: str = ""  # another case's name: the engine time of this case relative to it ...
    max_ratio: float = 0.0  # ... must stay at or below this (linear PogoStickMem <= 1.3x)

    def reference_events(self) -> Events:
        return self.reference(self)

    def load_model(self):
        module, attr = self.model.split(":")
        return getattr(importlib.import_module(module), attr)

    def full_params(self) -> Dict[str, float]:
        """The model's parameter defaults updated with ``params`` (what ``scipy_loop`` gets)."""
        values = self.load_model().defaults()
        unknown = set(self.params) - set(values)
        if unknown:
            raise ValueError(f"case {self.name}: unknown parameter(s) {sorted(unknown)}")
        values.update(self.params)
        return values


def csv_reference(path) -> Callable[[Case], Events]:
    """Reference events from a CSV with columns ``event`` and ``time_s`` (``#`` lines are comments)."""

    def load(case: Case) -> Events:
        with open(path) as f:
            rows = csv.DictReader(line for line in f if not line.startswith("#"))
            return [(float(r["time_s"]), r["event"]) for r in rows]

    return load


def closed_form_reference(case: Case) -> Events:
    """The basic stick's events in closed form (pogofmu.references.closed_form, 40-digit roots) for the
    case's parameters, up to its stop time."""
    from pogofmu.references.closed_form import events_as_floats

    return [(e["time"], e["name"]) for e in events_as_floats(case.params, case.stop_time)]


def tests_reference(kind: str) -> Callable[[Case], Events]:
    """Reference events from the independent scipy model in the test suite (``tests/test_mem.py``,
    ``test_sma.py``, ``test_penetrator.py``: the equations written there from docs/models.md, with
    DOP853 at rtol 1e-13), not the benchmark's own peer: a mistake in the peer's loop cannot make
    the peer look exact.  ``kind``: ``"mem"``, ``"sma"`` (the default drop only) or ``"penetrator"``."""

    def load(case: Case) -> Events:
        import sys

        tests = str(Path(__file__).resolve().parents[2] / "tests")
        if tests not in sys.path:
            sys.path.insert(0, tests)
        p = case.full_params()
        if kind == "mem":
            from test_mem import scipy_mem

            base = {k: p[k] for k in ("m", "k", "x_i", "g", "y_0", "ydot_0")}
            if base != dict(m=1.0, k=100.0, x_i=1.0, g=9.81, y_0=1.5, ydot_0=0.0):
                raise ValueError(f"case {case.name}: the tests' mem-stick model drops the default stick only")
            return [(t, n) for n, t, _ in scipy_mem(p["spring_law"], p["beta"], p["gamma"], case.stop_time,
                                                    c=p["c"], a0=p["a_0"])]
        if kind == "sma":
            from test_sma import scipy_sma

            if case.params:
                raise ValueError(f"case {case.name}: the tests' SMA model drops the default stick only")
            return [(t, n) for n, t in scipy_sma(case.stop_time)]
        from test_penetrator import reference

        return [(t, n) for n, t, _ in reference(case.stop_time, **case.params)[0]]

    return load


_TIGHT_CACHE: Dict[str, Events] = {}


def tight_scipy_reference(rtol: float = 1e-13, atol: float = 1e-15,
                          max_step: float = 0.01) -> Callable[[Case], Events]:
    """Reference events for a model without a closed form: the case's own ``scipy_loop`` with
    DOP853 at ``rtol=1e-13``, ``atol=1e-15`` (computed once per process and case)."""

    def load(case: Case) -> Events:
        if case.name not in _TIGHT_CACHE:
            _TIGHT_CACHE[case.name] = case.scipy_loop(case.full_params(), case.stop_time, "DOP853",
                                                      rtol, atol, max_step)
        return _TIGHT_CACHE[case.name]

    return load


def event_error(events: Events, reference: Events) -> float:
    """Largest |t - t_ref| over the events; inf if the sequences differ in length or names."""
    if len(events) != len(reference) or any(a[1] != b[1] for a, b in zip(events, reference)):
        return float("inf")
    return max((abs(a[0] - b[0]) for a, b in zip(events, reference)), default=0.0)


def all_cases(names=None) -> List[Case]:
    """Every ``CASE`` defined by a module of this package (sorted by module name), optionally
    only those whose ``name`` or ``fmu`` is in ``names``."""
    cases = []
    for info in sorted(pkgutil.iter_modules([str(Path(__file__).parent)]), key=lambda m: m.name):
        module = importlib.import_module(f"{__name__}.{info.name}")
        case = getattr(module, "CASE", None)
        if isinstance(case, Case):
            cases.append(case)
    if names:
        wanted = set(names)
        cases = [c for c in cases if c.name in wanted or c.fmu in wanted]
        missing = wanted - {c.name for c in cases} - {c.fmu for c in cases}
        if missing:
            raise SystemExit(f"unknown benchmark case(s): {sorted(missing)}")
    return cases
