"""Which outputs, derivatives and event indicators of a model depend on which inputs and states,
for the FMUs' model structure (``dependencies``) and for the SSP master's update order.

* **Inputs** (direct feed-through): the model declares them (``HybridModel.feedthrough``); this
  module checks the declaration against the model's functions.
* **States** (FMI 3.0 model exchange: the derivatives, the event indicators and the outputs as
  functions of the continuous states): found by perturbing each state at states sampled along
  the model's default experiment in every discrete mode it visits, and at the initial state.

The probe evaluates the model's pure functions only (flow, guards, outputs), never an FMU.
Host-side (build) code; never imported inside an FMU.
"""
from __future__ import annotations

import math
from typing import Dict, List, Set, Tuple

from pogofmu.memo import once_per_model
from pogofmu.runtime.solver import Simulator

SAMPLES_PER_RUN = 400


class DependencyError(Exception):
    """The model's declared feed-through disagrees with its functions."""


def sample_points(model, n: int = SAMPLES_PER_RUN) -> List[Tuple[list, dict, tuple]]:
    """``(x, q, u)`` points on the model's default experiment: evenly spaced in time, the states on
    both sides of every event, and (for a model that only reacts to its inputs) the inputs of its
    ``default_input``."""
    p = model.params()
    u0 = tuple(float(v.start) for v in model.inputs)
    stop = model.default_stop_time
    inputs = (lambda t: tuple(float(model.default_input(t, p)[v.name]) for v in model.inputs)) \
        if model.default_input is not None else (lambda t: u0)
    sim = Simulator(model, p, u=inputs(0.0), keep_history=True)
    points = [(list(sim.x), dict(sim.q), sim.u)]
    for k in range(1, n + 1):
        t = stop * k / n
        u = inputs(t)
        try:
            if u != sim.u:
                sim.set_input(u)
            x, q = sim.advance(t)
        except Exception:  # noqa: BLE001 - a sample run that stops early gives the points it reached
            break
        points.append((list(x), dict(q), sim.u))
    for ev in sim.events:  # both sides of every event (the mode changes there)
        points.append((list(ev.x_after), dict(sim.q), sim.u))
    return points


def _quantities(model, t, x, q, u, p):
    """{name: value} of the outputs, derivatives and event indicators at one point."""
    out = {f"output:{k}": v for k, v in model.output_fn(t, x, q, u, p).items()}
    if model.states:
        out.update({f"der:{v.name}": d for v, d in zip(model.states, model.flow(t, x, q, u, p))})
    for ev in model.events:
        out[f"indicator:{ev.name}"] = ev.guard_t(t, x, q, u, p) if ev.active(q) else 1.0
    return out


def _differs(a, b):
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return False
    return a != b


def probe(model) -> Tuple[Dict[str, Set[str]], Dict[str, Set[str]]]:
    """``(on_states, on_inputs)``: for every quantity (``output:<name>``, ``der:<state>``,
    ``indicator:<event>``) the states and the inputs it was seen to depend on."""
    p = model.params()
    on_states: Dict[str, Set[str]] = {}
    on_inputs: Dict[str, Set[str]] = {}
    integer_inputs = model.integer_inputs
    points = sample_points(model)
    # each point also with every real input moved away from its value (a product such as
    # F_ext * ydot depends on ydot only where F_ext is not 0)
    real = [j for j, v in enumerate(model.inputs) if v.name not in integer_inputs]
    points += [(x, q, tuple(u[j] + 1.0 if j in real else u[j] for j in range(len(u)))) for x, q, u in points] \
        if real else []
    for x, q, u in points:
        try:
            base = _quantities(model, 0.0, x, q, u, p)
        except (ArithmeticError, ValueError):
            continue
        for name in base:
            on_states.setdefault(name, set())
            on_inputs.setdefault(name, set())
        for j, var in enumerate(model.states):
            xp = list(x)
            xp[j] += 1e-6 * max(1.0, abs(x[j]))
            try:
                got = _quantities(model, 0.0, xp, q, u, p)
            except (ArithmeticError, ValueError):
                continue
            for name, v in got.items():
                if _differs(v, base[name]):
                    on_states[name].add(var.name)
        for j, var in enumerate(model.inputs):
            for up in _input_moves(var, u[j], integer_inputs):
                uu = list(u)
                uu[j] = up
                try:
                    got = _quantities(model, 0.0, x, q, tuple(uu), p)
                except (ArithmeticError, ValueError):
                    continue
                for name, v in got.items():
                    if _differs(v, base[name]):
                        on_inputs[name].add(var.name)
    return on_states, on_inputs


def _input_moves(var, value, integer_inputs):
    """The values an input is moved to: a small step, and (for outputs that switch at a threshold,
    such as a phase at a velocity crossing 0) the input's opposite and zero; an integer's other value."""
    if var.name in integer_inputs:
        return [1.0 - value]
    return [value + 1e-6 * max(1.0, abs(value)), -value, 0.0 if value != 0.0 else 1.0]


def check_feedthrough(model, on_inputs) -> None:
    """The declared feed-through must be what the functions do: no undeclared input dependency of
    an output, and every declared one seen at some sample."""
    problems = []
    for var in model.outputs:
        seen = on_inputs.get(f"output:{var.name}", set())
        declared = set(model.feeds_through(var.name))
        if seen - declared:
            problems.append(f"output {var.name} depends on the input(s) {sorted(seen - declared)} "
                            f"not declared in feedthrough")
    # a declaration naming an array stands for all its elements: it holds when one of them is seen
    # (declare elements, "r[1]": ("z[1]",), for an FMI 2.0 model structure element by element)
    for out, ins in model.declared_feedthrough().items():
        for name in ins:
            pairs = [(o, i) for o in model.elements(out) for i in model.elements(name)]
            if not any(i in on_inputs.get(f"output:{o}", set()) for o, i in pairs):
                problems.append(f"output {out} is declared to depend on {[name]}, "
                                f"which never changed it at the sampled points")
    if problems:
        raise DependencyError(f"{model.name}: " + "; ".join(problems))


@once_per_model
def structure(model):
    """Everything the model structure needs: ``{"output:<name>" | "der:<state>" |
    "indicator:<event>": (states, inputs)}`` with the feed-through of the outputs as declared."""
    on_states, on_inputs = probe(model)
    check_feedthrough(model, on_inputs)
    out = {}
    for name in on_states:
        if name.startswith("output:"):
            inputs = set(model.feeds_through(name.split(":", 1)[1]))
        else:
            inputs = on_inputs[name]
        out[name] = (on_states[name], inputs)
    return out


def _initial_quantities(model, p, u):
    """{name: value} of what an FMU computes at initialization: the outputs (``output:<name>``),
    the states (``state:<name>``) and their derivatives (``der:<name>``)."""
    x, q = model.initial(p)
    out = {f"output:{k}": v for k, v in model.output_fn(0.0, x, q, u, p).items()}
    out.update({f"state:{v.name}": a for v, a in zip(model.states, x)})
    if model.states:
        out.update({f"der:{v.name}": d for v, d in zip(model.states, model.flow(0.0, x, q, u, p))})
    return out


def _valid(model, values):
    from pogofmu.runtime.model import ModelError, Params

    p = Params(values)
    try:
        model.check(p)
        model.initial(p)
    except (ModelError, ArithmeticError, ValueError):
        return None
    return p


@once_per_model
def initial_dependencies(model) -> Dict[str, Set[str]]:
    """For every initial unknown (``output:<name>``, ``state:<name>``, ``der:<name>``) the knowns it
    was seen to depend on at initialization: the model's parameters (its initial state derives from
    them) and the inputs.  Probed at the defaults and at a second valid point with every
    parameter moved (a product such as ``k * x_0`` depends on ``k`` only where ``x_0`` is not 0),
    each parameter and input moved in turn by a small step and to another value."""
    import random

    defaults = model.defaults()
    u0 = tuple(float(v.start) for v in model.inputs)
    rng = random.Random(1)
    bases = [defaults]
    moved = {k: (v + 1 if isinstance(v, int) and not isinstance(v, bool) else v * (1 + 0.1 * rng.uniform(0.5, 1.0))
                 + 0.01) for k, v in defaults.items()}
    if _valid(model, moved) is not None:
        bases.append(moved)
    deps: Dict[str, Set[str]] = {}
    for values in bases:
        p = _valid(model, values)
        if p is None:
            continue
        for u in (u0, tuple(v + 1.0 for v in u0)):
            try:
                base = _initial_quantities(model, p, u)
            except (ArithmeticError, ValueError):
                continue
            for name in base:
                deps.setdefault(name, set())

            def note(known, p_moved, u_moved):
                """Add ``known`` to every quantity that changes at the moved point."""
                if p_moved is None:
                    return
                try:
                    got = _initial_quantities(model, p_moved, u_moved)
                except (ArithmeticError, ValueError):
                    return
                for name, val in got.items():
                    if _differs(val, base.get(name)):
                        deps.setdefault(name, set()).add(known)

            for par in model.parameters:
                v = values[par.name]
                for vp in ((v + 1, v - 1) if par.integer else (v + 1e-6 * max(1.0, abs(v)), -v, 2 * v + 1.0)):
                    note(par.name, _valid(model, dict(values, **{par.name: vp})), u)
            for j, var in enumerate(model.inputs):
                for up in _input_moves(var, u[j], model.integer_inputs):
                    note(var.name, p, tuple(up if k == j else a for k, a in enumerate(u)))
    return deps
