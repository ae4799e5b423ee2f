"""Run an SSP package under libcosimpy (CosimExecution.from_ssp_file) and print JSON samples.

``python -m pogofmu.ssp.libcosim_runner '<json>'``, in a process of its own (a native crash stays out
of the caller): used by tests/test_ssp.py and ``pogofmu study coupling`` (libcosimpy is a test
dependency; the study leaves libcosim out where it is not installed).
libcosim applies, for every component, the *first* ParameterBinding of the .ssd (its parameter
set ""), steps with its fixed-step algorithm (Jacobi: every slave steps from the same time, the
outputs are transferred afterwards) and takes times in nanoseconds.

Input (argv[1], JSON, or ``-``: the JSON on stdin): {"ssp": path, "step": s, "times": [t1, t2, ...]
(or "n_steps": n for the times step, 2 step, ... n step), "variables": {"Component": ["var", ...]}}
Output (last line of stdout, JSON): {"ok": bool, "samples": {"Component.var": [v(t1), v(t2), ...]}}
"""
import json
import sys

from libcosimpy.CosimEnums import CosimVariableType
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver


def main():
    args = json.loads(sys.stdin.read() if sys.argv[1] == "-" else sys.argv[1])
    if "times" not in args:
        args["times"] = [k * args["step"] for k in range(1, int(args["n_steps"]) + 1)]
    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_ssp_file(ssp_path=args["ssp"], step_size=int(round(args["step"] * 1e9)))
    obs = CosimObserver.create_last_value()
    ex.add_observer(observer=obs)
    index = {s.name.decode(): s.index for s in ex.slave_infos()}
    refs = {}
    for comp, names in args["variables"].items():
        i = index[comp]
        variables = {v.name.decode(): v for v in ex.slave_variables(i)}
        for n in names:
            refs[f"{comp}.{n}"] = (i, variables[n])
    samples = {k: [] for k in refs}
    ok = True
    for t in args["times"]:
        ok = ex.simulate_until(target_time=int(round(t * 1e9))) and ok
        for key, (i, v) in refs.items():
            if v.type == CosimVariableType.REAL.value:
                samples[key].append(obs.last_real_values(i, [v.reference])[0])
            else:
                samples[key].append(obs.last_integer_values(i, [v.reference])[0])
    print(json.dumps({"ok": bool(ok), "samples": samples}))


if __name__ == "__main__":
    main()
