"""The code inside every FMU (standard library only; built into each FMU as a package private to
that build of that model).

* :mod:`.model` — a model as plain data and pure functions; :mod:`.plant` — the plant's
  parameters, declared once; :mod:`.elements`, :mod:`.soil` — leg elements and the soil law;
  :mod:`.models` — the model variants (the registry);
* :mod:`.engine` — one integrator with exact state-event location for any model;
* :mod:`.fmi2`, :mod:`.fmi3` — one adapter per FMI version from any model to an FMU;
  :mod:`.status` — the FMI status table; :mod:`.units` — the unit definitions.

Nothing here imports anything outside this folder: the build stages the folder as it is.
"""

__version__ = "0.2.0"  # the project's version (pyproject.toml reads it; every FMU carries it)
