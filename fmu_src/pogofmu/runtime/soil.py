"""Soil contact laws for a massless foot (docs/models.md "Penetrator"; paper Sect. 5, Appendix A.3).

A soil is plain data plus pure functions, like a leg element (it knows nothing of FMI):

* ``parameters``: its :class:`~pogofmu.runtime.model.Parameter` s, ``check(p)`` their rules;
* ``reference_velocity(p, impact_speed)``: the velocity scale of its damping, fixed at each
  touchdown (a model keeps it in its discrete state ``q``);
* ``bind(p, d0dot) -> (force, rate)``: two closures for one contact,
  ``force(delta, delta_dot)`` the soil's reaction on the foot (positive up, ``delta`` the
  penetration, positive into the soil) and ``rate(load, c_series, delta)`` the penetration rate of
  a *massless* foot pushed into the soil by ``load - c_series*delta_dot`` (a leg whose force on the
  foot is affine in ``delta_dot``, e.g. a spring ``k`` parallel to a dashpot ``c_series``).

Only the positive part of the penetration counts: ``max(0, delta)^n`` (the paper's remedy for a
non-integer power while the integrator probes ``delta`` slightly below 0 around liftoff).
"""
from __future__ import annotations

from . import fmath
from .model import Parameter, Params, require


def _power(n: float):
    """``d -> max(0, d)^n``, with the common exponents written without ``pow`` (chosen once per
    contact: :meth:`HuntCrossley.bind` builds the flow's closures with it)."""
    if n == 1.0:
        return lambda d: d if d > 0.0 else 0.0
    if n == 1.5:
        return lambda d: d * fmath.sqrt(d) if d > 0.0 else 0.0
    if n == 2.0:
        return lambda d: d * d if d > 0.0 else 0.0
    return lambda d: d ** n if d > 0.0 else 0.0


def positive_power(d: float, n: float) -> float:
    """``max(0, d)^n`` with the arithmetic of :func:`_power`'s closures, without building one."""
    if not d > 0.0:
        return 0.0
    if n == 1.0:
        return d
    if n == 1.5:
        return d * fmath.sqrt(d)
    if n == 2.0:
        return d * d
    return d ** n


class HuntCrossley:
    """Hunt–Crossley soil: ``F = K P + lambda P delta_dot`` with ``P = max(0, delta)^n`` and
    ``lambda = (3/2)(1 - c_r) K / d0dot``.

    ``K`` stiffness (N/m^n), ``n >= 1`` exponent (1 linear, 3/2 Hertzian), ``c_r`` in [0, 1] the
    coefficient of restitution the damping reproduces for an impact at the reference velocity
    ``d0dot`` (> 0).  With ``d0dot_from_impact = 1`` the reference velocity is the impact speed of
    each touchdown instead (so every impact sees the same restitution law, whatever its speed);
    the parameter ``d0dot`` is then used only for a contact that exists at the start (no impact).
    """

    parameters = (
        Parameter("K", 1.0e4, "N/m^n", "Hunt-Crossley stiffness of the soil: F = K delta^n (1 + lambda/K delta_dot)"),
        Parameter("n", 1.5, "", "Hunt-Crossley exponent (>= 1; 1 linear soil, 1.5 Hertzian contact)"),
        Parameter("c_r", 0.5, "", "coefficient of restitution at the reference velocity, 0 <= c_r <= 1 "
                  "(lambda = 1.5 (1 - c_r) K / d0dot)"),
        Parameter("d0dot", 3.1321, "m/s", "reference impact velocity of the restitution law (> 0)"),
        Parameter("d0dot_from_impact", 0, "", "1: take the reference velocity from each touchdown's impact "
                  "speed instead of d0dot; 0: use d0dot", integer=True),
    )

    def check(self, p: Params):
        require(p.K >= 0, "K", p.K, "K >= 0 (soil stiffness)")
        require(p.n >= 1, "n", p.n, "n >= 1 (Hunt-Crossley exponent; n < 1 gives an infinite stiffness at "
                "zero penetration)")
        require(0 <= p.c_r <= 1, "c_r", p.c_r, "0 <= c_r <= 1 (coefficient of restitution)")
        require(p.d0dot > 0, "d0dot", p.d0dot, "d0dot > 0 (reference impact velocity)")
        require(p.d0dot_from_impact in (0, 1), "d0dot_from_impact", p.d0dot_from_impact,
                "d0dot_from_impact is 0 or 1")

    @staticmethod
    def reference_velocity(p: Params, impact_speed: float) -> float:
        """The ``d0dot`` of a contact that starts with this impact speed (m/s, >= 0)."""
        if p.d0dot_from_impact and impact_speed > 0.0:
            return impact_speed
        return p.d0dot

    @staticmethod
    def damping(p: Params, d0dot: float) -> float:
        """``lambda = (3/2)(1 - c_r) K / d0dot`` (N s/m^(n+1))."""
        return 1.5 * (1.0 - p.c_r) * p.K / d0dot

    def force_of(self, p: Params, d0dot: float, delta: float, delta_dot: float) -> float:
        """The soil force (N, positive up) at penetration ``delta`` and rate ``delta_dot`` (the
        arithmetic of ``bind``'s closures, without building them: guards call this every step)."""
        P = positive_power(delta, p.n)
        return (p.K + self.damping(p, d0dot) * delta_dot) * P

    def rate_of(self, p: Params, d0dot: float, load: float, c_series: float, delta: float) -> float:
        """Penetration rate of a massless foot loaded by ``load - c_series*delta_dot`` (see ``bind``)."""
        P = positive_power(delta, p.n)
        return (load - p.K * P) / (self.damping(p, d0dot) * P + c_series)

    def bind(self, p: Params, d0dot: float):
        """``(force, rate)`` closures for a contact with reference velocity ``d0dot``."""
        K = p.K
        lam = self.damping(p, d0dot)
        power = _power(p.n)

        def force(delta, delta_dot):
            P = power(delta)
            return (K + lam * delta_dot) * P

        def rate(load, c_series, delta):
            # massless foot: K P + lam P delta' = load - c_series delta'  (affine in delta')
            P = power(delta)
            return (load - K * P) / (lam * P + c_series)

        return force, rate
