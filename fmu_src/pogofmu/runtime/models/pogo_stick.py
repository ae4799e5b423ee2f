"""PogoStick: the basic model (docs/models.md "PogoStick"; paper Sect. 3, Appendix A.1).

A mass ``m`` on a massless leg made of a linear spring ``k`` and a linear dashpot ``c`` in parallel.
"""
from ..elements import LinearDashpot, LinearSpring
from .stick import make_stick_model

MODEL = make_stick_model(
    "PogoStick",
    "Pogo stick (Pei, Quadrelli & Wright 2020, Sect. 3): mass on a massless spring-dashpot leg, "
    "switching between flight and contact; state events located by the internal solver",
    (LinearSpring(), LinearDashpot()),
)
