"""The plant's parameters and input, declared once: the pogo-stick family, the penetrator and the
controller (whose knowledge of the plant carries the plant's names, so that one SSP parameter set
sets both consistently) all take them from here.
"""
from __future__ import annotations

from dataclasses import replace

from .model import Parameter, Variable

MASS = Parameter("m", 1.0, "kg", "mass of the body")
STIFFNESS = Parameter("k", 100.0, "N/m", "stiffness of the leg spring")
DAMPING = Parameter("c", 0.5, "N.s/m", "damping coefficient of the leg dashpot")
FREE_LENGTH = Parameter("x_i", 1.0, "m", "free length of the leg")
GRAVITY = Parameter("g", 9.81, "m/s2", "gravitational acceleration (Earth 9.81, Moon 1.62, Ceres 0.28)")

F_EXT = Variable("F_ext", "N", "external vertical force on the mass (positive up)", 0.0)


def known_to_controller(par: Parameter) -> Parameter:
    """The plant parameter as a controller's model of it: same name, default and unit."""
    return replace(par, description=f"{par.description} (controller's model of the plant)")
