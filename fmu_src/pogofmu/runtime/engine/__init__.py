"""The hybrid engine: embedded Runge-Kutta integration with exact state-event location.

* :mod:`.pairs` — the Runge-Kutta pairs (DOPRI5, DOP853) and their generated code;
* :mod:`.settings` — the solver's settings, their rules, the domain slack;
* :mod:`.simulator` — the :class:`Simulator` that integrates any model and locates its events;
* :mod:`.snapshot` — a simulator's state as plain data (serialized FMU states).
"""
from .pairs import DOP853, DOPRI5, METHODS
from .settings import (SOLVER_PARAMETER_NAMES, SOLVER_PARAMETERS, check_solver_parameters, solver_defaults,
                       solver_parameters, split_parameters)
from .simulator import EventRecord, Simulator
from .snapshot import snapshot_from_data, snapshot_to_data

__all__ = ["DOP853", "DOPRI5", "METHODS", "SOLVER_PARAMETER_NAMES", "SOLVER_PARAMETERS", "EventRecord",
           "Simulator", "check_solver_parameters", "snapshot_from_data", "snapshot_to_data", "solver_defaults",
           "solver_parameters", "split_parameters"]
