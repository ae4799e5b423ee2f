"""FMU slave: Penetrator (MODELS.md Sect. 4), built into dist/Penetrator.fmu by build_fmu.py.

pythonfmu's native loader looks for a line ``class <Name>(Fmi2Slave):`` in this file, and a
second instance in the same process crashes if the class body holds no method: keep both.
"""
from pogofmu.fmi import HybridSlave as Fmi2Slave
from pogofmu.models.penetrator import MODEL


class Penetrator(Fmi2Slave):
    model = MODEL

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
