"""Free one instance of an FMU twice, then call it: what an importer with a stale pointer does.

Run in a process of its own (a heap that is corrupted takes only this process with it); prints
the statuses of the calls on the freed instance as JSON on its last line.
Arguments: the .fmu, the FMI version (2 or 3).
"""
import ctypes
import json
import sys

from fmpy import extract, read_model_description

path, fmi = sys.argv[1], int(sys.argv[2])
md = read_model_description(path)
unzipped = extract(path)
V = ctypes.c_void_p
if fmi == 2:
    from fmpy.fmi2 import FMU2Slave

    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="freed")
    fmu.instantiate(loggingOn=True)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    c = V(fmu.component)
    free, step, reset = fmu.dll["fmi2FreeInstance"], fmu.dll["fmi2DoStep"], fmu.dll["fmi2Reset"]
    free.restype = None
    free(c)
    free(c)  # the second free
    statuses = {"fmi2DoStep": step(c, ctypes.c_double(0.0), ctypes.c_double(1e-3), 1), "fmi2Reset": reset(c)}
else:
    from fmpy.fmi3 import FMU3Slave

    fmu = FMU3Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="freed")
    fmu.instantiate(loggingOn=True)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    c = V(fmu.component)
    free, step, reset = fmu.dll["fmi3FreeInstance"], fmu.dll["fmi3DoStep"], fmu.dll["fmi3Reset"]
    free.restype = None
    free(c)
    free(c)
    flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
    statuses = {"fmi3DoStep": step(c, ctypes.c_double(0.0), ctypes.c_double(1e-3), ctypes.c_bool(True),
                                   *[ctypes.byref(f) for f in flags]),
                "fmi3Reset": reset(c)}
print(json.dumps(statuses))
