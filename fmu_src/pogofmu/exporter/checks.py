"""The checks of a model before anything is built (``pogofmu export --check`` runs them alone).

Each mistake is one :class:`~.errors.ModelFileError` naming the file and the line — of the
declaration (``Variable``, ``Parameter``, ``Event`` and ``HybridModel`` remember where they were
written) or of the user's code that raised — and what to write instead.  The model's functions
are called at its default initial state: ``initial``, ``check``, ``flow``, the guards, activities
and jumps, ``output_fn`` and ``domain``.
"""
from __future__ import annotations

import math
import re
from typing import Iterable, Optional

from .errors import ModelFileError
from .source import describe_exception

NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_UNIT_CHARS = re.compile(r"[^\W]|[0-9_.*/^()+\-%°µΩ]", re.UNICODE)
_OPERATORS = set(".*/^")


def unit_problem(unit: str) -> Optional[str]:
    """None if ``unit`` is a well-formed unit name (``m``, ``N.s/m``, ``m/s2``, ``N/m^(n+1)``,
    ``1/(m.s)``, ``kg.m2``), else what is wrong with it."""
    if not isinstance(unit, str):
        return f"a unit is a string, not {type(unit).__name__}"
    if unit == "":
        return None
    bad = [c for c in unit if not _UNIT_CHARS.fullmatch(c)]
    if bad:
        return f"the character {bad[0]!r} has no place in a unit name (letters, digits and . * / ^ ( ) + - only)"
    depth = 0
    for c in unit:
        depth += {"(": 1, ")": -1}.get(c, 0)
        if depth < 0:
            return "a ')' without its '('"
    if depth:
        return "a '(' without its ')'"
    if unit[0] in _OPERATORS or unit[-1] in _OPERATORS | {"+", "-"}:
        return "a unit cannot start or end with an operator"
    for a, b in zip(unit, unit[1:]):
        if a in _OPERATORS and b in _OPERATORS:
            return f"two operators in a row ({a}{b})"
        if a == "(" and b == ")":
            return "empty parentheses"
    return None


def _at(obj, model) -> str:
    site = getattr(obj, "site", None) or getattr(model, "site", None)
    return f"{site[0]}:{site[1]}" if site else model.name


def _fn_at(fn) -> str:
    code = getattr(fn, "__code__", None)
    return f"{code.co_filename}:{code.co_firstlineno}" if code is not None else "?"


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def reserved_names(model) -> dict:
    """Names a model's own variables may not take: what every FMU of it already has."""
    from pogofmu.runtime.solver import SOLVER_PARAMETERS

    out = {p.name: "a solver setting of every pogofmu FMU" for p in SOLVER_PARAMETERS}
    out.update({v.name: "an output the engine adds to every FMU" for v in model.engine_outputs()})
    out["time"] = "the independent variable of the FMI 3.0 FMUs"
    out.update({f"guard_{ev.name}": f"the FMI 3.0 event indicator of the event {ev.name}" for ev in model.events})
    return out


def check_declarations(model) -> None:
    """Names, types, units, descriptions and cross references of a model's declarations."""
    from pogofmu.runtime.model import Event, HybridModel, Parameter, TimeEvent, Variable

    if not isinstance(model, HybridModel):
        raise ModelFileError(f"{model!r} is not a HybridModel")
    if not isinstance(model.name, str) or not NAME.match(model.name) or model.name.startswith("_pogofmu"):
        raise ModelFileError(f"{_at(model, model)}: model name {model.name!r} is not a valid FMU name: it names the "
                             f"FMU's files and C functions, so letters, digits and _ only, not starting with a digit")
    inputs, outputs = model.declared_inputs(), model.declared_outputs()
    groups = (("state", model.states, Variable), ("parameter", model.parameters, Parameter),
              ("input", inputs, Variable), ("output", outputs, Variable), ("event", model.events, Event),
              ("time event", model.time_events, TimeEvent))
    for what, items, cls in groups:
        if not isinstance(items, tuple):
            raise ModelFileError(f"{_at(model, model)}: {what}s={type(items).__name__}: HybridModel takes a tuple "
                                 f"of {cls.__name__}s (write {what}s=({cls.__name__}(...), ...))")
        for item in items:
            if not isinstance(item, cls):
                raise ModelFileError(f"{_at(model, model)}: one of the {what}s is {item!r}, not a {cls.__name__}")
    reserved = reserved_names(model)
    for what, items, _ in groups:
        for item in items:
            name = item.name
            if not isinstance(name, str) or not NAME.match(name):
                raise ModelFileError(f"{_at(item, model)}: {what} name {name!r} is not a valid name: letters, digits "
                                     f"and _ only, not starting with a digit (FMI flat names, C identifiers)")
            if name in reserved and what not in ("event", "time event"):
                raise ModelFileError(f"{_at(item, model)}: {what} {name!r} collides with {reserved[name]}: "
                                     f"choose another name")
            if what not in ("event", "time event"):
                if not isinstance(item.description, str) or not item.description.strip():
                    raise ModelFileError(f"{_at(item, model)}: {what} {name!r} has no description: every FMU "
                                         f"variable needs one (description=\"...\")")
                problem = unit_problem(item.unit)
                if problem:
                    raise ModelFileError(f"{_at(item, model)}: {what} {name!r} has the unit {item.unit!r}: {problem}")
            if what in ("state", "input", "output"):
                _check_shape(item, what, model)
    # name spaces: the FMU's variables (parameters, inputs, outputs); the states (a state may also be
    # an output of the same name, carrying its value, but not a parameter or an input); the events
    spaces = ((("parameter", model.parameters), ("input", inputs), ("output", outputs)),
              (("state", model.states), ("parameter", model.parameters), ("input", inputs)),
              (("event", model.events), ("time event", model.time_events)))
    for space in spaces:
        seen = {}
        for what, items in space:
            for item in items:
                other = seen.get(item.name)
                if other is not None:
                    raise ModelFileError(f"{_at(item, model)}: duplicate name {item.name!r}: {what} here and "
                                         f"{other[0]} at {_at(other[1], model)}")
                seen[item.name] = (what, item)
    for par in model.parameters:
        if par.integer:
            if not isinstance(par.default, int) or isinstance(par.default, bool):
                raise ModelFileError(f"{_at(par, model)}: parameter {par.name} is an integer (integer=True) but its "
                                     f"default is {par.default!r}: write an int")
        elif not _is_number(par.default):
            raise ModelFileError(f"{_at(par, model)}: parameter {par.name} = {par.default!r}: a default is a number")
    for ev in model.events:
        if ev.direction not in (-1, 1):
            raise ModelFileError(f"{_at(ev, model)}: event {ev.name} has direction {ev.direction!r}: write FALLING "
                                 f"(fires where the guard goes from > 0 to <= 0) or RISING")
        for fn, what in ((ev.guard, "guard"), (ev.jump, "jump"), (ev.active, "active")):
            if not callable(fn):
                raise ModelFileError(f"{_at(ev, model)}: event {ev.name}: {what} is {fn!r}, not a function")
    for fn, what in ((model.flow, "flow"), (model.initial, "initial"), (model.output_fn, "output_fn"),
                     (model.check, "check"), (model.domain, "domain")):
        if not callable(fn):
            raise ModelFileError(f"{_at(model, model)}: {what} is {fn!r}, not a function")
    names_in = {v.name for v in model.inputs}
    names_out = {v.name for v in model.outputs}
    for name in sorted(model.integer_outputs - names_out):
        raise ModelFileError(f"{_at(model, model)}: integer_outputs names {name!r}, which is not an output")
    for name in sorted(model.integer_inputs - names_in):
        raise ModelFileError(f"{_at(model, model)}: integer_inputs names {name!r}, which is not an input")
    for out, ins in dict(model.feedthrough).items():
        if out not in names_out:
            raise ModelFileError(f"{_at(model, model)}: feedthrough names the output {out!r}, which is not declared")
        for name in ins:
            if name not in names_in:
                raise ModelFileError(f"{_at(model, model)}: feedthrough of {out!r} names the input {name!r}, which "
                                     f"is not declared")
    for what, value in (("default_stop_time", model.default_stop_time), ("default_step", model.default_step)):
        if not _is_number(value) or not value > 0 or not math.isfinite(value):
            raise ModelFileError(f"{_at(model, model)}: {what} = {value!r}: it must be a positive finite number")
    plotted = names_in | names_out | {v.name for v in model.engine_outputs()}
    for fig in model.plots:
        for panel in fig:
            names = panel[1:3] if panel and panel[0] == "vs" else panel
            for name in names:
                if name not in plotted:
                    raise ModelFileError(f"{_at(model, model)}: plots name {name!r}, which is not an input or output")


def _check_shape(var, what, model) -> None:
    """``shape``: ``()`` (a scalar) or ``(N,)`` with an int ``N >= 1`` (a 1-D array), for inputs and
    outputs; a state is a scalar (``x`` is a flat list of floats)."""
    from pogofmu.runtime.model import array_size

    shape = var.shape
    if shape == ():
        return
    if what == "state":
        raise ModelFileError(f"{_at(var, model)}: state {var.name!r} has shape={shape!r}, which violates the rule: "
                             f"a state is a scalar (shape=()); declare one state per element")
    if array_size(var) is None:
        raise ModelFileError(f"{_at(var, model)}: {what} {var.name!r} has shape={shape!r}, which violates the rule: "
                             f"shape=() (a scalar) or shape=(N,) with an int N >= 1 (a 1-D array)")
    if not _is_number(var.start):
        raise ModelFileError(f"{_at(var, model)}: {what} {var.name!r} has start={var.start!r}, which violates the "
                             f"rule: an array's start is one number, every element's")
    if what == "output" and var.name in {s.name for s in model.states}:
        raise ModelFileError(f"{_at(var, model)}: output {var.name!r} has shape={shape!r} and is also a state, which "
                             f"violates the rule: an output of a state's name carries that (scalar) state")


def _call(files, model, what, fn, *args):
    from pogofmu.runtime.model import ModelError

    try:
        return fn(*args)
    except ModelError:
        raise
    except Exception as exc:  # noqa: BLE001 - a mistake in the user's function: one line naming its line
        raise ModelFileError(_explain(describe_exception(exc, files, _fn_at(fn)), exc, model, what)) from None


def _explain(text: str, exc: Exception, model, what: str) -> str:
    """Add what the usual mistakes mean to an exception's one line."""
    msg = str(exc)
    hint = ""
    m = re.match(r"'Params' object has no attribute '(\w+)'", msg)
    if isinstance(exc, AttributeError) and m:
        hint = f" (parameter {m.group(1)!r} is used in {what} but not declared in parameters)"
    elif isinstance(exc, IndexError) and "tuple index" in msg:
        hint = (f" (in {what}: u holds the {len(model.inputs)} declared input(s) "
                f"{', '.join(v.name for v in model.inputs) or '(none)'}; x the {len(model.states)} state(s): an input "
                f"or state used but not declared?)")
    elif isinstance(exc, IndexError):
        hint = f" (in {what}: x holds the {len(model.states)} declared state(s): a state used but not declared?)"
    elif isinstance(exc, KeyError):
        hint = f" (in {what}: a key of the discrete state q that initial does not create?)"
    return text + hint


def _rule_breaker(exc, model):
    m = re.match(r"parameter (\w+) = ", str(exc))
    if m:
        for par in model.parameters:
            if par.name == m.group(1):
                return par
    return None


def check_behaviour(model, files: Iterable) -> None:
    """Call the model's functions at its default initial state and check what they return."""
    from pogofmu.runtime.model import Event, ModelError, ParameterError

    files = list(files)
    p = model.params()
    try:
        _call(files, model, "check", model.check_parameters, p)  # the rules the engine applies
    except ParameterError as exc:
        par = _rule_breaker(exc, model)
        where = _at(par, model) if par is not None else _at(model, model)
        raise ModelFileError(f"{where}: the default breaks its own rule: {exc}") from None
    except ModelError as exc:
        raise ModelFileError(f"{_at(model, model)}: check raises at the defaults: {exc}") from None
    try:
        init = _call(files, model, "initial", model.initial, p)
    except ModelError as exc:
        par = _rule_breaker(exc, model)
        where = _at(par, model) if par is not None else _fn_at(model.initial)
        raise ModelFileError(f"{where}: initial raises at the default parameters: {type(exc).__name__}: {exc}") from None
    if not isinstance(init, (tuple, list)) or len(init) != 2:
        raise ModelFileError(f"{_fn_at(model.initial)}: initial returns {init!r}: it returns (x0, q0), the list of "
                             f"the {len(model.states)} initial states and the dict of the discrete state")
    x, q = init
    x = list(x) if isinstance(x, (list, tuple)) else x
    if not isinstance(x, list) or len(x) != len(model.states) or not all(_is_number(v) for v in x):
        raise ModelFileError(f"{_fn_at(model.initial)}: initial returns x0 = {x!r}: it must be {len(model.states)} "
                             f"number(s), one per declared state ({', '.join(v.name for v in model.states)})")
    if not isinstance(q, dict) or not all(isinstance(k, str) for k in q) or not all(_is_number(v) for v in q.values()):
        raise ModelFileError(f"{_fn_at(model.initial)}: initial returns q0 = {q!r}: the discrete state is a dict of "
                             f"numbers keyed by name ({{}} if the model has none)")
    u = tuple(float(v.start) for v in model.inputs)
    t = 0.0
    dx = _call(files, model, "flow", model.flow, t, x, q, u, p)
    try:
        n = len(dx)
    except TypeError:
        n = None
    if n != len(model.states):
        raise ModelFileError(f"{_fn_at(model.flow)}: flow returns {n if n is not None else repr(dx)} value(s) but the "
                             f"model has {len(model.states)} state(s) ({', '.join(v.name for v in model.states)}): "
                             f"it returns dx/dt, one value per state, in their order")
    bad = [i for i, v in enumerate(dx) if not _is_number(v)]
    if bad:
        raise ModelFileError(f"{_fn_at(model.flow)}: flow returns {dx[bad[0]]!r} for d{model.states[bad[0]].name}/dt: "
                             f"a rate is a float")
    for ev in model.time_events:
        for what, fn in (("at", ev.at), ("every", ev.period)):
            value = _call(files, model, f"the {what} of time event {ev.name}", fn, p)
            bad = not _is_number(value) or math.isnan(value) or value == -math.inf \
                or (what == "every" and not (math.isfinite(value) and value >= 0))
            if bad:
                rule = "a time in s (math.inf: never)" if what == "at" else "a finite period in s, > 0 (or None: once)"
                raise ModelFileError(f"{_at(ev, model)}: time event {ev.name}: {what}(p) returns {value!r}: {rule}")
    for ev in model.all_events():
        active = _call(files, model, f"the activity of event {ev.name}", ev.active, q) \
            if isinstance(ev, Event) else True
        if not isinstance(active, (bool, int)):
            raise ModelFileError(f"{_fn_at(ev.active)}: event {ev.name}: active(q) returns {active!r}: True or False")
        g = _call(files, model, f"the guard of event {ev.name}", ev.guard_t, t, x, q, u, p) \
            if isinstance(ev, Event) else 0.0
        if not _is_number(g):
            raise ModelFileError(f"{_fn_at(ev.guard)}: event {ev.name}: the guard returns {g!r} "
                                 f"({type(g).__name__}): a guard is a number whose zero crossing is the event "
                                 f"(write h, not h > 0)")
        try:
            jumped = _call(files, model, f"the jump of event {ev.name}", ev.jump_t, t, x, q, u, p)
        except ModelError:
            continue  # a jump may refuse the initial state; what it returns is checked where it runs
        if not isinstance(jumped, (tuple, list)) or len(jumped) != 2 or len(jumped[0]) != len(model.states) \
                or not isinstance(jumped[1], dict):
            raise ModelFileError(f"{_fn_at(ev.jump)}: event {ev.name}: the jump returns {jumped!r}: it returns "
                                 f"(x_new, q_new), {len(model.states)} state value(s) and the discrete state dict")
        if set(jumped[1]) != set(q):
            raise ModelFileError(f"{_fn_at(ev.jump)}: event {ev.name}: the jump returns q with the keys "
                                 f"{sorted(jumped[1])}, initial with {sorted(q)}: a jump keeps the keys of q")
    output_fn = model.declared_output_fn()
    out = _call(files, model, "output_fn", output_fn, t, x, q, u, p)
    if not isinstance(out, dict):
        raise ModelFileError(f"{_fn_at(output_fn)}: output_fn returns {type(out).__name__}: it returns a dict "
                             f"{{output name: value}}")
    outputs = model.declared_outputs()
    declared = [v.name for v in outputs]
    extra = [k for k in out if k not in declared]
    if extra:
        raise ModelFileError(f"{_fn_at(output_fn)}: output_fn returns {extra[0]!r}, which is not declared in "
                             f"outputs (declare Variable({extra[0]!r}, ...) or drop it)")
    missing = [k for k in declared if k not in out]
    if missing:
        var = next(v for v in outputs if v.name == missing[0])
        raise ModelFileError(f"{_at(var, model)}: output {missing[0]!r} is declared but output_fn does not return it")
    from pogofmu.runtime.model import array_size

    sizes = {v.name: array_size(v) for v in outputs}
    for k, v in out.items():
        n = sizes[k]
        if n is not None:
            if not isinstance(v, (list, tuple)) or len(v) != n:
                raise ModelFileError(f"{_fn_at(output_fn)}: output_fn returns {k} = {v!r}, which violates the rule: "
                                     f"{k} is an array of {n} (shape=({n},)): a list of {n} numbers")
            values = [(f"{k}[{i}]", e) for i, e in enumerate(v, start=1)]
        else:
            values = [(k, v)]
        for key, e in values:
            if not _is_number(e):
                raise ModelFileError(f"{_fn_at(output_fn)}: output_fn returns {key} = {e!r}: an output is a number")
            if key in model.integer_outputs and not (isinstance(e, int) or float(e).is_integer()):
                raise ModelFileError(f"{_fn_at(output_fn)}: output {key} is an integer output but output_fn "
                                     f"returns {e!r}")
    from pogofmu.runtime.fmi3 import check_state_outputs

    problem = check_state_outputs(model)
    if problem:
        raise ModelFileError(f"{_fn_at(output_fn)}: {problem}")
    verdict = _call(files, model, "domain", model.domain, t, x, q, u, p, lambda scale: 0.0)
    if verdict is not None and not isinstance(verdict, str):
        raise ModelFileError(f"{_fn_at(model.domain)}: domain returns {verdict!r}: None inside the domain, else the "
                             f"text of the violated condition")


def check_model(source) -> None:
    """Every check of one model (declarations, then behaviour at the defaults)."""
    check_declarations(source.model)
    check_behaviour(source.model, source.user_files())
