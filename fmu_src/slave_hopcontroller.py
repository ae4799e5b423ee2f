"""FMU slave: HopController (README "HopController.fmu"), built into dist/HopController.fmu by build_fmu.py.

pythonfmu's native loader looks for a line ``class <Name>(Fmi2Slave):`` in this file, and a
second instance in the same process crashes if the class body holds no method: keep both.
"""
from pogofmu.fmi import HybridSlave as Fmi2Slave
from pogofmu.models.hop_controller import MODEL


class HopController(Fmi2Slave):
    model = MODEL

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
