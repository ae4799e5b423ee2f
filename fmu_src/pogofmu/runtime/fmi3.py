"""FMI 3.0 for any :class:`~pogofmu.runtime.model.HybridModel`: what the FMU exposes, and the
semantics of model exchange and co-simulation with event mode that the adapter implements.

The rules are C, once for every FMU of either kind: the FMI 3.0 entry file
``fmu_src/native/fmi3/pg_fmi3.c`` (call states, arguments) and the adapter's FMI 3.0 part
``fmu_src/native/adapter/pg_instance3.c``; a Python-hosted FMU's model functions are its Python
code (:mod:`.hosted`). Here: :func:`check_state_outputs` (an export's check) and
:func:`fmi3_class`, the model's FMU class for the FMI 3.0 modelDescription.

Variables (:func:`fmi3_variables`): those of the FMI 2.0 FMU (same names, units, descriptions,
value references), then

* every continuous state that is not already an output of the same name, as a ``local``;
* ``der(<state>)`` for every state (``ContinuousStateDerivative``);
* ``guard_<event>`` for every event of the model (``EventIndicator``): the event's guard while the
  event is active in the current mode, ``1`` while it is inactive (a value that cannot cross zero);
* ``time``, the independent variable FMI 3.0 requires.

Model exchange (``fmi3InstantiateModelExchange``): the importer integrates the states and locates
the sign changes of the indicators.  The arming of the guards is the engine's, the one of
co-simulation (docs/solver.md, "Event semantics"; ``pg_engine_me_indicators`` and
``pg_engine_me_fired`` in ``pg_engine.c``): each indicator evaluation is an observation of the
trajectory (a guard seen on its before side is armed); a guard armed at zero after a jump is
reported shifted by its rounding band, so that the importer sees a sign change where it leaves the
band to its after side.  ``fmi3UpdateDiscreteStates`` applies the jump of the event pending at this
instant (a cascade of the latest jump) or else of the first event (in the model's priority order)
whose armed guard is on its after side, and asks for another update
(``discreteStatesNeedUpdate``) while the jump leaves an event pending at the same instant.  A sign
change in the wrong direction applies nothing.  An event that fires from zero again and again ends
in the engine's storm error naming it, as in co-simulation.
``valuesOfContinuousStatesChanged`` is true exactly when the jump changed a state;
``nominalsOfContinuousStatesChanged`` is always false (nominals are 1).  The domain of the model
is checked in ``fmi3CompletedIntegratorStep`` (which asks for Event Mode instead when an armed
guard has crossed: a state a step past an event may lie outside the domain until the jump),
event storms and domain at each event.

Co-simulation (``fmi3InstantiateCoSimulation``): the engine inside, as in FMI 2.0.  With
``earlyReturnAllowed`` ``fmi3DoStep`` stops at the first event of the step, at its exact time
(``lastSuccessfulTime``, ``earlyReturn`` when it lies before the end of the step):

* with ``eventModeUsed`` it stops *before* the jump (outputs: the left limit) and sets
  ``eventHandlingNeeded``; ``fmi3UpdateDiscreteStates`` in Event Mode applies the jump;
* without, it applies the jump itself and returns right after it.

Without ``earlyReturnAllowed`` it behaves like the FMI 2.0 FMU (every event handled inside the
step).  The step sequence of the engine, hence every event time, does not depend on where the
steps stop.
"""
from __future__ import annotations

from typing import Tuple

from .fmi2 import HybridSlave
from .interface import FmiVariable, array_table, fmi3_variables, indicator_name, rate_unit  # noqa: F401
from .model import HybridModel

__all__ = ["fmi3_variables", "fmi3_class", "check_state_outputs", "rate_unit", "indicator_name", "array_table"]


def check_state_outputs(model: HybridModel):
    """An output that shares its name with a state is that state's variable in FMI 3.0: its value
    must be the state's (checked at the default initial state).  Returns a problem or None."""
    p = model.params()
    x, q = model.initial(p)
    u = tuple(float(v.start) for v in model.inputs)
    out = model.output_fn(0.0, x, q, u, p)
    for i, var in enumerate(model.states):
        if var.name in out and out[var.name] != x[i]:
            return (f"{model.name}: output {var.name} = {out[var.name]!r} differs from the state {var.name} = "
                    f"{x[i]!r}: an FMI 3.0 state variable must carry the state's value")
    return None


class Fmi3Slave(HybridSlave):
    """The FMU class of a model in FMI 3.0: its variables are :func:`.interface.fmi3_variables`."""

    @classmethod
    def variables(cls) -> Tuple[FmiVariable, ...]:
        return fmi3_variables(cls.model)


_CLASSES = {}


def fmi3_class(slave_cls):
    """The FMI 3.0 class for a slave file's class (same name and model), made once."""
    cls = _CLASSES.get(slave_cls)
    if cls is None:
        cls = _CLASSES[slave_cls] = type(slave_cls.__name__, (Fmi3Slave, slave_cls),
                                         {"__module__": slave_cls.__module__})
    return cls
