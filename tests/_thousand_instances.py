"""Run by tests/test_concurrent_instantiation.py in a fresh process: instantiate one FMU (argv[1]) n times
(argv[2]) through fmpy, one after the other, each initialized, stepped once and freed; print, as
JSON, which of the FMU's private modules (``_pogofmu_*``) the process holds after the first and
after the last instance (name -> id of the module object), and the modules the FMU's boot code
created (``importlib.util.module_from_spec`` calls)."""
import importlib.util
import json
import sys

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

path, n = sys.argv[1], int(sys.argv[2])
md = read_model_description(path)
unzipped = extract(path)
created = []
real = importlib.util.module_from_spec


def counting(spec):
    created.append(spec.name)
    return real(spec)


importlib.util.module_from_spec = counting


def private():
    return {name: id(module) for name, module in sys.modules.items() if name.startswith("_pogofmu_")}


after = []
for i in range(n):
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=f"instance{i}")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)
    fmu.terminate()
    fmu.freeInstance()
    if i in (0, n - 1):
        after.append(private())
print(json.dumps({"first": after[0], "last": after[-1], "created": created}))
