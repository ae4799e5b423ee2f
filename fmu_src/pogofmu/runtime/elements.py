"""Restoring-force elements of a leg, composed in parallel.

A leg element is plain data plus pure functions, like a model (it knows nothing of FMI):

* ``parameters``: its :class:`~pogofmu.runtime.model.Parameter` s (names unique within a leg);
* ``states``: its own continuous states (e.g. the absement ``a`` of a mem-spring), with
  ``initial_states(p)`` and ``rates(x, xdot, xi, q, p)``;
* ``discrete``: its own entries of the discrete state ``q`` (e.g. an SMA branch and anchor);
* ``force(x, xdot, xi, q, p)``: its contribution to the leg's restoring force ``r``
  (``x = xbar - x_i`` the deflection, ``xdot`` its rate, ``xi`` the element's own states);
* ``events``: its own :class:`LegEvent` s, active in contact only;
* ``check(p)``: its parameter rules (raise :class:`~pogofmu.runtime.model.ParameterError`).

A leg is a tuple of elements; :func:`pogofmu.runtime.models.stick.make_stick_model` sums the forces,
stacks the states and collects the events and checks: adding an element is adding a class here.

This module is also the public ``pogofmu.elements`` of a user's model file: the elements, the
soil law (:class:`HuntCrossley`, from :mod:`.soil`) and the parameter rules, which a model calls
in its own flow, guards and checks (docs/writing-models.md).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Tuple

from .plant import DAMPING, STIFFNESS
from .model import FALLING, RISING, Parameter, Params, Variable, require, require_nonnegative
from .soil import HuntCrossley, positive_power

__all__ = ["Element", "LegEvent", "LinearSpring", "LinearDashpot", "MemSpring", "MemDashpot", "SMAFlag",
           "SPRING_LAWS", "HuntCrossley", "positive_power"]


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

    def time_scales(self, p: Params):
        """Physical time scales of the element on the stick's mass ``m``: ``(label, names, s)``."""
        return ()

    def error_scales(self, p: Params):
        """Smallest magnitudes of the element's motion the error control must resolve."""
        return ()

    def liftoff_allowed(self, q) -> bool:
        """May the foot leave the ground in this discrete state (e.g. only on the virgin line)?"""
        return True

    def check(self, p: Params):
        pass


def _spring_time_scale(p, k):
    """``sqrt(m/k)``: the leg spring's oscillation time scale (1/omega) on the mass."""
    if p[k] > 0:
        return ((f"sqrt(m/{k}) (leg spring)", ("m", k), (p.m / p[k]) ** 0.5),)
    return ()


def _static_deflection(p, k):
    """``m g/k``: the spring's static deflection under the mass."""
    if p[k] > 0 and p.g > 0:
        return ((f"m g/{k} (static leg deflection)", ("m", "g", k), p.m * p.g / p[k]),)
    return ()


def _dashpot_time_scale(p):
    """``m/c``: the dashpot's relaxation time on the mass."""
    if p.c > 0:
        return (("m/c (leg dashpot)", ("m", "c"), p.m / p.c),)
    return ()


class LinearSpring(Element):
    """``r = k x`` (the paper's capacitor analogue)."""

    parameters = (STIFFNESS,)

    def force(self, x, xdot, xi, q, p):
        return p.k * x

    def time_scales(self, p):
        return _spring_time_scale(p, "k")

    def error_scales(self, p):
        return _static_deflection(p, "k")

    def check(self, p):
        require_nonnegative(p, "k")


class LinearDashpot(Element):
    """``r = c xdot`` (the paper's resistor analogue)."""

    parameters = (DAMPING,)

    def force(self, x, xdot, xi, q, p):
        return p.c * xdot

    def time_scales(self, p):
        return _dashpot_time_scale(p)

    def check(self, p):
        require_nonnegative(p, "c")


# ---------------------------------------------------------------------------------------------
# mem-elements (docs/models.md "PogoStickMem"): each reduces to its linear element when its memory parameter
# is 0.  Both keep their memory in continuous states (absement a) or in the deflection itself.
# ---------------------------------------------------------------------------------------------

SPRING_LAWS = {0: "linear", 1: "softening", 2: "hardening"}


class MemSpring(Element):
    """Mem-spring (memcapacitor analogue), ``r = k(a) x`` with the absement ``a' = x``.

    ``spring_law`` 0: ``k(a) = k`` (linear); 1: ``k / (1 + beta |a|)`` (softening);
    2: ``k (1 + beta |a|)`` (hardening).  ``a`` is frozen in flight (``x = 0`` there), so it
    carries memory from one contact to the next.  Its force-deflection loop is pinched:
    ``r = 0`` wherever ``x = 0``.
    """

    parameters = (
        Parameter("k", 100.0, "N/m", "stiffness of the leg spring at zero absement"),
        Parameter("spring_law", 1, "", "mem-spring law: 0 linear k, 1 softening k/(1+beta|a|), "
                  "2 hardening k(1+beta|a|)", integer=True),
        Parameter("beta", 1.0, "1/(m.s)", "memory coefficient of the mem-spring (0: linear spring)"),
        Parameter("a_0", 0.0, "m.s", "initial absement a (time integral of the deflection)"),
    )
    states = (Variable("a", "m.s", "absement of the leg, a' = x (time integral of the deflection)"),)
    outputs = (Variable("a", "m.s", "absement of the leg, a' = x (time integral of the deflection)"),)

    def initial_states(self, p):
        return (p.a_0,)

    def rates(self, x, xdot, xi, q, p):
        return (x,)

    def stiffness(self, a, p):
        """``k(a)`` of the chosen law."""
        law = p.spring_law
        if law == 0:
            return p.k
        if law == 1:
            return p.k / (1.0 + p.beta * abs(a))
        return p.k * (1.0 + p.beta * abs(a))

    def force(self, x, xdot, xi, q, p):
        law = p.spring_law
        if law == 0:
            return p.k * x
        if law == 1:
            return p.k / (1.0 + p.beta * abs(xi[0])) * x
        return p.k * (1.0 + p.beta * abs(xi[0])) * x

    def output_values(self, x, xdot, xi, q, p):
        return (xi[0],)

    def time_scales(self, p):
        return _spring_time_scale(p, "k")  # at zero absement

    def error_scales(self, p):
        return _static_deflection(p, "k")

    def check(self, p):
        require_nonnegative(p, "k", "beta")
        require(p.spring_law in tuple(SPRING_LAWS), "spring_law", p.spring_law,
                "spring_law is 0 (linear), 1 (softening) or 2 (hardening)")


class MemDashpot(Element):
    """Mem-dashpot (memristor analogue), ``r = c(x) xdot`` with ``c(x) = c (1 + gamma x^2)``.

    Its memory is the deflection ``x = integral of xdot`` itself; its force-velocity loop is
    pinched (``r = 0`` wherever ``xdot = 0``).  ``gamma = 0`` is the linear dashpot.
    """

    parameters = (
        Parameter("c", 0.5, "N.s/m", "damping coefficient of the leg dashpot at zero deflection"),
        Parameter("gamma", 0.0, "1/m2", "memory coefficient of the mem-dashpot, c(x) = c (1 + gamma x^2)"),
    )

    def force(self, x, xdot, xi, q, p):
        return p.c * (1.0 + p.gamma * x * x) * xdot

    def time_scales(self, p):
        return _dashpot_time_scale(p)  # at zero deflection

    def check(self, p):
        require_nonnegative(p, "c", "gamma")


# ---------------------------------------------------------------------------------------------
# shape-memory alloy (docs/models.md "PogoStickSMA"): a flag-shaped hysteresis with its branch as an explicit
# discrete state and one event per branch transition
# ---------------------------------------------------------------------------------------------

ELASTIC, UPPER, LOWER = 0, 1, 2


class SMAFlag(Element):
    """Superelastic SMA element: piecewise-linear flag in compression (``x <= 0``).

    Discrete memory in ``q``: ``branch`` (0 elastic, 1 upper plateau, 2 lower plateau), the
    anchor ``(x_a, r_a)`` of the current elastic line (``(0, 0)``: the virgin line) and ``H_l``,
    the deflection of the latest load reversal on the upper plateau (0 before the first).

    * elastic line: ``r = r_a + k1 (x - x_a)``
    * upper plateau: ``r_U(x) = k1 x1 + k2 (x - x1)``
    * lower plateau: ``r_L(x) = k1 x3 + k2 (x - x3)``

    Events (in priority order): ``upper_plateau`` (elastic: ``r_el - r_U`` falling),
    ``reversal`` (upper: ``xdot`` rising; anchor ``(x, r_U(x))``, ``H_l <- x``),
    ``lower_plateau`` (anchored elastic line: ``r_el - r_L`` rising), ``virgin_line`` (lower:
    ``x - x3`` rising; anchor ``(0, 0)``), ``reload`` (lower: ``xdot`` falling; anchor
    ``(x, r_L(x))``).  The foot may leave the ground only from the virgin line.
    """

    parameters = (
        Parameter("k1", 100.0, "N/m", "SMA elastic (austenite) stiffness, slope of every elastic line"),
        Parameter("k2", 40.0, "N/m", "SMA plateau stiffness, slope of both transformation plateaus (0 < k2 < k1)"),
        Parameter("x1", -0.2, "m", "SMA deflection where the virgin line meets the upper plateau (x1 < x3)"),
        Parameter("x3", -0.1, "m", "SMA deflection where the lower plateau meets the virgin line (x3 < 0)"),
    )
    discrete = {"branch": ELASTIC, "x_a": 0.0, "r_a": 0.0, "H_l": 0.0}
    outputs = (
        Variable("branch", "", "SMA branch: 0 elastic (virgin line or inner elastic line), "
                 "1 upper plateau, 2 lower plateau"),
        Variable("H_l", "m", "deflection of the latest load reversal on the upper plateau (0 before the first)"),
    )
    integer_outputs = frozenset({"branch"})

    # ---- the flag ----
    @staticmethod
    def r_upper(x, p):
        return p.k1 * p.x1 + p.k2 * (x - p.x1)

    @staticmethod
    def r_lower(x, p):
        return p.k1 * p.x3 + p.k2 * (x - p.x3)

    def force(self, x, xdot, xi, q, p):
        b = q["branch"]
        if b == ELASTIC:
            return q["r_a"] + p.k1 * (x - q["x_a"])
        if b == UPPER:
            return p.k1 * p.x1 + p.k2 * (x - p.x1)
        return p.k1 * p.x3 + p.k2 * (x - p.x3)

    def output_values(self, x, xdot, xi, q, p):
        return (q["branch"], q["H_l"])

    def time_scales(self, p):
        return _spring_time_scale(p, "k1")

    def error_scales(self, p):
        return _static_deflection(p, "k1") + (("|x3| (SMA lower corner)", ("x3",), abs(p.x3)),
                                              ("x3 - x1 (SMA plateau length)", ("x1", "x3"), p.x3 - p.x1))

    def liftoff_allowed(self, q):
        return q["branch"] == ELASTIC and q["x_a"] == 0.0 and q["r_a"] == 0.0

    def check(self, p):
        require(p.k2 > 0, "k2", p.k2, "k2 > 0 (the plateaus rise with the deflection)")
        require(p.k1 > p.k2, "k2", p.k2, f"k2 < k1 = {p.k1!r} (the plateaus are softer than the elastic lines)")
        require(p.x3 < 0, "x3", p.x3, "x3 < 0 (the flag lies in compression)")
        require(p.x1 < p.x3, "x1", p.x1, f"x1 < x3 = {p.x3!r} (the upper plateau starts beyond the lower one)")
        x0 = p.xbar_0 - p.x_i
        require(x0 >= p.x1, "xbar_0", p.xbar_0,
                f"the SMA starts on its virgin line: xbar_0 - x_i >= x1 (xbar_0 >= {p.x_i + p.x1!r})")


def _to_upper(x, xdot, xi, q, p):
    return xi, dict(q, branch=UPPER)


def _reversal(x, xdot, xi, q, p):
    return xi, dict(q, branch=ELASTIC, x_a=x, r_a=SMAFlag.r_upper(x, p), H_l=x)


def _to_lower(x, xdot, xi, q, p):
    return xi, dict(q, branch=LOWER)


def _to_virgin(x, xdot, xi, q, p):
    return xi, dict(q, branch=ELASTIC, x_a=0.0, r_a=0.0)


def _reload(x, xdot, xi, q, p):
    return xi, dict(q, branch=ELASTIC, x_a=x, r_a=SMAFlag.r_lower(x, p))


# The plateau guards r_el(x) - r_U(x) and r_el(x) - r_L(x), written as (k1 - k2)(x - x_a) + (r_a - r_P(x_a)):
# the same lines, but without the cancellation of two forces of ~k1 |x| that left a noise of ~1e-14 k1 |x|
# on a guard whose slope is only (k1 - k2) xdot.  With k2 close to k1 that noise fired a false
# upper_plateau right after a reversal (where the guard starts at 0 and rises with x - x_a), and the leg
# then extended on the plateau.  Right after a reversal (reload) the constant term is
# exactly 0, since r_a was computed by r_upper (r_lower) at x_a itself.
def _upper_guard(x, xdot, xi, q, p):
    x_a = q["x_a"]
    return (p.k1 - p.k2) * (x - x_a) + (q["r_a"] - (p.k1 * p.x1 + p.k2 * (x_a - p.x1)))


def _lower_guard(x, xdot, xi, q, p):
    x_a = q["x_a"]
    return (p.k1 - p.k2) * (x - x_a) + (q["r_a"] - (p.k1 * p.x3 + p.k2 * (x_a - p.x3)))


_SMA_EVENTS = (
    LegEvent("upper_plateau", FALLING, _upper_guard, _to_upper, lambda q: q["branch"] == ELASTIC),
    LegEvent("reversal", RISING, lambda x, xdot, xi, q, p: xdot, _reversal, lambda q: q["branch"] == UPPER),
    LegEvent("lower_plateau", RISING, _lower_guard, _to_lower, lambda q: q["branch"] == ELASTIC and q["x_a"] != 0.0),
    LegEvent("virgin_line", RISING, lambda x, xdot, xi, q, p: x - p.x3, _to_virgin, lambda q: q["branch"] == LOWER),
    LegEvent("reload", FALLING, lambda x, xdot, xi, q, p: xdot, _reload, lambda q: q["branch"] == LOWER),
)

SMAFlag.events = _SMA_EVENTS
