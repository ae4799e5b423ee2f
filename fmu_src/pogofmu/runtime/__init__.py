"""The code inside every FMU (standard library only; built into each FMU as a package private to
that build of that model).

* :mod:`.model` — a model as plain data and pure functions; :mod:`.plant` — the plant's
  parameters, declared once; :mod:`.elements`, :mod:`.soil` — leg elements and the soil law;
  :mod:`.models` — the model variants (the registry);
* :mod:`.solver` — the solver's Python side: the binding of the one engine (C, exact state-event
  location for any model), the solver's settings and their rules, the Runge–Kutta tableaux;
* :mod:`.fmi2`, :mod:`.fmi3` — the model's FMU class per FMI version (the FMI rules are C, one
  adapter for both kinds of FMU); :mod:`.hosted` — a Python-hosted FMU's model for that adapter;
  :mod:`.interface` — what an FMU exposes (its variables and their roles, arrays, discrete
  layout), for both generators;
  :mod:`.status` — the FMI status table; :mod:`.units` — the unit definitions;
* :mod:`.fmath` — the mathematical functions and tables a model may call (followed by the native
  generator); :mod:`.dual` — dual numbers, the exact derivatives of a model's functions;
  :mod:`.eventlog` — the event log's record (``log_events = 1``), written and read in one place.

Nothing here imports anything outside this folder: the build stages the folder as it is, under a
name private to each build (``_pogofmu_<Model>_<hash>``), and rewrites a user's model file's
``from pogofmu import ...`` to that name: the names below are the public API a model file imports
(``pogofmu/__init__.py`` gives the same ones on the host), and ``pogofmu.elements`` /
``pogofmu.fmath`` are this folder's :mod:`.elements` and :mod:`.fmath`.
"""

__version__ = "0.3.0"  # the project's version (pyproject.toml reads it; every FMU carries it)

from . import fmath  # noqa: E402
from .model import (FALLING, RISING, DomainError, Event, HybridModel, TimeEvent, ModelError, Parameter,  # noqa: E402
                    ParameterError, Params, Variable, ZenoError, require, require_finite, require_nonnegative,
                    require_positive)

__all__ = ["HybridModel", "Event", "TimeEvent", "Variable", "Parameter", "FALLING", "RISING", "Params", "ModelError",
           "ParameterError", "DomainError", "ZenoError", "require", "require_finite", "require_positive",
           "require_nonnegative", "fmath", "__version__"]
