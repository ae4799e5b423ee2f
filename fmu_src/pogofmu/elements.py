"""Restoring-force elements of a leg, composed in parallel.

A leg element is plain data plus pure functions, like a model (it knows nothing of FMI):

* ``parameters``: its :class:`~pogofmu.model.Parameter` s (names unique within a leg);
* ``states``: its own continuous states (e.g. the absement ``a`` of a mem-spring), with
  ``initial_states(p)`` and ``rates(x, xdot, xi, q, p)``;
* ``discrete``: its own entries of the discrete state ``q`` (e.g. an SMA branch and anchor);
* ``force(x, xdot, xi, q, p)``: its contribution to the leg's restoring force ``r``
  (``x = xbar - x_i`` the deflection, ``xdot`` its rate, ``xi`` the element's own states);
* ``events``: its own :class:`LegEvent` s, active in contact only;
* ``check(p)``: its parameter rules (raise :class:`~pogofmu.model.ParameterError`).

A leg is a tuple of elements; :func:`pogofmu.models.stick.make_stick_model` sums the forces,
stacks the states and collects the events and checks: adding an element is adding a class here.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Tuple

from .model import Parameter, Params, Variable, require_nonnegative


@dataclass(frozen=True)
class LegEvent:
    """An element's own event; guard and jump see the leg's quantities.

    ``guard(x, xdot, xi, q, p) -> float``; ``jump(x, xdot, xi, q, p) -> (xi_new, q_new)``;
    ``active(q) -> bool`` (in addition to being in contact).
    """

    name: str
    direction: int
    guard: Callable
    jump: Callable
    active: Callable = lambda q: True


class Element:
    """Base class: no parameters, no states, no force."""

    parameters: Tuple[Parameter, ...] = ()
    states: Tuple[Variable, ...] = ()
    discrete: dict = {}
    events: Tuple[LegEvent, ...] = ()
    outputs: Tuple[Variable, ...] = ()

    def initial_states(self, p: Params):
        return ()

    def rates(self, x, xdot, xi, q, p):
        return ()

    def force(self, x, xdot, xi, q, p):
        return 0.0

    def output_values(self, x, xdot, xi, q, p):
        """Values of the element's own outputs (same order as ``outputs``)."""
        return ()

    def liftoff_allowed(self, q) -> bool:
        """May the foot leave the ground in this discrete state (e.g. only on the virgin line)?"""
        return True

    def check(self, p: Params):
        pass


class LinearSpring(Element):
    """``r = k x`` (the paper's capacitor analogue)."""

    parameters = (Parameter("k", 100.0, "N/m", "stiffness of the leg spring"),)

    def force(self, x, xdot, xi, q, p):
        return p.k * x

    def check(self, p):
        require_nonnegative(p, "k")


class LinearDashpot(Element):
    """``r = c xdot`` (the paper's resistor analogue)."""

    parameters = (Parameter("c", 0.5, "N.s/m", "damping coefficient of the leg dashpot"),)

    def force(self, x, xdot, xi, q, p):
        return p.c * xdot

    def check(self, p):
        require_nonnegative(p, "c")
