"""The FMI floor of bench_fmu.py: a pythonfmu co-simulation FMU that does nothing.

``fmi2DoStep`` returns at once; one Real output (constant 0) is all fmpy records.  It measures
what fmpy + pythonfmu cost per communication step before any model code runs.  bench_fmu.py
builds it into a temporary folder at benchmark time.

(pythonfmu 0.7's loader needs the literal line ``class BenchFloor(Fmi2Slave):`` below and a
method in the class body; the module name is unique so that it never shadows another slave.)
"""
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class BenchFloor(Fmi2Slave):
    author = "pogofmu benchmarks"
    description = "do-nothing FMU: the FMI floor of bench_fmu.py"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.out = 0.0
        self.register_variable(Real("out", causality=Fmi2Causality.output,
                                    description="constant 0 (the one output fmpy records)"))

    def do_step(self, current_time, step_size):
        return True
