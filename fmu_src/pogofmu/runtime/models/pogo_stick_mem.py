"""PogoStickMem: the pogo stick with mem-elements (docs/models.md "PogoStickMem"; paper Sect. 4, Appendix A.2).

The leg is a mem-spring (``spring_law`` 0 linear, 1 softening, 2 hardening, memory coefficient
``beta``, absement state ``a``) in parallel with a mem-dashpot (``c(x) = c (1 + gamma x^2)``).
With ``beta = gamma = 0`` it is the basic PogoStick for every law.
"""
from ..elements import MemDashpot, MemSpring
from .stick import make_stick_model

PLOTS = (
    (("y", "z", "xbar"), ("a",), ("s",)),  # time histories, like the paper's Fig. 23
    (("vs", "x", "r"),),  # force-deflection loop: pinched at x = 0 for the mem-spring
    (("r",), ("E", "W_leg")),  # leg force and energy book-keeping
)

MODEL = make_stick_model(
    "PogoStickMem",
    "Pogo stick with mem-models (Pei, Quadrelli & Wright 2020, Sect. 4): mass on a massless leg of a "
    "mem-spring k(a) (a = absement) and a mem-dashpot c(x) in parallel, switching between flight and "
    "contact; state events located by the internal solver",
    (MemSpring(), MemDashpot()),
    plots=PLOTS,
)
