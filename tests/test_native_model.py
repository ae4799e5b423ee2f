"""The C generated from each Python model against the Python model itself.

Every generated function is called with the same inputs as its Python original — random
parameter sets (valid ones, and ones that break a rule, are zero, huge, NaN), states, discrete
states and inputs — and must give the same result to the bit: the same numbers (NaN for NaN,
the sign of zero), the same refusal text, the same arithmetic failure (division by zero, math
domain or range error, with Python's own detail text).
"""
import math

import numpy as np
import pytest

from native_model import NativeModel, python_result, same_number
from pogofmu.codegen.build import CompileError, c_compiler, model_library
from pogofmu.codegen.cmodel import discrete_layout
from pogofmu.runtime.solver import SOLVER_PARAMETERS
from pogofmu.runtime.solver.settings import check_solver_parameters, domain_slack
from pogofmu.runtime.model import Params
from pogofmu.runtime.models import all_models
from support import needs_mark


MODELS = sorted(all_models())
N_CASES = 300

pytestmark = [pytest.mark.own_fmus,  # (exports its own FMUs, or needs none)
              needs_mark(c_compiler() is not None, "a C compiler (Debian gcc, or the ziglang PyPI package of pyproject.toml)")]


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    folder = tmp_path_factory.mktemp("native_models")
    libs = {}

    def get(name):
        if name not in libs:
            try:
                libs[name] = NativeModel(model_library(name, folder))
            except CompileError as exc:
                pytest.fail(str(exc))
        return libs[name]
    return get


def _odd(rng, default):
    """A parameter value: mostly near the default, sometimes 0, negative, huge, tiny or not finite."""
    r = rng.random()
    if r < 0.6:
        return default * (1 + 0.2 * rng.standard_normal()) if default else 0.1 * rng.standard_normal()
    if r < 0.7:
        return 0.0
    if r < 0.8:
        return -abs(default or 1.0) * rng.random()
    if r < 0.9:
        return float(10.0 ** rng.uniform(-300, 300))
    return float(rng.choice([math.inf, -math.inf, math.nan, 1e308, -0.0]))


def params(rng, model, odd=0.0):
    """Random parameters; in about half the sets the initial conditions (``*_0``) and the free leg
    length keep their defaults, which agree with each other (a valid set, most of the time)."""
    keep = rng.random() < 0.5
    p = {}
    for par in model.parameters:
        if keep and (par.name.endswith("_0") or par.name == "x_i"):
            p[par.name] = par.default
            continue
        if par.integer:
            p[par.name] = int(rng.choice([par.default] * 6 + [0, 1, 2, 3, -1]))
        elif rng.random() < odd:
            p[par.name] = _odd(rng, par.default)
        else:
            p[par.name] = par.default * (1 + 0.05 * rng.standard_normal()) if par.default else 0.0
    return p


def settings(rng, odd=0.3):
    s = {}
    for par in SOLVER_PARAMETERS:
        if par.integer:
            s[par.name] = int(rng.choice([par.default] * 4 + [0, 1, 4, 8]))
        elif rng.random() < odd:
            s[par.name] = _odd(rng, par.default)
        else:
            s[par.name] = par.default
    return s


def states(rng, model, layout):
    x = [float(rng.standard_normal() * 2) for _ in model.states]
    q = {k: (int(rng.integers(0, 3)) if kind == "i" else float(rng.standard_normal() * 0.3))
         for k, kind in layout}
    if rng.random() < 0.3:  # the plateaus' anchors of the SMA at their virgin values
        q = {k: (0.0 if kind == "f" else v) for (k, kind), v in zip(layout, q.values())}
    u = [float(rng.standard_normal() * 5) for _ in model.inputs]
    return x, q, u


def assert_same(py, c, what):
    assert py[0] == c[0], f"{what}: Python {py} but C {c}"
    if py[0] == "raise" or py[0] == "arith":
        assert py[1:] == c[1:], f"{what}: Python {py[1:]} but C {c[1:]}"
        return
    a, b = py[1], c[1]
    if a is None:
        return
    if isinstance(a, (int, float)):
        a, b = [a], [b]
    assert len(a) == len(b), f"{what}: {a} vs {b}"
    for i, (u, v) in enumerate(zip(a, b)):
        assert same_number(u, v), f"{what}[{i}]: Python {u!r} but C {v!r}"


@pytest.mark.parametrize("name", MODELS)
def test_rules_and_initial_state_are_the_pythons(name, native):
    model, nat = all_models()[name], native(name)
    rng = np.random.default_rng(18)
    order = [par.name for par in model.parameters]
    raised = 0
    for case in range(N_CASES):
        p = params(rng, model, odd=0.15)
        vec = [p[n] for n in order]
        py = python_result(lambda: model.check(Params(p)))
        assert_same(py, nat.check(vec), f"{name} check {p}")
        raised += py[0] != "ok"
        py = python_result(lambda: model.initial(Params(p)))
        c = nat.initial(vec)
        if py[0] == "ok":
            x, q = py[1]
            py = ("ok", list(x) + [q[k] for k, _ in discrete_layout(model)])
            c = ("ok", c[1][0] + c[1][1]) if c[0] == "ok" else c
        assert_same(py, c, f"{name} initial {p}")
        for which in ("time_scales", "error_scales"):
            fn = getattr(model, which)
            if fn is None or py[0] != "ok":
                continue
            ps = python_result(lambda: tuple(fn(Params(p))))
            cs = nat.scales(which, vec)
            assert ps[0] == cs[0], (which, ps, cs)
            if ps[0] == "ok":
                assert [(lbl, tuple(nm)) for lbl, nm, _ in ps[1]] == [(lbl, nm) for lbl, nm, _ in cs[1]]
                for (_, _, a), (_, _, b) in zip(ps[1], cs[1]):
                    assert same_number(a, b), (which, a, b)
            else:
                assert ps == cs
    assert 0.2 * N_CASES < raised < 0.95 * N_CASES  # both outcomes were exercised


@pytest.mark.parametrize("name", MODELS)
def test_settings_rules_are_the_pythons(name, native):
    model, nat = all_models()[name], native(name)
    rng = np.random.default_rng(5)
    raised = 0
    for _ in range(N_CASES):
        s = settings(rng)
        py = python_result(lambda: check_solver_parameters(Params(s), has_states=bool(model.states)))
        assert_same(py, nat.check_settings([s[par.name] for par in SOLVER_PARAMETERS]), f"settings {s}")
        raised += py[0] != "ok"
    assert 0.2 * N_CASES < raised < 0.95 * N_CASES


@pytest.mark.parametrize("name", MODELS)
def test_flow_guards_jumps_outputs_and_domain_are_the_pythons(name, native):
    model, nat = all_models()[name], native(name)
    layout = discrete_layout(model)
    rng = np.random.default_rng(3)
    order = [par.name for par in model.parameters]
    seen = set()
    for _ in range(N_CASES):
        p = params(rng, model, odd=0.05)
        P, vec = Params(p), [p[n] for n in order]
        x, q, u = states(rng, model, layout)
        qv = list(q.values())
        t = float(rng.random() * 10)
        bind = model.bind
        py = python_result(lambda: bind(q, tuple(u), P)(t, x) if bind else model.flow(t, x, q, tuple(u), P))
        assert_same(py, nat.flow(t, x, qv, u, vec), f"{name} flow x={x} q={q} u={u}")
        seen.add(("flow", py[0]))
        for k, ev in enumerate(model.events):
            assert_same(python_result(lambda: bool(ev.active(q))), nat.active(k, qv), f"{name} active {ev.name} {q}")
            py = python_result(lambda: ev.guard(x, q, tuple(u), P))
            assert_same(py, nat.guard(k, x, qv, u, vec), f"{name} guard {ev.name} x={x} q={q}")
            py = python_result(lambda: ev.jump(x, q, tuple(u), P))
            c = nat.jump(k, x, qv, u, vec)
            if py[0] == "ok":
                xn, qn = py[1]
                py = ("ok", list(xn) + [qn[kk] for kk, _ in layout])
                c = ("ok", c[1][0] + c[1][1]) if c[0] == "ok" else c
            assert_same(py, c, f"{name} jump {ev.name} x={x} q={q}")
        py = python_result(lambda: model.output_fn(t, x, q, tuple(u), P))
        if py[0] == "ok":
            py = ("ok", [py[1][v.name] for v in model.outputs])
        assert_same(py, nat.outputs(t, x, qv, u, vec), f"{name} outputs x={x} q={q} u={u}")
        s = settings(rng, odd=0.0)
        S = Params(s)
        py = python_result(lambda: model.domain(t, x, q, tuple(u), P, domain_slack(S)))
        py = ("ok", None) if py == ("ok", None) else (("raise", py[1]) if py[0] == "ok" else py)
        c = nat.domain(t, x, qv, u, vec, [s[par.name] for par in SOLVER_PARAMETERS])
        assert_same(py, c, f"{name} domain x={x} q={q}")
        seen.add(("domain", py[0]))
    if model.states:
        assert ("domain", "raise") in seen and ("domain", "ok") in seen, seen
