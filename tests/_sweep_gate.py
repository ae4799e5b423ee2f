"""A pythonfmu FMU for the sweep tests that must interrupt a sweep at a point they control.

``fmi2DoStep`` of a run whose parameter ``k`` is at least ``hold`` waits until the gate file
``<temporary folder>/pogofmu-test-gate-<gate>`` exists (at most ``GATE_TIMEOUT`` seconds; ``gate``
is a whole number the test chooses, so that worker processes started before the test find the
same file); the runs below ``hold`` pass at once. A test thus knows exactly which runs can have finished when it
interrupts the sweep, however fast or loaded the machine is. Output ``y = k``.
"""
import os
import tempfile
import time

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

GATE_TIMEOUT = 600.0


class SweepGate(Fmi2Slave):
    author = "pogofmu tests"
    description = "sweep test gate: runs with k >= hold wait for the file pogofmu-test-gate-<gate>"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.k = 0.0
        self.hold = 1e300
        self.gate = 0.0
        self.y = 0.0
        self.register_variable(Real("k", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                                    description="the swept value"))
        self.register_variable(Real("hold", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                                    description="runs with k >= hold wait for the gate file"))
        self.register_variable(Real("gate", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                                    description="number of the gate file"))
        self.register_variable(Real("y", causality=Fmi2Causality.output, description="k"))

    def do_step(self, current_time, step_size):
        if self.k >= self.hold:
            gate = gate_file(self.gate)
            deadline = time.monotonic() + GATE_TIMEOUT
            while not os.path.exists(gate) and time.monotonic() < deadline:
                time.sleep(0.005)
        self.y = self.k
        return True


def gate_file(number) -> str:
    return os.path.join(tempfile.gettempdir(), f"pogofmu-test-gate-{int(number)}")
