"""First instantiations from several threads at once, in a fresh process (tests/test_concurrent_instantiation.py).

    python _threads_fmpy.py DIST NAME,NAME,...

One thread per name, released together at a barrier before fmi2Instantiate (nothing of these
FMUs instantiated before in the process); each initializes, takes 100 steps of 1 ms and reports
its y (or the failure) in a JSON list on the last line."""
import json
import sys
import threading

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
dist, names = sys.argv[1], sys.argv[2].split(",")
dirs = {n: extract(f"{dist}/{n}.fmu") for n in set(names)}
mds = {n: read_model_description(f"{dist}/{n}.fmu") for n in set(names)}
barrier = threading.Barrier(len(names))
results = [None] * len(names)
def work(i, n):
    md = mds[n]
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=dirs[n], modelIdentifier=md.coSimulation.modelIdentifier, instanceName=f"t{i}")
    barrier.wait()
    try:
        fmu.instantiate(loggingOn=True)
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        for k in range(100):
            fmu.doStep(k * 1e-3, 1e-3)
        y = next(v for v in md.modelVariables if v.causality == "output" and v.type == "Real")
        results[i] = ["ok", y.name, fmu.getReal([y.valueReference])[0]]
        fmu.terminate()
        fmu.freeInstance()
    except Exception as exc:
        results[i] = f"failed: {exc}"
threads = [threading.Thread(target=work, args=(i, n)) for i, n in enumerate(names)]
for t in threads:
    t.start()
for t in threads:
    t.join()
print(json.dumps(results))
