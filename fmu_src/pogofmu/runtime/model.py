"""A hybrid dynamical system as plain data and pure functions.

Nothing here knows about FMI or the solver: the engine (:mod:`.engine`) integrates any
:class:`HybridModel`, the adapters (:mod:`.fmi2`, :mod:`.fmi3`) map any of them onto FMI.

Conventions (docs/models.md):

* continuous states ``x`` (a list of floats; ``flow`` returns a list too), a discrete state ``q`` (a ``dict`` of
  numbers: the mode ``s`` and any memory such as an SMA branch), parameters ``p`` (a read-only
  :class:`Params` with attribute access), inputs ``u`` (a tuple of floats, held over a
  communication step);
* ``flow(t, x, q, u, p) -> dx/dt``;
* every :class:`Event` has a guard ``h(x, q, u, p)`` (or ``h(t, x, q, u, p)``: a guard may read the
  time) with a direction: ``FALLING`` fires where ``h`` goes from ``> 0`` to ``<= 0``, ``RISING``
  where it goes from ``< 0`` to ``>= 0``; and a jump ``(x, q) <- jump(x, q, u, p)`` (or ``jump(t, x,
  q, u, p)``).  Events listed first win when several fire at the same instant (the documented
  priority, docs/solver.md "Event semantics");
* a :class:`TimeEvent` fires at given instants (``at(p)``, then every ``every(p)``), hit exactly by
  the steps; listed in ``events`` beside the state events, it comes after them at one instant.
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from typing import Callable, Mapping, Optional, Sequence, Tuple

from . import fmath

_HERE = os.path.dirname(os.path.abspath(__file__))
_INTERNAL = (_HERE, os.path.join(_HERE, "solver"))


def _site():
    """``(file, line)`` where a declaration was written: the first caller outside this package's
    own folder (a model file, or the helper that built the declaration), for the build's messages
    about a model (``ball.py:12: ...``)."""
    frame = sys._getframe(2)
    while frame is not None:
        name = frame.f_code.co_filename
        if not name.startswith("<") and os.path.dirname(os.path.abspath(name)) not in _INTERNAL:
            return name, frame.f_lineno
        frame = frame.f_back
    return None

FALLING = -1
RISING = 1


class ModelError(Exception):
    """Base class of the errors a model raises; the message is meant for the user."""


class ParameterError(ModelError, ValueError):
    """A parameter, start value or input breaks a rule of the model."""


class DomainError(ModelError):
    """The trajectory left the physical domain of the model."""


class ZenoError(ModelError):
    """Too many events in too short a time (an event storm)."""


@dataclass(frozen=True)
class Variable:
    """A named variable with a unit and a description (state, input or output).

    ``shape=(N,)`` (inputs and outputs) declares a 1-D array of ``N`` elements: one FMI 3.0 variable
    with ``<Dimension start="N"/>``, the ``N`` scalars ``name[1]`` ... ``name[N]`` in FMI 2.0
    (:meth:`HybridModel.__post_init__` expands it; ``start`` is every element's)."""

    name: str
    unit: str = ""
    description: str = ""
    start: float = 0.0
    shape: tuple = ()
    site: Optional[tuple] = field(default=None, compare=False, repr=False)  # (file, line) of the declaration
    # an element of an array declaration: (array name, 1-based index, number of elements)
    element: tuple = field(default=(), compare=False, repr=False)

    def __post_init__(self):
        if self.site is None:
            object.__setattr__(self, "site", _site())


def array_size(var) -> Optional[int]:
    """``N`` for a well-formed 1-D array declaration ``shape=(N,)``, ``None`` for a scalar (``shape=()``)
    and for a malformed shape (which the build's checks refuse, naming the rule)."""
    shape = getattr(var, "shape", ())
    if isinstance(shape, tuple) and len(shape) == 1 and isinstance(shape[0], int) \
            and not isinstance(shape[0], bool) and shape[0] >= 1:
        return shape[0]
    return None


def element_name(name: str, index: int) -> str:
    """The FMI 2.0 scalar of element ``index`` (1-based) of the array ``name``: ``name[index]``
    (the structured naming convention)."""
    return f"{name}[{index}]"


def _expand(variables):
    """Scalars for declarations: an array ``z`` of ``N`` becomes ``z[1]`` ... ``z[N]``, in order."""
    out = []
    for var in variables:
        n = array_size(var)
        if n is None:
            out.append(var)
            continue
        for i in range(1, n + 1):
            out.append(Variable(element_name(var.name, i), var.unit, f"{var.description} (element {i} of {n})",
                                var.start, (), var.site, (var.name, i, n)))
    return tuple(out)


def _flat_values(fn, arrays):
    """``fn`` returning ``{name: value or list}`` made to return scalars only: the list of an array
    output ``r`` becomes the entries ``r[1]`` ... ``r[N]``, in the place of ``r``."""
    def flat(*args):
        out = {}
        for name, value in fn(*args).items():
            n = arrays.get(name)
            if n is None:
                out[name] = value
            else:
                for i in range(n):
                    out[element_name(name, i + 1)] = value[i]
        return out
    return flat


@dataclass(frozen=True)
class Parameter:
    """A fixed parameter with its default, unit, description and (optionally) type."""

    name: str
    default: float
    unit: str = ""
    description: str = ""
    integer: bool = False
    site: Optional[tuple] = field(default=None, compare=False, repr=False)  # (file, line) of the declaration

    def __post_init__(self):
        if self.site is None:
            object.__setattr__(self, "site", _site())


def reads_time(fn) -> bool:
    """A guard or jump written ``(t, x, q, u, p)`` (five required positional parameters) reads the
    time; one written ``(x, q, u, p)`` does not (the signature of every model before time could be
    read, which keeps working unchanged)."""
    code = getattr(fn, "__code__", None)
    if code is not None and not hasattr(fn, "__self__"):  # a plain function or lambda: no inspect import
        return code.co_argcount - len(getattr(fn, "__defaults__", None) or ()) == 5
    import inspect

    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return False
    kinds = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return sum(1 for a in params if a.kind in kinds and a.default is inspect.Parameter.empty) == 5


def with_time(fn):
    """``fn`` as ``(t, x, q, u, p) -> ...`` whichever of the two signatures it was written with."""
    if fn is None or reads_time(fn):
        return fn
    return lambda t, x, q, u, p: fn(x, q, u, p)


@dataclass(frozen=True)
class Event:
    """One guard with its direction, the modes it is active in and its jump map.

    ``guard`` and ``jump`` take ``(x, q, u, p)`` or, to read the time, ``(t, x, q, u, p)``;
    ``guard_t`` and ``jump_t`` are both as ``(t, x, q, u, p)``, whichever was written."""

    name: str
    direction: int
    guard: Callable  # (x, q, u, p) or (t, x, q, u, p) -> float
    jump: Callable  # (x, q, u, p) or (t, x, q, u, p) -> (x_new, q_new)
    active: Callable = lambda q: True  # (q) -> bool
    site: Optional[tuple] = field(default=None, compare=False, repr=False)  # (file, line) of the declaration
    guard_t: Optional[Callable] = field(default=None, compare=False, repr=False)
    jump_t: Optional[Callable] = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if self.site is None:
            object.__setattr__(self, "site", _site())
        object.__setattr__(self, "guard_t", with_time(self.guard))
        object.__setattr__(self, "jump_t", with_time(self.jump))


@dataclass(frozen=True)
class TimeEvent:
    """An event at given instants: ``at(p)`` the first, then every ``every(p)`` seconds (``every``
    omitted, or returning 0: once). The steps land on each instant exactly, with no root finding;
    ``jump`` as an :class:`Event`'s, ``(x, q, u, p)`` or ``(t, x, q, u, p)``. At one instant the
    state events come first, then the time events in their order (docs/solver.md)."""

    name: str
    at: Callable  # p -> float
    jump: Callable  # (x, q, u, p) or (t, x, q, u, p) -> (x_new, q_new)
    every: Optional[Callable] = None  # p -> float (> 0), or None: once
    site: Optional[tuple] = field(default=None, compare=False, repr=False)
    jump_t: Optional[Callable] = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if self.site is None:
            object.__setattr__(self, "site", _site())
        object.__setattr__(self, "jump_t", with_time(self.jump))

    def period(self, p) -> float:
        """``every(p)``, 0.0 for a single instant."""
        return 0.0 if self.every is None else self.every(p)


class Params:
    """Read-only parameter record: attribute access (``p.m``, as fast as a plain attribute) and
    mapping access (``p["m"]``)."""

    def __init__(self, values: Mapping[str, float]):
        self.__dict__.update(values)

    def __setattr__(self, name, value):
        raise AttributeError("Params is read-only")

    def __getitem__(self, name):
        return self.__dict__[name]

    def as_dict(self):
        return dict(self.__dict__)

    def __repr__(self):
        return f"Params({self.__dict__!r})"


@dataclass(frozen=True)
class HybridModel:
    """Everything the engine and the FMI adapter need to know about one model variant.

    ``initial(p) -> (x0, q0)`` derives the initial state from the parameters (it may raise
    :class:`ParameterError`); ``check(p)`` validates the parameters; ``domain(t, x, q, u, p,
    slack)`` returns ``None`` or the text of the violated domain condition, where
    ``slack(scale)`` (given by the engine) is how far the integration error alone may carry a
    state of magnitude ``scale`` beyond a bound;
    ``output_fn(t, x, q, u, p)`` returns a dict of the model's output values (the engine adds
    ``n_events``, ``t_last_event`` and ``last_event``, see :meth:`engine_outputs`);
    ``integer_outputs`` / ``integer_inputs`` name the outputs / inputs that are integers (modes,
    branches; an FMI Integer connects only to an Integer);
    ``bind(q, u, p) -> f(t, x)`` (optional) returns the flow for fixed ``(q, u, p)``, equal to
    ``flow(t, x, q, u, p)`` but free to hoist lookups out of the hot loop;
    ``plots`` lists the figures the master script draws: each a tuple of panels, a panel being a
    tuple of output (or input) names against time, or a loop ``("vs", x, y)``; a loop may name a
    rate and two labels, ``("vs", x, y, rate, label_rate_positive, label_rate_negative)``, to be
    drawn in two colours by the sign of ``rate`` (e.g. loading and unloading);
    ``default_input(t, p) -> {input name: value}`` (optional) gives the inputs of the master
    script's default experiment at time ``t`` (a model that only reacts to its inputs, such as a
    controller, shows nothing with constant inputs);
    ``feedthrough`` maps an output to the inputs it depends on *directly* (within one evaluation,
    not through the states): an output not named depends on the states, the discrete state and
    the parameters only — the FMUs declare it in their model structure, and a master derives its
    update order and finds algebraic loops from it (tests perturb each input to check it);
    ``time_scales(p)`` (optional) lists the model's physical time scales as
    ``(label, parameter names, seconds)``: the engine refuses parameters that make one faster than
    it can resolve and names the fastest ones when the model turns out stiff; ``error_scales(p)``
    (optional) lists the smallest magnitudes of the motion the error control must resolve
    (e.g. a static deflection), in the same form: ``abs_tol`` must be well below them.
    """

    name: str
    description: str
    states: Tuple[Variable, ...]
    parameters: Tuple[Parameter, ...]
    inputs: Tuple[Variable, ...]
    outputs: Tuple[Variable, ...]
    flow: Callable
    events: Tuple[Event, ...]
    initial: Callable
    output_fn: Callable
    check: Callable = lambda p: None
    domain: Callable = lambda t, x, q, u, p, slack: None
    integer_outputs: frozenset = frozenset()
    integer_inputs: frozenset = frozenset()
    bind: Optional[Callable] = None
    plots: tuple = ()
    default_input: Optional[Callable] = None
    feedthrough: Mapping[str, Tuple[str, ...]] = field(default_factory=dict)
    default_stop_time: float = 10.0
    default_step: float = 1e-3
    time_scales: Optional[Callable] = None  # p -> ((label, parameter names, seconds), ...)
    error_scales: Optional[Callable] = None  # p -> ((label, parameter names, magnitude), ...)
    site: Optional[tuple] = field(default=None, compare=False, repr=False)  # (file, line) of the declaration
    # what the model file declared, where it has arrays (see _expand_arrays): a dict with the keys
    # inputs, outputs, output_fn, default_input, feedthrough, sizes; None for a model of scalars only
    declared: Optional[dict] = field(default=None, compare=False, repr=False)
    # the TimeEvents listed in ``events``, taken out of it (``events`` keeps the state events)
    time_events: Tuple[TimeEvent, ...] = ()

    def __post_init__(self):
        if self.site is None:
            object.__setattr__(self, "site", _site())
        if isinstance(self.events, (tuple, list)) and any(isinstance(ev, TimeEvent) for ev in self.events):
            object.__setattr__(self, "time_events",
                               tuple(self.time_events) + tuple(ev for ev in self.events if isinstance(ev, TimeEvent)))
            object.__setattr__(self, "events", tuple(ev for ev in self.events if not isinstance(ev, TimeEvent)))
        # (inputs or outputs that are not tuples are left to the build's checks, which name the rule)
        if self.declared is None and isinstance(self.inputs, tuple) and isinstance(self.outputs, tuple) \
                and any(array_size(v) for v in self.inputs + self.outputs):
            self._expand_arrays()

    def _expand_arrays(self):
        """Array inputs and outputs (``shape=(N,)``) as their scalar elements, so that everything
        downstream (engine, FMI 2.0, generated C, model structure) sees scalars: ``inputs`` and
        ``outputs`` list the elements ``z[1]`` ... ``z[N]`` in the place of ``z`` (``u`` holds them
        in consecutive slots); ``output_fn`` and ``default_input`` return the elements in the place
        of a list; a name of an array in ``feedthrough`` and the integer sets stands for all its
        elements.  The declarations are kept in ``declared`` (the FMI 3.0 description groups the
        elements back into one array variable)."""
        arrays_in = {v.name: array_size(v) for v in self.inputs if array_size(v)}
        arrays_out = {v.name: array_size(v) for v in self.outputs if array_size(v)}
        declared = {"inputs": self.inputs, "outputs": self.outputs, "output_fn": self.output_fn,
                    "default_input": self.default_input, "feedthrough": dict(self.feedthrough),
                    "sizes": dict(arrays_in, **arrays_out)}
        object.__setattr__(self, "declared", declared)
        names = self.elements

        feedthrough = {}
        for out, ins in self.feedthrough.items():
            flat_in = tuple(e for name in ins for e in names(name))
            for o in names(out):
                feedthrough[o] = tuple(dict.fromkeys(feedthrough.get(o, ()) + flat_in))
        changes = {"inputs": _expand(self.inputs), "outputs": _expand(self.outputs),
                   "feedthrough": feedthrough,
                   "integer_inputs": frozenset(e for n in self.integer_inputs for e in names(n)),
                   "integer_outputs": frozenset(e for n in self.integer_outputs for e in names(n))}
        if arrays_out:
            changes["output_fn"] = _flat_values(self.output_fn, arrays_out)
        if arrays_in and self.default_input is not None:
            changes["default_input"] = _flat_values(self.default_input, arrays_in)
        for key, value in changes.items():
            object.__setattr__(self, key, value)

    def elements(self, name: str) -> list:
        """The scalars of a declared input or output: ``[name]``, or an array's ``name[1]`` ... ``name[N]``."""
        n = self.declared["sizes"].get(name) if self.declared else None
        return [name] if n is None else [element_name(name, i) for i in range(1, n + 1)]

    def declared_feedthrough(self) -> Mapping[str, Tuple[str, ...]]:
        """``feedthrough`` as declared: an array's name stands for all its elements."""
        return self.declared["feedthrough"] if self.declared else self.feedthrough

    def declared_inputs(self) -> Tuple[Variable, ...]:
        """The inputs as the model file declared them (an array as one :class:`Variable`)."""
        return self.declared["inputs"] if self.declared else self.inputs

    def declared_outputs(self) -> Tuple[Variable, ...]:
        return self.declared["outputs"] if self.declared else self.outputs

    def declared_output_fn(self) -> Callable:
        return self.declared["output_fn"] if self.declared else self.output_fn

    def check_parameters(self, p: "Params") -> None:
        """The rules of the parameters: each is a finite number (the rule every model has), then the
        model's own ``check``.  Raises :class:`ParameterError` naming the parameter, its value and the rule."""
        require_finite(p, [par.name for par in self.parameters])
        self.check(p)

    def engine_outputs(self) -> Tuple[Variable, ...]:
        """Outputs every model has, kept by the engine: event counter, time and kind of the latest."""
        codes = ", ".join(f"{i} {ev.name}" for i, ev in enumerate(self.all_events(), start=1))
        what = "state event" if not self.time_events else "event (state or time)"
        return (
            Variable("n_events", "", f"number of {what}s handled so far"),
            Variable("t_last_event", "s", f"time of the latest {what} (the start time before the first)"),
            Variable("last_event", "", f"kind of the latest {what}: 0 none, {codes}"),
        )

    def all_events(self) -> tuple:
        """The state events, then the time events: the engine's event indices."""
        return tuple(self.events) + tuple(self.time_events)

    def feeds_through(self, output: str) -> Tuple[str, ...]:
        """The inputs ``output`` depends on directly (empty for the engine's own outputs)."""
        return tuple(self.feedthrough.get(output, ()))

    def all_outputs(self) -> Tuple[Variable, ...]:
        return self.outputs + self.engine_outputs()

    def all_integer_outputs(self) -> frozenset:
        return self.integer_outputs | {"n_events", "last_event"}

    def defaults(self) -> dict:
        return {par.name: par.default for par in self.parameters}

    def params(self, **overrides) -> Params:
        values = self.defaults()
        unknown = set(overrides) - set(values)
        if unknown:
            raise ParameterError(f"unknown parameter(s) {sorted(unknown)} for model {self.name}")
        values.update(overrides)
        return Params(values)

    def state_index(self, name: str) -> int:
        for i, v in enumerate(self.states):
            if v.name == name:
                return i
        raise KeyError(name)


# ---------------------------------------------------------------------------------------------
# parameter rules: each raises ParameterError naming the parameter, its value and the rule
# ---------------------------------------------------------------------------------------------

def require(condition: bool, name: str, value, rule: str):
    if not condition:
        raise ParameterError(f"parameter {name} = {value!r} violates the rule: {rule}")


def require_finite(p: Params, names: Optional[Sequence[str]] = None):
    for name in names if names is not None else p.as_dict():
        v = p[name]
        if not fmath.isfinite(v):
            raise ParameterError(f"parameter {name} = {v!r} violates the rule: {name} must be a finite number")


def require_positive(p: Params, *names: str):
    for name in names:
        require(p[name] > 0, name, p[name], f"{name} > 0")


def require_nonnegative(p: Params, *names: str):
    for name in names:
        require(p[name] >= 0, name, p[name], f"{name} >= 0")
