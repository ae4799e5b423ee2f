"""pogofmu: FMUs of hybrid dynamical systems whose own solver locates every state event exactly —
FMI 2.0 co-simulation and FMI 3.0 model exchange/co-simulation, Python-hosted or native C.

The public API of a model file (docs/writing-models.md)::

    from pogofmu import HybridModel, Event, Variable, Parameter, FALLING, RISING
    from pogofmu import require, require_positive, require_nonnegative, require_finite, ParameterError
    from pogofmu import fmath            # the math functions a model calls (fmath.sqrt(x), ...)
    from pogofmu.elements import MemSpring, LinearDashpot, HuntCrossley   # building blocks

and ``pogofmu export model.py --out DIR`` makes the FMUs of it.  The same names work inside the
FMUs, where the build rewrites the imports to the FMU's private copy of :mod:`pogofmu.runtime`.

Two floors: :mod:`pogofmu.runtime` is the code that goes into every FMU (model, engine, FMI
adapters; standard library only); the host-side tools beside it — :mod:`pogofmu.exporter` (the
exporter), :mod:`pogofmu.experiments` (default experiments), :mod:`pogofmu.ssp` (the SSP master),
:mod:`pogofmu.sweep`, :mod:`pogofmu.studies` and :mod:`pogofmu.cli` (the ``pogofmu`` command) —
never go into an FMU.
"""
import sys as _sys

from .runtime import *  # noqa: F401,F403 (the public API of a model file)
from .runtime import __all__, __version__  # noqa: F401 (one place for the version: the FMUs carry it)
from .runtime import elements, fmath  # noqa: F401

# ``import pogofmu.elements`` / ``pogofmu.fmath`` are the runtime's modules themselves (not copies):
# a model file's calls of ``fmath`` are the runtime's functions, which the native generator follows
# through the traced values' own tables (fmath's docstring)
_sys.modules.setdefault(__name__ + ".elements", elements)
_sys.modules.setdefault(__name__ + ".fmath", fmath)
__all__ = list(__all__) + ["elements"]


def _host_engine_library():
    from pogofmu.codegen.build import host_engine_library  # (host-side: compiled once, or the wheel's)

    return host_engine_library()


# the runtime (which goes into FMUs) imports nothing of the host side: the host tells it where its engine is
from .runtime.solver import cengine as _cengine  # noqa: E402

_cengine.set_host_library(_host_engine_library)
