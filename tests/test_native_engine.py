"""The two backends' models on the one engine (fmu_src/native/engine, C): the generated C of a
model against its Python functions called back through the binding (runtime/solver/cengine.py).

Both integrate the same model — the C generated from the Python model — from the same parameters,
settings and inputs, and are compared at every communication point *to the bit*: the served time,
states and discrete state, the event count and the latest event. Far stronger than the issue's
1e-12 s: the two do the same floating-point operations in the same order. Cases: every model's
default experiment with both Runge-Kutta pairs and both ways of stepping (to the end of each
step; FMI 3.0 early return at each event); the property suite's valid parameter sets with
switching thrust (tests/test_properties.py strategies: hidden crossings, restarts at input
changes); and sets that break a rule or leave the domain, which must end with the same message.
"""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from native_engine import NativeEngine, both_runs
from pogofmu.codegen.build import CompileError, c_compiler, engine_library
from pogofmu.runtime.solver import SOLVER_PARAMETERS
from pogofmu.runtime.models import all_models
from parameter_sets import THRUST, penetrator_params, stick_params
from support import needs_mark


MODELS = sorted(all_models())
SAME = settings(max_examples=25, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.function_scoped_fixture])

pytestmark = [pytest.mark.own_fmus,  # (exports its own FMUs, or needs none)
              needs_mark(c_compiler() is not None, "a C compiler (Debian gcc, or the ziglang PyPI package of pyproject.toml)")]


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    folder = tmp_path_factory.mktemp("native_engines")
    engines = {}

    def get(model):
        """The native engine of a model (itself, or one of the project's by name)."""
        name = model if isinstance(model, str) else model.name
        if name not in engines:
            try:
                engines[name] = NativeEngine(engine_library(model, folder))
            except CompileError as exc:
                pytest.fail(str(exc))
        return engines[name]
    return get


def split(model, values):
    p = model.defaults()
    s = {par.name: par.default for par in SOLVER_PARAMETERS}
    for k, v in values.items():
        (s if k in s else p)[k] = v
    return p, s


def grid(model, stop=None, step=None):
    stop, step = stop or model.default_stop_time, step or model.default_step
    return [k * step for k in range(1, int(round(stop / step)) + 1)]


def demo_inputs(model, steps):
    if model.default_input is None:
        return None
    p = model.params()
    return [[model.default_input(t - model.default_step, p)[v.name] for v in model.inputs] for t in steps]


@pytest.mark.parametrize("method", [5, 8, 1, 0])  # 1: Rodas5P throughout, its Jacobian exact on both sides
@pytest.mark.parametrize("early", [False, True])
@pytest.mark.parametrize("name", MODELS)
def test_default_experiments_are_the_python_engines_to_the_bit(name, method, early, native):
    model = all_models()[name]
    p, s = split(model, {"method": method})
    steps = grid(model)
    diffs = both_runs(native(name), model, p, s, steps, demo_inputs(model, steps),
                      t_stop=model.default_stop_time, early=early)
    assert diffs == []


def _stick_case(name, p, thrust):
    p = dict(p)
    p.pop("_scale")
    inputs = [[f * p["m"] * p["g"]] for f in thrust] if thrust else None
    return p, inputs


@pytest.mark.parametrize("name", ["PogoStick", "PogoStickMem", "PogoStickSMA"])
def test_property_sets_with_switching_thrust_are_the_python_engines(name, native):
    model = all_models()[name]

    @SAME
    @given(p=stick_params(name), thrust=THRUST, early=st.booleans())
    def check(p, thrust, early):
        values, inputs = _stick_case(name, p, thrust)
        p_, s_ = split(model, values)
        assert both_runs(native(name), model, p_, s_, [k * 0.01 for k in range(1, 201)], inputs,
                         early=early) == []
    check()


def test_penetrator_property_sets_are_the_python_engines(native):
    model = all_models()["Penetrator"]

    @SAME
    @given(p=penetrator_params(), thrust=THRUST, early=st.booleans())
    def check(p, thrust, early):
        values, inputs = _stick_case("Penetrator", p, thrust)
        p_, s_ = split(model, values)
        assert both_runs(native("Penetrator"), model, p_, s_, [k * 0.01 for k in range(1, 201)], inputs,
                         early=early) == []
    check()


@pytest.mark.parametrize("name", MODELS)
def test_refusals_and_failures_give_the_python_engines_messages(name, native):
    """Random parameter sets of every magnitude and sign (most are refused at the start, some
    leave the domain, exhaust the work budget or collapse the step): the same outcome, the same
    text, at the same time."""
    model = all_models()[name]
    rng = np.random.default_rng(20)
    outcomes = set()
    for case in range(60):
        kind = case % 3  # 0: near the defaults, 1: every magnitude and sign, 2: a soft leg or soil
        values = {}
        for par in model.parameters:
            r = rng.random()
            if par.integer:
                values[par.name] = int(rng.choice([par.default, par.default, 0, 1, 2, -1])) if kind == 1 \
                    else par.default
            elif kind != 1:
                values[par.name] = par.default * float(10.0 ** rng.uniform(-0.2, 0.2)) if r < 0.3 else par.default
            elif r < 0.5:
                values[par.name] = par.default
            elif r < 0.9:
                values[par.name] = par.default * float(10.0 ** rng.uniform(-3, 3)) if par.default else \
                    float(rng.uniform(-1, 1))
            else:
                values[par.name] = float(rng.choice([0.0, -1.0, math.inf, math.nan, 1e300]))
        if kind == 1 and rng.random() < 0.3:
            values["max_steps_per_second"] = 50.0
            values["max_step"] = 0.0
        if kind == 2:
            for stiff in ("k", "k1", "K"):
                if stiff in values:
                    values[stiff] = 1e-3 * model.defaults()[stiff]
        p, s = split(model, values)
        if "y_0" in p and "xbar_0" in p and (kind != 1 or rng.random() < 0.7):  # a consistent start
            p["xbar_0"] = p["x_i"] if p["y_0"] > p["x_i"] else p["y_0"]
            p["z_0"] = p["y_0"] - p["xbar_0"]
        steps = [k * 0.05 for k in range(1, 41)]
        u = [[float(rng.uniform(-30, 30)) for _ in model.inputs] for _ in range(5)] if model.inputs else None
        diffs = both_runs(native(name), model, p, s, steps, u, outcome=outcomes)
        assert diffs == [], (values, diffs)
    # refused at the start, and run to the end (and for a model with states, stopped on the way)
    assert {"init", "ok"} <= outcomes and (not model.states or "advance" in outcomes), outcomes


def _ball(jump_keeps_h):
    """The example ball (a user's model file); its bounce leaves h at 0, or (the variant) as it is."""
    from pogofmu.exporter import load_model_file
    from pogofmu.runtime.model import Event
    import dataclasses

    from support import EXAMPLES

    model = load_model_file(EXAMPLES / "ball" / "ball.py")[0].model
    if not jump_keeps_h:
        return model
    bounce = model.events[0]
    kept = dataclasses.replace(bounce, jump=lambda x, q, u, p: ([x[0], -p.e * x[1]], q))
    return dataclasses.replace(model, name="BallKeepsH", events=(kept,))


@pytest.mark.parametrize("case", ["storm of events", "storm within the rounding", "work budget"])
def test_the_storm_and_the_budget_end_alike_in_both_engines(native, case):
    """Each end the engines promise (docs/errors.md), required, not only allowed: the same message at
    the same point in both engines — a ball at its accumulation point (200 events in 1e-6 s, or a
    bounce back past zero within its own rounding) and a work budget run out."""
    from pogofmu.runtime.solver import Simulator
    from pogofmu.runtime.model import ModelError

    model, values, stop, words = {
        "storm of events": (_ball(False), {}, 5.0, "event storm: 200 events (bounce)"),
        "storm within the rounding": (_ball(True), {}, 5.0, "event storm: bounce happens again within the rounding"),
        "work budget": (all_models()["PogoStick"], {"c": 1e4, "max_steps_per_second": 1000.0, "method": 5}, 1.0,
                        "work budget exhausted"),
    }[case]
    p, s = split(model, values)
    steps = [k * 0.01 for k in range(1, int(round(stop / 0.01)) + 1)]
    outcome = set()
    assert both_runs(native(model), model, p, s, steps, outcome=outcome) == []
    assert outcome == {"advance"}, outcome
    sim = Simulator(model, {**p, **s})
    with pytest.raises(ModelError) as exc:
        for t in steps:
            sim.advance(t)
    assert words in str(exc.value), exc.value


def test_the_pairs_c_file_is_what_the_generator_writes():
    """fmu_src/native/engine/pg_pairs.c is generated from the tableaux (pogofmu.codegen.cpairs) and
    kept in the repository, so that the engine compiles from its C files alone: regenerating it
    gives the same text (an edited tableau without a regenerated file fails here)."""
    from pogofmu.codegen.build import ENGINE
    from pogofmu.codegen.cpairs import generate

    assert (ENGINE / "pg_pairs.c").read_text() == generate(), \
        "regenerate it: python -m pogofmu.codegen.cpairs > fmu_src/native/engine/pg_pairs.c"


def _engine_program(tmp_path, main, defines):
    """A C program ``main`` built with the PogoStick's generated C and the engine's files, with the
    ``-D`` ``defines`` (a native FMU's sizes header gives them: cmodel.specialization)."""
    from pogofmu.codegen.build import ENGINE, ENGINE_SOURCES, compile_c, write_model_source
    from pogofmu.runtime.models import get

    sources = [write_model_source(get("PogoStick"), tmp_path), *(ENGINE / s for s in ENGINE_SOURCES), main]
    return compile_c(sources, tmp_path / main.stem, shared=False, include=[ENGINE],
                     defines=[f"{k}={v}" for k, v in defines.items()])


def _engine_loop(tmp_path, counts):
    """benchmarks/c/engine_loop.c built with the constant counts ``counts``, run over 1 s at 1 ms."""
    import subprocess
    from pathlib import Path

    from pogofmu.runtime.models import get

    model = get("PogoStick")
    exe = _engine_program(tmp_path, Path(__file__).resolve().parent.parent / "benchmarks" / "c" / "engine_loop.c",
                          counts)
    p = model.defaults()
    s = [par.default for par in SOLVER_PARAMETERS]
    args = [str(len(p)), *(repr(float(v)) for v in p.values()), str(len(s)), *(repr(float(v)) for v in s)]
    return subprocess.run([str(exe), "1.0", "0.001", *args], capture_output=True, text=True)


def test_an_engine_built_for_other_counts_refuses_the_model(tmp_path):
    """A native FMU's engine is built for its model's exact counts (PG_NX, PG_NQ, PG_NY): with other
    counts its loops would run over the wrong number of values, so it refuses the model, naming both."""
    from pogofmu.codegen.cmodel import exact_counts
    from pogofmu.runtime.models import get

    counts = exact_counts(get("PogoStick"))
    assert counts == {"PG_NX": 7, "PG_NQ": 1, "PG_NY": 11}
    right = _engine_loop(tmp_path / "right", counts)
    assert right.returncode == 0, right.stderr
    wrong = _engine_loop(tmp_path / "wrong", dict(counts, PG_NX=6))
    assert wrong.returncode == 1
    assert "the model has 7 states, 1 discrete state entries and 11 outputs; this engine was built for exactly 6, " \
           "1 and 11 (PG_NX, PG_NQ, PG_NY)" in wrong.stderr, wrong.stderr


ONE_MODEL_PROBE = r"""
#include <stdio.h>
#include <stdlib.h>
#include "pg_engine.h"
extern const PgModel PG_MODEL;
int main(void)
{
    double p[PG_MAX_P] = {0}, s[PG_NS] = {0}, u[PG_MAX_U] = {0};
    PgModel copy = PG_MODEL; /* the same functions and counts, another model to the engine */
    copy.name = "Copy";
    PgEngine *e = malloc(pg_engine_sizeof());
    int rc = pg_engine_init(e, &copy, p, s, u, 0.0, 1.0);
    printf("%d %s\n", rc, pg_engine_message(e));
    return 0;
}
"""


def test_an_engine_built_for_one_model_refuses_another(tmp_path):
    """A native FMU's engine calls its one model's functions by name (PG_ONE_MODEL, its pg_sizes.h):
    given any other model it would run that one's counts with this one's functions, so it refuses it,
    naming both, before anything else is read."""
    import subprocess

    from pogofmu.codegen.cmodel import ONE_MODEL, sizes_header, specialization
    from pogofmu.runtime.models import get

    model = get("PogoStick")
    assert f"#define PG_ONE_MODEL {ONE_MODEL}" in sizes_header(model)
    probe = tmp_path / "probe.c"
    probe.write_text(ONE_MODEL_PROBE)
    exe = _engine_program(tmp_path, probe, specialization(model))
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "1 the model Copy is not the one this engine was built for (PogoStick, PG_ONE_MODEL)", out
