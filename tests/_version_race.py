"""Python-hosted FMUs instantiated while another thread of the process calls Py_GetVersion without
pause (tests/test_concurrent_instantiation.py), in a fresh process.

    python _version_race.py DIST NAME,NAME,... HAMMER.so

CPython's Py_GetVersion formats its text into a static buffer at every call (glibc's vsnprintf
first writes '\\0' there), so a launcher that reads the version through it while another thread
calls it can read an empty text and take the host's CPython for an unusable one. The hammering
thread is C (tests/c_host/py_version_hammer.c, compiled by the test: a Python loop calls too
seldom to hit that window often). Each FMU (each its own copy of the launcher, which checks the
host's CPython once) is instantiated, initialized and stepped once with the hammering thread
running; the last line is a JSON list of "ok" or the failure (fmpy prints the FMU's log to
stdout)."""
import ctypes
import json
import sys

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

dist, names = sys.argv[1], sys.argv[2].split(",")
hammer = ctypes.CDLL(sys.argv[3], mode=ctypes.RTLD_GLOBAL)
hammer.hammer_stop.restype = ctypes.c_long
results = []
if hammer.hammer_start() != 0:
    raise SystemExit("cannot start the hammering thread")
try:
    for n in names:
        md = read_model_description(f"{dist}/{n}.fmu")
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(f"{dist}/{n}.fmu"),
                        modelIdentifier=md.coSimulation.modelIdentifier, instanceName=n)
        try:
            fmu.instantiate(loggingOn=True)
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            fmu.exitInitializationMode()
            fmu.doStep(0.0, 1e-3)
            fmu.terminate()
            fmu.freeInstance()
            results.append("ok")
        except Exception as exc:  # noqa: BLE001 - reported
            results.append(f"{n}: {exc}")
finally:
    calls = hammer.hammer_stop()
assert calls > 0, "the hammering thread never called Py_GetVersion"
print(json.dumps(results))
