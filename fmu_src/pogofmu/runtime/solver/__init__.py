"""The solver's Python side: the engine is C (``fmu_src/native/engine/``); here is its binding for a
model written in Python, and the settings and tableaux both backends share.

* :mod:`.cengine` — the :class:`Simulator`: the C engine (explicit Runge-Kutta pairs with error
  control, exact state-event location, restarts, the work budget, event storms, domain conditions)
  with the model's Python functions called back; its snapshots as plain data;
* :mod:`.settings` — the solver's settings, their rules, the domain slack (the C engine receives
  them as the model's ``check_settings``);
* :mod:`.tableaux` — the Runge-Kutta tableaux the C pairs (``pg_pairs.c``) are generated from.
"""
from .cengine import EventRecord, Simulator, snapshot_from_data, snapshot_to_data
from .settings import (SOLVER_PARAMETER_NAMES, SOLVER_PARAMETERS, check_solver_parameters, solver_defaults,
                       solver_parameters, split_parameters)

__all__ = ["SOLVER_PARAMETER_NAMES", "SOLVER_PARAMETERS", "EventRecord", "Simulator", "check_solver_parameters",
           "snapshot_from_data", "snapshot_to_data", "solver_defaults", "solver_parameters", "split_parameters"]
