"""PogoStickSMA: the pogo stick with a shape-memory-alloy leg (docs/models.md "PogoStickSMA"; paper Sect. 4,
Appendix A.2 event types #3-#6).

The leg is a superelastic SMA flag (``k1, k2, x1, x3``; its branch and anchor are discrete
states with one event per transition) in parallel with a linear dashpot ``c``.
"""
from ..elements import LinearDashpot, SMAFlag
from .stick import make_stick_model

PLOTS = (
    (("y", "z", "xbar"), ("branch", "s")),  # time histories with the SMA branch
    (("vs", "x", "r"),),  # force-deflection loop: the flag (plus the dashpot's c xdot)
    (("H_l",), ("E", "W_leg")),  # latest reversal point and energy book-keeping
)

MODEL = make_stick_model(
    "PogoStickSMA",
    "Pogo stick with a shape-memory-alloy leg (Pei, Quadrelli & Wright 2020, Sect. 4): mass on a "
    "massless leg of a superelastic SMA flag and a linear dashpot in parallel; flight/contact and SMA "
    "branch transitions are state events located by the internal solver",
    (SMAFlag(), LinearDashpot()),
    plots=PLOTS,
)
