"""Run by tests/test_portability.py in a venv holding only fmpy and numpy (no pogofmu, no
pythonfmu): several of the project's FMUs in one plain fmpy process.  Writes a JSON summary."""
import json
import sys

from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave

job = json.loads(sys.argv[1])
out = {"project_importable": []}
for module in ("pogofmu", "pythonfmu"):
    try:
        __import__(module)
        out["project_importable"].append(module)
    except ImportError:
        pass


def path(name):
    return f"{job['dist']}/{name}.fmu"


# 1. one after the other (fmpy extracts each FMU to a new folder and deletes it afterwards);
#    PogoStick again at the end, after its first folder is gone
out["sequential"] = []
for name in job["fmus"] + ["PogoStick"]:
    md = read_model_description(path(name))
    res = simulate_fmu(path(name), output_interval=float(md.defaultExperiment.stepSize))
    out["sequential"].append({"name": name, "result": {
        "stop": float(res["time"][-1]), "n_events": int(res["n_events"][-1]),
        "t_last_event": float(res["t_last_event"][-1])}})


class Stepper:
    """One instance stepped by hand, so that several live in the process at the same time."""

    def __init__(self, fmu, name):
        self.md = read_model_description(fmu)
        self.dir = extract(fmu)
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.dir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.t = 0.0
        self.k = 0

    def step(self, h):
        """On fmpy's grid: the k-th point is k*h (not a running sum)."""
        self.k += 1
        t_next = self.k * h
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=t_next - self.t)
        self.t = t_next

    def get(self, name):
        v = self.vars[name]
        return (self.fmu.getReal if v.type == "Real" else self.fmu.getInteger)([v.valueReference])[0]

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


# 2. three different models alive at once, stepped in turn
models = ["PogoStick", "PogoStickSMA", "Penetrator"]
live = [Stepper(path(n), n) for n in models]
for _ in range(2000):
    for s in live:
        s.step(1e-3)
out["simultaneous"] = {n: {"n_events": int(s.get("n_events")), "t_last_event": s.get("t_last_event"),
                           "y": s.get("y")} for n, s in zip(models, live)}
for s in live:
    s.close()

# 3. the same model from two versions of the project, alive at once
current, other = Stepper(path("PogoStick"), "current"), Stepper(job["other"], "other")
for _ in range(1000):
    current.step(1e-2)
    other.step(1e-2)
packages = {name: m for name, m in sys.modules.items()
            if name.startswith("_pogofmu_PogoStick_") and "." not in name and not name.endswith("_slave")}
out["two_versions"] = {
    "current": {"n_events": int(current.get("n_events")), "stop": round(current.t, 9)},
    "other": {"n_events": int(other.get("n_events")), "stop": round(other.t, 9)},
    "packages": {name: m.__version__ for name, m in packages.items()},
    "package_folders": {name: m.__path__[0] for name, m in packages.items()},
    "unzipdirs": [str(current.dir), str(other.dir)],
}
current.close()
other.close()
with open(job["out"], "w") as f:
    json.dump(out, f)
