"""An error logged after fmpy's FMI 2.0 log proxy was pointed at a logger that is gone.

fmpy 0.3 formats FMI 2.0 messages in a native proxy with one target for the whole process;
``simulate_fmu(..., logger=...)`` points it at that logger, which is freed when the simulation
returns (docs/known-issues.md). This script does that first, as earlier tests of a long test
process do, then instantiates PogoStick and calls the bare getter with an unknown value reference,
whose refusal the FMU logs. Run in a process of its own: with fmpy's default callbacks the proxy
calls the freed function, which may kill the process.

Arguments: the backend (``python`` or ``native``), the FMI version (2 or 3), ``own`` (the instance gets callbacks of its own, as
tests/support.py's RawInstance gives them) or ``default`` (fmpy's ``instantiate_fmu`` without a
logger: fmpy's default callbacks); optionally ``sweep``: what comes first is a run of the sweep's
runner (pogofmu.sweep.Runner) instead of ``simulate_fmu(logger=...)``. Prints the status and the
messages the instance's logger got, as JSON on its last line.
"""
import ctypes
import gc
import json
import sys
from pathlib import Path

from fmpy import extract, instantiate_fmu, read_model_description, simulate_fmu

sys.path.insert(0, str(Path(__file__).parent))
from support import DIST, RawInstance  # noqa: E402

from pogofmu.fmpy_raw import raw_call  # noqa: E402

backend, fmi, callbacks = "native/" if sys.argv[1] == "native" else "", int(sys.argv[2]), sys.argv[3]
path = str(DIST / backend / ("fmi3/" if fmi == 3 else "") / "PogoStick.fmu")
md = read_model_description(path)
unzipped = extract(path)
if sys.argv[4:] == ["sweep"]:
    from pogofmu.sweep import Runner, Settings

    row, _ = Runner(path).run({"k": 100.0}, Settings(stop_time=0.01))
    assert row["status"] == "ok", row
else:
    simulate_fmu(unzipped, model_description=md, stop_time=0.01, logger=lambda *message: None)
gc.collect()  # the logger's ctypes function is freed now; the proxy still points at it

getter = "fmi2GetReal" if fmi == 2 else "fmi3GetFloat64"
if callbacks == "own":
    inst = RawInstance(backend, fmi, unzip_dir=unzipped)
    inst.enter_initialization()
    inst.exit_initialization()
    fmu, messages = inst.fmu, inst.messages
else:
    fmu = instantiate_fmu(unzipped, md, "CoSimulation")
    if fmi == 2:
        fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    messages = None  # fmpy's default logger prints; its messages are not collected
unknown, out = (ctypes.c_uint32 * 1)(9999), (ctypes.c_double * 1)()
status = raw_call(fmu, getter, *((unknown, 1, out) if fmi == 2 else (unknown, 1, out, 1)))
fmu.freeInstance()
print(json.dumps({"status": status, "messages": [text for _, text in messages] if messages is not None else None}))
