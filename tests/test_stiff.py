"""The stiff methods of the native engine: Rodas5P (method = 1) and the automatic method (method = 0:
DOPRI5, Rodas5P while the problem is stiff), against independent references.

The references are scipy's on the same equations written in tests/references.py (DOP853 and Radau
at rtol 1e-12, which agree with each other to ~1e-11 s on these cases; checked here too), closed
forms for the convergence order. The engine runs through tests/native_engine.py (the C engine built
with the model's generated C), the log category through a native FMU in fmpy, and the same engine
with the model's Python functions (the Python-hosted FMUs' way, the Jacobian from the flow on dual
numbers, or by differences for a flow that does not run on them) through the binding. Step counts, not CPU times: nothing here depends on the machine's speed (CPU:
benchmarks/bench_stiff.py).
"""
import ctypes as C
import math
import struct

import pytest

from native_engine import NativeEngine
from pogofmu.codegen.build import c_compiler, engine_library
from pogofmu.runtime.solver import SOLVER_PARAMETERS
from pogofmu.runtime.solver.cengine import FN, PgMsg
from pogofmu.runtime.models import all_models
from references import hard_stop_reference, penetrator_contacts
from support import example_models, fmu_path, needs_mark

pytestmark = needs_mark(c_compiler() is not None, "a C compiler (Debian gcc, or the ziglang PyPI package of pyproject.toml)")

T_END = 3.0  # the Penetrator: three contacts (the references cost ~10 s a case in Python)
SOILS = [(1e6, 1.0), (1e8, 1.5)]


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stiff_engines")
    engines = {}

    def get(model):
        if model.name not in engines:
            engines[model.name] = NativeEngine(engine_library(model, folder))
        return engines[model.name]
    return get


def run(native, model, method, rel_tol, t_end, jvp=True, **par):
    """The events [(name, time)] of a run of the C engine to ``t_end`` (stopping at each event, as
    FMI 3.0's early return), and its work (steps, rejected, Jacobians, switches, method in use)."""
    eng = native(model)
    p = model.defaults()
    p.update(par)
    s = {q.name: q.default for q in SOLVER_PARAMETERS}
    s.update(method=method, rel_tol=rel_tol, max_steps_per_second=1e7, max_steps_per_call=1e9)
    e, err = eng.start(model, p, s, [float(v.start) for v in model.inputs], 0.0, t_end, jvp=jvp)
    assert e is not None, err
    stop, events = C.c_int(), []
    while True:
        assert eng.lib.pg_engine_advance_to_event(e, t_end, C.byref(stop)) == 0, eng.message(e)
        if not stop.value:
            break
        t = eng.served(e)[0]
        assert eng.lib.pg_engine_advance(e, t) == 0, eng.message(e)
        events.append((model.events[eng.last_event(e)[1]].name, t))
    return events, eng.stats(e)


def max_gap(got, ref):
    assert [n for n, _ in got] == [n for n, _ in ref]
    return max(abs(a - b) for (_, a), (_, b) in zip(got, ref))


@pytest.fixture(scope="module")
def soil_refs():
    refs = {}
    for K, n in SOILS:
        dop = penetrator_contacts(T_END, "DOP853", 1e-12, K=K, n=n)
        radau = penetrator_contacts(T_END, "Radau", 1e-12, K=K, n=n)
        assert len(dop) >= 6 and max_gap(dop, radau) < 2e-9  # the two references agree
        refs[K, n] = dop
    return refs


@pytest.mark.parametrize("method", [1, 0])
@pytest.mark.parametrize("K,n", SOILS)
def test_penetrator_contacts_on_stiff_soils(K, n, method, native, soil_refs):
    """Soil K = 1e6 (n = 1) and 1e8 (n = 1.5): every touchdown and liftoff within 1e-8 s of scipy at
    rel_tol 1e-8, in a few thousand steps (DOPRI5 needs ~80 000 steps per simulated second)."""
    model = all_models()["Penetrator"]
    events, (steps, rejected, jacobians, switches, _) = run(native, model, method, 1e-8, T_END, K=K, n=n)
    contacts = [ev for ev in events if ev[0] != "max_penetration"]
    assert max_gap(contacts, soil_refs[K, n]) < 1e-8
    assert steps + rejected < 8000 * T_END
    if method == 0:
        assert switches >= 4  # into each contact and out of it


def test_penetrator_jacobian_by_differences(native, soil_refs):
    """Without the model's flow_jvp (as a Python-hosted model may be) the Jacobian comes from
    central differences: the same contacts within 1e-8 s, at about the same work."""
    model = all_models()["Penetrator"]
    exact = run(native, model, 1, 1e-8, T_END, K=1e6, n=1.0)
    diff = run(native, model, 1, 1e-8, T_END, jvp=False, K=1e6, n=1.0)
    contacts = [ev for ev in diff[0] if ev[0] != "max_penetration"]
    assert max_gap(contacts, soil_refs[1e6, 1.0]) < 1e-8
    assert diff[1][0] < 1.5 * exact[1][0]


def test_work_on_a_stiff_soil_is_a_twentieth_of_dopri5s(native):
    """The issue's target in steps (deterministic): method 0 on K = 1e6 over 1 s takes at most 1/20
    of DOPRI5's step attempts (the CPU ratio is benchmarks/bench_stiff.py's)."""
    model = all_models()["Penetrator"]
    _, auto = run(native, model, 0, 1e-8, 1.0, K=1e6, n=1.0)
    _, explicit = run(native, model, 5, 1e-8, 1.0, K=1e6, n=1.0)
    assert 20 * (auto[0] + auto[1]) < explicit[0] + explicit[1]


@pytest.mark.parametrize("method", [1, 0])
def test_hard_stop_of_1e7(method, native):
    """A mass pushed by 30 N against a Hunt-Crossley stop of K = 1e7 N/m (examples/hard_stop/), 37
    contacts and releases in 1 s: every one within 1e-8 s of scipy Radau at rtol 1e-12, at rel_tol
    1e-9 (the error accumulates over the bounces: at 1e-8 DOPRI5 ends 8e-8 s off, Rodas5P 2.5e-8 s).
    The contacts last 1 ms: DOPRI5 is not held by stability here, and method 0 stays explicit."""
    model = example_models()["HardStop"]
    ref = hard_stop_reference(1.0)
    assert len(ref) > 20 and max_gap(hard_stop_reference(1.0, method="DOP853"), ref) < 2e-9
    events, (steps, rejected, jacobians, switches, _) = run(native, model, method, 1e-9, 1.0)
    assert max_gap(events, ref) < 1e-8
    assert steps + rejected < 2000


@pytest.mark.parametrize("name", ["PogoStick", "PogoStickMem", "PogoStickSMA", "Penetrator"])
def test_non_stiff_defaults_keep_their_events(name, native):
    """The default experiments are not stiff: method 0 never leaves DOPRI5, so its events are
    method 5's (to the bit, more than the 1e-9 s asked) with the same steps."""
    model = all_models()[name]
    ev5, st5 = run(native, model, 5, 1e-6, model.default_stop_time)
    ev0, st0 = run(native, model, 0, 1e-6, model.default_stop_time)
    assert len(ev0) > 5 and max_gap(ev0, ev5) <= 1e-9
    assert st0[3] == 0 and st0[:2] == st5[:2]


# ---- the convergence order, with fixed steps on a stiff problem in closed form ---------------
LAMBDA = 1e6


def _flow(t, y, dy):
    """A rotation, a stiff Prothero-Robinson equation (y2 = sin t), and a nonlinear coupling
    (y3 = exp(sin t)): the solution is smooth, one eigenvalue is -1e6."""
    dy[0] = -y[1]
    dy[1] = y[0]
    dy[2] = -LAMBDA * (y[2] - math.sin(t)) + math.cos(t)
    dy[3] = y[3] * y[0]


def _exact(t):
    return [math.cos(t), math.sin(t), math.sin(t), math.exp(math.sin(t))]


def _fixed_step_errors(lib, steps, t_end=2.0):
    X = 32
    FUN = C.CFUNCTYPE(C.c_int, C.c_void_p, C.c_double, C.POINTER(C.c_double), C.POINTER(C.c_double), C.c_void_p)
    fun = FUN(lambda ctx, t, y, dy, m: _flow(t, y, dy) or 0)
    lib.pg_rodas_step.argtypes = [FUN, C.c_void_p, C.c_double, *[C.c_void_p] * 2, C.c_double, C.c_int,
                                  *[C.c_void_p] * 6, C.c_void_p]
    lib.pg_rodas_dense.argtypes = [C.c_void_p, C.c_int, C.c_void_p]
    lib.pg_rodas_eval.argtypes = [C.c_void_p, C.c_double, C.c_double, C.c_void_p, C.c_void_p, C.c_double, C.c_int,
                                  C.c_void_p]
    D = C.c_double
    out = []
    for N in steps:
        h, t = t_end / N, 0.0
        y, f = (D * X)(1.0, 0.0, 0.0, 1.0), (D * X)()
        J, dT, yn, fn, K, Q, o = (D * (X * X))(), (D * X)(), (D * X)(), (D * X)(), (D * (13 * X))(), \
            (D * (7 * X))(), (D * X)()
        sing, msg = C.c_int(), C.create_string_buffer(4096)
        dense = 0.0
        for _ in range(N):
            _flow(t, y, f)
            for i in range(X * X):
                J[i] = 0.0
            J[0 * X + 1], J[1 * X + 0], J[2 * X + 2] = -1.0, 1.0, -LAMBDA
            J[3 * X + 3], J[3 * X + 0] = y[0], y[3]
            dT[0], dT[1], dT[2], dT[3] = 0.0, 0.0, LAMBDA * math.cos(t) - math.sin(t), 0.0
            assert lib.pg_rodas_step(fun, None, t, y, f, h, 4, J, dT, yn, fn, K, C.byref(sing), msg) == 0
            lib.pg_rodas_dense(K, 4, Q)
            tm = t + 0.37 * h
            lib.pg_rodas_eval(Q, t, h, y, yn, tm, 4, o)
            dense = max(dense, max(abs(o[i] - v) for i, v in enumerate(_exact(tm))))
            for i in range(4):
                y[i] = yn[i]
            t += h
        out.append((max(abs(y[i] - v) for i, v in enumerate(_exact(t_end))), dense))
    return out


def test_rodas5p_converges_with_order_5_on_a_stiff_problem(native):
    """Fixed steps h = 2/N, N = 10 ... 160, on a problem with one eigenvalue at -1e6 and a closed-form
    solution: the global error falls with slope 5 (no order reduction on the stiff component), the
    continuous extension's error with slope >= 4."""
    lib = native(all_models()["PogoStick"]).lib  # any engine library: pg_rodas_* are in it
    steps = [10, 20, 40, 80, 160]
    errs = _fixed_step_errors(lib, steps)
    slopes = [math.log2(a[0] / b[0]) for a, b in zip(errs, errs[1:])]
    dense = [math.log2(a[1] / b[1]) for a, b in zip(errs, errs[1:])]
    assert all(4.6 < s < 5.5 for s in slopes), slopes
    assert all(s > 3.8 for s in dense), dense
    assert errs[-1][0] < 1e-11


# ---- the switch, seen in the FMU's log ------------------------------------------------------
def test_the_switch_both_ways_in_the_log(soil_refs):
    """method = 0 on K = 1e6 in a native FMU: logSolver reports DOPRI5 -> Rodas5P inside each
    contact (between the reference's touchdown and liftoff) and Rodas5P -> DOPRI5 in each flight."""
    from fmpy import simulate_fmu

    messages = []

    def logger(component, instance, status, category, message):
        messages.append((category.decode(), message.decode()))

    simulate_fmu(str(fmu_path("native/Penetrator")), stop_time=T_END, output_interval=0.01, debug_logging=True,
                 logger=logger, start_values={"method": 0, "rel_tol": 1e-8, "K": 1e6, "n": 1.0})
    switches = [text for cat, text in messages if cat == "logSolver"]
    assert switches, messages[:5]
    ref = soil_refs[1e6, 1.0]
    contacts = [(a[1], b[1]) for a, b in zip(ref, ref[1:] + [("end", T_END)]) if a[0] == "touchdown"]
    into = [float(s.split("t = ")[1].split(" s")[0]) for s in switches if "DOPRI5 -> Rodas5P (stiff" in s]
    back = [float(s.split("t = ")[1].split(" s")[0]) for s in switches if "Rodas5P -> DOPRI5 (no longer stiff" in s]
    assert len(into) == len(contacts) and len(back) >= len(contacts) - 1
    assert all(t0 < t < t1 for t, (t0, t1) in zip(into, contacts))
    flights = [(b[1], a[1]) for a, b in zip(ref[1:], ref) if b[0] == "liftoff"]
    assert all(t0 < t < t1 for t, (t0, t1) in zip(back, flights))
    assert all("h*rho = " in s for s in switches)


# ---- the Python-hosted FMUs' engine: the same C engine, the model's Python functions ------------
def python_run(model, method, t_end, **par):
    """A Simulator run (the Python-hosted FMUs' engine) to ``t_end``: its events [(name, time)], its
    final state and work, and the simulator."""
    from pogofmu.runtime.solver import Simulator

    sim = Simulator(model, {**par, "method": method, "rel_tol": 1e-8, "max_steps_per_second": 1e7,
                            "max_steps_per_call": 1e9}, t_stop=t_end, keep_history=True)
    sim.advance(t_end)
    return [(e.name, e.time) for e in sim.events], sim


@pytest.mark.parametrize("method", [1, 0])
@pytest.mark.parametrize("K,n", SOILS)
def test_the_python_model_is_the_native_engine_to_the_bit_on_stiff_soils(K, n, method, soil_refs, native):
    """The Python-hosted FMUs' Rodas5P takes the exact Jacobian too — the model's flow on dual
    numbers, the operations of the native FMU's generated flow_jvp — so the two runs are the same
    to the bit (every event time, the step counts, the final state) and both within 1e-8 s of scipy."""
    model = all_models()["Penetrator"]
    events, sim = python_run(model, method, T_END, K=K, n=n)
    assert max_gap([ev for ev in events if ev[0] != "max_penetration"], soil_refs[K, n]) < 1e-8
    eng = native(model)
    p = model.defaults()
    p.update(K=K, n=n)
    s = {q.name: q.default for q in SOLVER_PARAMETERS}
    s.update(method=method, rel_tol=1e-8, max_steps_per_second=1e7, max_steps_per_call=1e9)
    e, err = eng.start(model, p, s, [float(v.start) for v in model.inputs], 0.0, T_END)
    assert e is not None, err
    assert eng.lib.pg_engine_advance(e, T_END) == 0, eng.message(e)
    t, x, q, n_events = eng.served(e)
    steps, rejected, jacobians, switches, _ = eng.stats(e)
    assert jacobians > 100 and (switches > 0) == (method == 0)
    assert (sim.t_out, list(sim.x_out), sim.n_events) == (t, list(x), n_events)
    assert (sim.n_steps, sim.n_rejected) == (steps, rejected)
    assert run(native, model, method, 1e-8, T_END, K=K, n=n)[0] == events  # (stopping at events: the same)
    assert not sim.jacobian_by_differences
    # the difference Jacobian's run is another one (so the comparison above can fail)
    assert run(native, model, method, 1e-8, T_END, jvp=False, K=K, n=n)[0] != events


@pytest.mark.parametrize("method", [1, 0])
@pytest.mark.parametrize("K,n", SOILS)
def test_the_python_hosted_fmu_is_the_native_fmu_to_the_bit_on_stiff_soils(K, n, method):
    """The FMUs through fmpy (every output at every communication point) on the stiff soils: the
    Python-hosted FMU's table is the native FMU's, byte for byte, and a contact does happen."""
    import numpy as np
    from fmpy import simulate_fmu

    start = {"method": method, "rel_tol": 1e-8, "K": K, "n": n}
    py, c = (simulate_fmu(str(fmu_path(name)), stop_time=T_END, output_interval=0.01, start_values=start)
             for name in ("Penetrator", "native/Penetrator"))
    assert py.dtype.names == c.dtype.names and len(py) == len(c) > 100
    assert max(py["delta"]) > 0.0
    assert all(np.ascontiguousarray(py[k]).tobytes() == np.ascontiguousarray(c[k]).tobytes() for k in py.dtype.names)


def _columns(flow_jvp, t, x, qv, u, p):
    """The flow's Jacobian at (t, x) in the mode qv, as columns: ``flow_jvp`` (pg_model.h's function,
    the generated C's or a Simulator's callback) on unit vectors."""
    D = C.c_double
    X, Q, U, P = (D * 32)(*x), (D * 16)(*qv), (D * 1024)(*u), (D * 64)(*p)
    msg = PgMsg()
    cols = []
    for j in range(len(x)):
        sx, su, df = (D * 32)(), (D * 1024)(), (D * 32)()
        sx[j] = 1.0
        assert flow_jvp(t, *(C.addressof(a) for a in (X, Q, U, P, sx, su, df, msg))) == 0, msg.text
        cols.append(list(df[:len(x)]))
    return cols


@pytest.mark.parametrize("n", [1.0, 1.5, 2.0, 1.3])
def test_the_python_jacobian_is_the_generated_one(n, native):
    """At random points in contact (every branch of the soil's power: n = 1, 1.5, 2, and x ** n),
    loading and unloading: each column of the binding's Jacobian (the Python flow on dual numbers) is
    the generated C's to the bit but for the sign of an exact zero, and within 1e-6 (relative to the
    column's size) of central differences of the Python flow (an independent check of both).

    The sign of zero: the generated C multiplies by the seeds (a traced seed is not known to be
    zero: F * 0.0 is -0.0 for F < 0), the duals on numbers skip a zero tangent (0.0). W = I/(h
    gamma) - J and the bound of rho (|J|) do not see it, so the runs are the same to the bit
    (the test above)."""

    def bits(cols):
        return [[struct.pack("<d", v + 0.0) for v in col] for col in cols]  # (v + 0.0: -0.0 -> 0.0)
    import random

    from pogofmu.runtime.solver import Simulator
    from pogofmu.runtime.model import Params

    model = all_models()["Penetrator"]
    par = {**model.defaults(), "K": 1e6, "n": n}
    sim = Simulator(model, {**par, "method": 1}, t_stop=1.0)
    eng = native(model)
    layout = sim._layout
    pvals = [float(par[q.name]) for q in model.parameters]
    rng = random.Random(29)
    flow_of = model.bind
    for case in range(60):
        x = [1.0 + 0.3 * rng.random(), rng.uniform(-3, 3), rng.uniform(1e-6, 1e-2), rng.random(), 0.0, 0.0, 0.0]
        q = {"s": 1, "d0dot": rng.uniform(0.5, 3.0), "delta_max": 0.0, "x_lift": 0.0}
        qv = [float(q[k]) for k, _ in layout]
        u = [rng.uniform(-5.0, 5.0)]
        py = _columns(sim._struct.flow_jvp, 0.0, x, qv, u, pvals)
        c = _columns(FN["flow_jvp"](eng.model.flow_jvp), 0.0, x, qv, u, pvals)
        assert bits(py) == bits(c), case
        f = flow_of(q, tuple(u), Params(par))
        for j in range(len(x)):
            h = 1e-6 * max(abs(x[j]), 1e-3)
            xp, xm = list(x), list(x)
            xp[j] += h
            xm[j] -= h
            fd = [(a - b) / (xp[j] - xm[j]) for a, b in zip(f(0.0, xp), f(0.0, xm))]
            scale = max(1.0, max(abs(v) for v in fd))
            assert all(abs(a - b) <= 1e-6 * scale for a, b in zip(py[j], fd)), (case, j, py[j], fd)


def _with_flow(model, name, wrap):
    """The model with its flow wrapped: ``wrap(t, X, inner_flow)``."""
    import dataclasses

    bind = model.bind

    def new_bind(q, u, p):
        inner = bind(q, u, p)
        return lambda t, X: wrap(t, X, inner)
    return dataclasses.replace(model, name=name, bind=new_bind,
                               flow=lambda t, X, q, u, p: new_bind(q, u, p)(t, X))


def test_a_flow_that_does_not_run_on_dual_numbers_gets_differences_and_says_so(soil_refs, native):
    """A flow calling math.sqrt (not pogofmu.fmath) cannot take a dual number: under Rodas5P the
    engine takes central differences from its first Jacobian on — the native engine's run without
    flow_jvp, to the bit, so within 1e-8 s of scipy — and the run says so (the flag, the logSolver
    text naming the model and the exception, once)."""
    import math

    model = all_models()["Penetrator"]

    def checked(t, X, inner):
        if math.sqrt(X[0] * X[0]) < 0.0:  # (never: the standard library's sqrt, on a state)
            raise AssertionError
        return inner(t, X)

    variant = _with_flow(model, "PenetratorMath", checked)
    events, sim = python_run(variant, 1, T_END, K=1e6, n=1.0)
    assert max_gap([ev for ev in events if ev[0] != "max_penetration"], soil_refs[1e6, 1.0]) < 1e-8
    assert events == run(native, model, 1, 1e-8, T_END, jvp=False, K=1e6, n=1.0)[0]
    assert sim.jacobian_by_differences
    said = [text for text in sim.new_switches if "Jacobian" in text]
    assert len(said) == 1 and said[0].startswith("the Jacobian by central differences from t = ") \
        and "PenetratorMath's flow does not run on dual numbers (NotDifferentiable: " in said[0], said
    # the explicit method never asks for a Jacobian: nothing said
    _, explicit = python_run(variant, 5, 0.5, K=1e6, n=1.0)
    assert not explicit.jacobian_by_differences and explicit.new_switches == []


def test_a_model_error_on_dual_numbers_is_raised_not_hidden():
    """The flow ran at the point already, so an exception on dual numbers comes from the duals; a
    model error (here raised only on them) is raised as itself, as any model error of a run, not
    taken for an untraceable flow."""
    from pogofmu.runtime.dual import Dual
    from pogofmu.runtime.model import ParameterError

    def strict(t, X, inner):
        if isinstance(X[1], Dual):
            raise ParameterError("K = 1e6 violates the rule: a test's rule")
        return inner(t, X)

    variant = _with_flow(all_models()["Penetrator"], "PenetratorStrict", strict)
    with pytest.raises(ParameterError, match="a test's rule"):
        python_run(variant, 1, T_END, K=1e6, n=1.0)


@pytest.mark.parametrize("name", ["PogoStick", "PogoStickMem", "PogoStickSMA", "Penetrator"])
def test_non_stiff_defaults_keep_their_events_in_the_python_engine(name):
    """The Python-hosted FMUs' default experiments under method 0 (the default) are method 5's to the
    bit, with the same steps: the stiffness test never fires, no Jacobian is taken."""
    from pogofmu.runtime.solver import Simulator

    model = all_models()[name]
    runs = []
    for method in (0, 5):
        sim = Simulator(model, {"method": method}, t_stop=model.default_stop_time, keep_history=True)
        sim.advance(model.default_stop_time)
        runs.append(([(e.name, e.time) for e in sim.events], list(sim.x_out), sim.n_steps, sim.n_rejected,
                     sim.new_switches))
    assert len(runs[0][0]) > 5 and runs[0] == runs[1]


VDP_POW = '''"""A stiff Van der Pol oscillator, its cubic written with ** (a user's audit, 2026-12-07)."""
from pogofmu import HybridModel, Parameter, Variable

MODEL = HybridModel(
    name="VdPPow", description="stiff Van der Pol, x ** 3",
    states=(Variable("x", "1", "fast"), Variable("y", "1", "slow")),
    parameters=(Parameter("eps", 1e-7, "s", "the fast time scale"),),
    inputs=(),
    outputs=(Variable("x", "1", "fast"), Variable("y", "1", "slow")),
    flow=lambda t, x, q, u, p: [(x[0] - x[0] ** 3 / 3.0 - x[1]) / p.eps, x[0]],
    events=(),
    initial=lambda p: ([2.0, -2.0 / 3.0], {}),
    output_fn=lambda t, x, q, u, p: {"x": x[0], "y": x[1]},
    default_stop_time=1.0,
)
'''


def test_a_flow_that_overflows_at_a_wild_trial_step_is_given_smaller_steps(tmp_path):
    """A stiff Van der Pol (eps = 1e-7) written with x ** 3, exported as a user does, run by fmpy: the
    automatic method's first explicit trial steps take x far out, where Python's ** raises OverflowError
    (x * x * x would give inf, a rate that is not finite, and smaller steps). Each kind of FMU runs to 1 s
    under method 0 and 1, on scipy's Radau (rtol 1e-11) within 1e-6, the two backends the same bits on
    every row (the native pow's exponent no longer folded into x * x by the compiler: they parted by
    5e-11 under Rodas5P). Until 2026-12-07 method 0 ended at its first step, naming a state of 1e165."""
    import numpy as np
    from fmpy import simulate_fmu
    from scipy.integrate import solve_ivp

    from support import run_pogofmu

    (tmp_path / "vdp.py").write_text(VDP_POW)
    proc = run_pogofmu("export", "vdp.py", "--out", "out", "--fmi", "2", "--platforms", "x86_64-linux",
                       cwd=tmp_path, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    eps = 1e-7
    ref = solve_ivp(lambda t, z: [(z[0] - z[0] ** 3 / 3.0 - z[1]) / eps, z[0]], (0.0, 1.0), [2.0, -2.0 / 3.0],
                    method="Radau", rtol=1e-11, atol=1e-13,
                    jac=lambda t, z: [[(1.0 - z[0] ** 2) / eps, -1.0 / eps], [1.0, 0.0]]).y[:, -1]
    for method in (0, 1):
        runs = []
        for kind in ("VdPPow.fmu", "native/VdPPow.fmu"):
            res = simulate_fmu(str(tmp_path / "out" / kind), stop_time=1.0, output_interval=0.01,
                               start_values={"method": method, "rel_tol": 1e-8}, output=["x", "y"])
            runs.append(res)
            end = np.array([res["x"][-1], res["y"][-1]])
            assert res["time"][-1] == 1.0 and np.allclose(end, ref, rtol=1e-6, atol=1e-9), (kind, method, end, ref)
        assert runs[0].tobytes() == runs[1].tobytes(), f"the two backends differ (method {method})"


LAG = '''"""A stiff lag following a sine, with counters of a level 1e-4 under its peak."""
from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable, fmath

MODEL = HybridModel(
    name="Lag", description="a stiff lag of a sine, a counter near its peak",
    states=(Variable("x", "1", "lag output"),),
    parameters=(Parameter("eps", 1e-5, "s", "lag time constant"), Parameter("L", 0.999899998026, "1", "level")),
    inputs=(),
    outputs=(Variable("x", "1", "lag output"),),
    flow=lambda t, x, q, u, p: [(fmath.sin(6.283185307179586 * t) - x[0]) / p.eps],
    events=(Event("up", RISING, guard=lambda x, q, u, p: x[0] - p.L, jump=lambda x, q, u, p: (x, {**q, "nu": q["nu"] + 1})),
            Event("down", FALLING, guard=lambda x, q, u, p: x[0] - p.L,
                  jump=lambda x, q, u, p: (x, {**q, "nd": q["nd"] + 1}))),
    initial=lambda p: ([0.0], {"nu": 0, "nd": 0}),
    output_fn=lambda t, x, q, u, p: {"x": x[0]},
    default_stop_time=0.5,
)
'''


def test_an_explicit_methods_failure_on_a_stiff_problem_names_the_stiff_method(tmp_path):
    """A lag of 1e-5 s under DOPRI5 (method = 5): with too small a work budget the run ends naming the stiff
    method as the remedy, and no "parameters named above" where the model names none; at rel_tol 1e-4
    DOPRI5's dithering across a level near the peak ends in an event storm whose message names the stiff
    method too. Rodas5P (method = 1) runs the same case to its end, and its own budget error suggests
    no stiff method (it is one). Both backends, the same message (a user's audit, 2026-12-07)."""
    from support import Instance, run_pogofmu

    (tmp_path / "lag.py").write_text(LAG)
    proc = run_pogofmu("export", "lag.py", "--out", "out", "--fmi", "2", "--platforms", "x86_64-linux",
                       cwd=tmp_path, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr

    from fmpy.fmi1 import FMICallException

    def end(kind, **settings):
        """The run to 0.3 s in steps of 0.03 s: None, or the error's message."""
        inst = Instance(str(tmp_path / "out" / kind)).init(**settings)
        try:
            for k in range(10):
                try:
                    inst.fmu.doStep(currentCommunicationPoint=k * 0.03, communicationStepSize=0.03)
                except FMICallException:
                    return inst.messages[-1][2]
            return None
        finally:
            inst.close()
    for kind in ("Lag", "native/Lag"):
        budget = end(kind, method=5, max_steps_per_second=1e4)
        assert budget and "work budget exhausted" in budget and "method = 1, Rodas5P" in budget, budget
        assert "named above" not in budget, budget
        storm = end(kind, method=5, rel_tol=1e-4)
        assert storm and "event storm" in storm and "method = 1 (Rodas5P) is the stiff method" in storm, storm
        assert end(kind, method=1, rel_tol=1e-4) is None
        rodas = end(kind, method=1, rel_tol=1e-12, max_steps_per_second=2e2)
        assert rodas and "work budget exhausted" in rodas and "Rodas5P" not in rodas, rodas
