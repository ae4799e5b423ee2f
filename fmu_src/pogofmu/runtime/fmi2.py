"""The FMU class of a model: what a Python-hosted FMU's slave module defines and what the exporter
writes the modelDescription from (:class:`HybridSlave`; FMI 3.0: :mod:`.fmi3`).

A slave file is a few lines (``pogofmu export`` writes it into the FMU's resources)::

    from pogofmu.runtime.fmi2 import HybridSlave as Fmi2Slave
    from pogofmu.runtime.models.pogo_stick import MODEL

    class PogoStick(Fmi2Slave):
        model = MODEL

        def __init__(self, **kwargs):
            super().__init__(**kwargs)

The FMI rules are C, written once for every FMU of either kind: the FMI entry files
``fmu_src/native/fmi2/pg_fmi2.c`` / ``fmi3/pg_fmi3.c`` (call states, arguments, the log filter)
and the adapter ``fmu_src/native/adapter/`` (``pg_instance.c``: the variable table, parameters
fixed at initialization and checked there, inputs held over a step, outputs refreshed once per
step, the step's rules, the event log, FMU states with their owner and seal; ``pg_instance3.c``:
FMI 3.0). A Python-hosted FMU's launcher is that adapter with a model whose functions are the
model's Python code (:mod:`.hosted`, :class:`.solver.cengine.Binding`); a native FMU's are
generated C. Behaviour (FMI 2.0 co-simulation):

* parameters are ``fixed``: set them before ``fmi2ExitInitializationMode``, where they are all
  checked and the initial state is derived from them;
* every ``fmi2DoStep`` holds the inputs over the step, lets the engine run to the end of the step
  (handling every event inside it) and refreshes all outputs;
* errors name the variable, its value and the rule (or the physical condition and the time); a
  refused call or a model that stopped is ``fmi2Error`` and the instance stays usable
  (``fmi2Reset``, ``fmi2SetFMUstate``, a corrected input);
* with the parameter ``log_events = 1`` every event is reported through the logger (category
  ``logEvents``): kind, exact time and the state before the jump;
* ``fmi2GetFMUstate`` / ``fmi2SetFMUstate`` save and restore the whole engine; the serialized
  form is sealed (SHA-256) and checked against the model and build it came from.
"""
from __future__ import annotations

from typing import Tuple

from .interface import LOG_CATEGORIES, FmiVariable, fmi2_variables  # (what the FMU exposes: one module)
from .model import HybridModel

__all__ = ["HybridSlave", "FmiVariable", "fmi2_variables", "LOG_CATEGORIES"]


class HybridSlave:
    """The FMU class of a :class:`HybridModel` (set ``model`` in a subclass): the model and what the
    modelDescription says of it."""

    model: HybridModel = None
    author = "pogofmu"
    license = "MIT"
    version = None  # the project version, written into modelDescription.xml by the exporter
    log_categories = LOG_CATEGORIES

    def __init__(self, **kwargs):  # (the slave file's class calls it; nothing to set up)
        pass

    @classmethod
    def variables(cls) -> Tuple[FmiVariable, ...]:
        return fmi2_variables(cls.model)
