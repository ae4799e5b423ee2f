"""Run one FMU under libcosimpy (an independent FMI importer) and print its final outputs as JSON.

Called by tests/support.py in a separate process: libcosim writes a lot to stderr and any crash
of a native library stays out of the test process.  Times are given to libcosim in nanoseconds.
"""
import json
import sys

from libcosimpy.CosimEnums import CosimVariableType
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave


def main():
    args = json.loads(sys.argv[1])
    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_step_size(step_size=int(round(args["step"] * 1e9)))
    slave = CosimLocalSlave(fmu_path=args["fmu"], instance_name="unit")
    idx = ex.add_local_slave(local_slave=slave)
    obs = CosimObserver.create_last_value()
    ex.add_observer(observer=obs)
    variables = {v.name.decode(): v for v in ex.slave_variables(idx)}
    for name, value in args["initial"].items():
        v = variables[name]
        if v.type == CosimVariableType.REAL.value:
            ex.real_initial_value(idx, v.reference, float(value))
        else:
            ex.integer_initial_value(idx, v.reference, int(value))
    ok = ex.simulate_until(target_time=int(round(args["stop_time"] * 1e9)))
    out = {}
    for name in args["outputs"]:
        v = variables[name]
        if v.type == CosimVariableType.REAL.value:
            out[name] = obs.last_real_values(idx, [v.reference])[0]
        else:
            out[name] = obs.last_integer_values(idx, [v.reference])[0]
    out["_ok"] = bool(ok)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
