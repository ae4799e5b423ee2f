"""The native FMUs: dist/native/<Model>.fmu, the same FMU as dist/<Model>.fmu without Python.

* the binary needs the C library and libm only (no libpython, no Py* symbol) and the
  modelDescription is the Python-hosted FMU's (every variable, value reference, unit, start value,
  capability and dependency), but for its own instantiation token;
* a C host of the project's own, in an empty environment, runs every default experiment with the
  outputs of the Python-hosted FMU through fmpy, to the bit (the events with them);
* a virtual environment with fmpy only simulates the native FMUs;
* refusals (bad parameters, bad steps, inputs, calls out of order) give the Python-hosted FMU's
  statuses and messages, word for word.

The rest of the conformance suite runs on both backends in tests/test_conformance.py.
"""
import json
import math
import subprocess
import zipfile

import numpy as np
import pytest

from pogofmu import exporter as build
from support import DIST, Instance, clean_venv, compile_c_host, fmu_path, simulate
from test_portability import BARE_ENV, C_HOST_SOURCE, outputs_of, run_c_host

FMUS = build.model_names()


@pytest.fixture(scope="module")
def c_host(tmp_path_factory):
    return compile_c_host(C_HOST_SOURCE, tmp_path_factory.mktemp("native_host") / "fmi2_host")


@pytest.fixture(scope="module")
def unzipped(tmp_path_factory):
    cache = {}

    def get(name):
        if name not in cache:
            d = tmp_path_factory.mktemp(name.replace("/", "_"))
            with zipfile.ZipFile(fmu_path(name)) as z:
                z.extractall(d)
            cache[name] = d
        return cache[name]
    return get


@pytest.mark.parametrize("folder, platform", [("native", "linux64"), ("native/fmi3", "x86_64-linux")],
                         ids=["fmi2", "fmi3"])
@pytest.mark.parametrize("name", FMUS)
def test_the_binary_needs_only_the_c_library(name, folder, platform, unzipped):
    lib = unzipped(f"{folder}/{name}") / "binaries" / platform / f"{name}.so"
    dynamic = subprocess.run(["readelf", "-d", str(lib)], capture_output=True, text=True, check=True).stdout
    needed = {line.split("[")[1].split("]")[0] for line in dynamic.splitlines() if "(NEEDED)" in line}
    assert needed <= {"libc.so.6", "libm.so.6"}, needed
    undefined = subprocess.run(["nm", "-D", "--undefined-only", str(lib)], capture_output=True, text=True,
                               check=True).stdout.split()
    assert not [s for s in undefined if s.startswith(("Py", "_Py", "dlopen"))], undefined
    # every math function the model calls (itself or through pg_support.c's checked pg_<f>), and pow
    # (the engine's step control, when the model has states to step), comes from the C library, as in
    # the Python-hosted FMU: none bundled by the compiler's runtime (zig's, linked for a 128-bit
    # division, carries its own exp and log, whose last bits differ). (Not every function pg_support.c
    # wraps: the link-time optimized binary keeps only what is called.)
    import re

    from pogofmu.runtime.models import get

    code = (unzipped(f"{folder}/{name}") / "sources" / f"{name}_model.c").read_text()
    code = re.sub(r'"(\\.|[^"\\])*"', '""', re.sub(r"/\*.*?\*/|//[^\n]*", " ", code, flags=re.S))
    called = {f for f in ("exp", "log", "sin", "cos", "sqrt", "floor", "fmod") if re.search(rf"\b(pg_)?{f}\(", code)}
    if get(name).states:
        called.add("pow")
    imported = {s.split("@")[0] for s in undefined}
    assert called <= imported, sorted(called - imported)
    with zipfile.ZipFile(fmu_path(f"{folder}/{name}")) as z:
        assert not [n for n in z.namelist() if n.startswith("resources/") and n.endswith(".py")]


def _description(name):
    import xml.etree.ElementTree as ET

    with zipfile.ZipFile(fmu_path(name)) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


@pytest.mark.parametrize("name", FMUS)
def test_the_model_description_is_the_python_hosted_fmus(name):
    import xml.etree.ElementTree as ET

    a, b = _description(name), _description(f"native/{name}")
    assert a.get("guid") != b.get("guid")  # each build has its own token
    cs = b.find("CoSimulation")
    files = cs.find("SourceFiles")  # a source FMU too: its compilation units
    with zipfile.ZipFile(fmu_path(f"native/{name}")) as z:
        units = sorted(n[len("sources/"):] for n in z.namelist() if n.startswith("sources/") and n.endswith(".c"))
    assert sorted(f.get("name") for f in files) == units and f"{name}_model.c" in units
    cs.remove(files)
    cs.text = a.find("CoSimulation").text  # (the whitespace that held <SourceFiles>)
    assert cs.attrib.pop("providesDirectionalDerivative") == "true"  # (the native FMUs provide them)
    assert a.find("CoSimulation").attrib.pop("providesDirectionalDerivative") == "false"
    for root in (a, b):
        for key in ("guid", "generationDateAndTime"):
            root.attrib.pop(key, None)
    assert ET.tostring(a) == ET.tostring(b)


@pytest.mark.parametrize("name", FMUS)
def test_a_c_host_in_an_empty_environment_gives_the_python_fmus_outputs(name, c_host, unzipped):
    """No Python anywhere: the project's C host (dlopen, no libpython) with an empty environment
    runs the native FMU's default experiment; every output at every communication point equals
    the Python-hosted FMU's under fmpy, to the bit — so the event times and counts are its."""
    from fmpy import read_model_description

    md = read_model_description(str(fmu_path(name)))
    stop, step = float(md.defaultExperiment.stopTime), float(md.defaultExperiment.stepSize)
    outputs = outputs_of(name)
    nat = read_model_description(str(fmu_path(f"native/{name}")))
    assert nat.guid != md.guid
    rc, rows, err = run_c_host(c_host, unzipped(f"native/{name}"), name, stop, step, outputs, env=BARE_ENV, md=nat)
    assert rc == 0, err[-3000:]
    ref = simulate(name).res
    assert len(rows) == len(ref)
    for out in outputs:
        got = [r[out] for r in rows]
        assert got == list(ref[out]), f"{name}.{out}: the native FMU differs from the Python-hosted one"
    if name != "HopController":
        assert rows[-1]["n_events"] > 5


def test_a_venv_with_fmpy_only_simulates_the_native_fmus(tmp_path):
    python = clean_venv()
    script = tmp_path / "run.py"
    script.write_text(
        "import json, sys\n"
        "from fmpy import simulate_fmu\n"
        "out = {}\n"
        "for path in sys.argv[1:]:\n"
        "    r = simulate_fmu(path, output_interval=1e-3)\n"
        "    out[path] = {n: float(r[n][-1]) for n in r.dtype.names}\n"
        "print(json.dumps(out))\n")
    paths = [str(fmu_path(f"native/{n}")) for n in FMUS]
    proc = subprocess.run([str(python), "-I", str(script), *paths], capture_output=True, text=True, timeout=600,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    for n, path in zip(FMUS, paths):
        ref = simulate(n, output_interval=1e-3).res
        assert got[path] == {c: float(ref[c][-1]) for c in ref.dtype.names}, n


def _refusals(name, script):
    """Run ``script(inst)`` on a fresh instance; the (status, text) of every warning and error."""
    from fmpy.fmi1 import FMICallException

    inst = Instance(name)
    try:
        try:
            script(inst)
        except FMICallException:
            pass
        return [(s, text) for s, _, text in inst.messages if s >= 1]
    finally:
        inst.close()


BAD = [
    {"m": 0.0}, {"m": -1.0}, {"k": -5.0}, {"c": -0.1}, {"x_i": 0.0}, {"y_0": -0.5}, {"z_0": 0.4}, {"g": math.nan},
    {"rel_tol": 0.0}, {"method": 4}, {"abs_tol": 1.0}, {"max_step": 1e-9}, {"k": 1e300}, {"m": 1e-300},
    {"g": 1e300}, {"max_steps_per_second": 5.0}, {"log_events": 2}, {"initial_step": -1.0},
]


@pytest.mark.parametrize("values", BAD, ids=lambda v: ",".join(f"{k}={v[k]}" for k in v))
def test_bad_parameters_are_refused_with_the_python_fmus_words(values):
    def script(inst):
        inst.init(**values)
    a, b = _refusals("PogoStick", script), _refusals("native/PogoStick", script)
    assert a and a == b


@pytest.mark.parametrize("name", FMUS)
def test_refused_calls_and_failures_are_the_python_fmus(name):
    """Calls out of order, an unknown value reference, a wrong type, a parameter after
    initialization, bad steps, a NaN input, a leg that bottoms out and the step after it."""
    from fmpy.fmi1 import FMICallException

    model = build.slave_class(name).model

    def script(inst):
        for call in (lambda: inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3),
                     lambda: inst.fmu.getReal([9999]), lambda: inst.fmu.getInteger([0])):
            try:
                call()
            except FMICallException:
                pass
        params = {}
        if "k" in inst.vars and model.states:
            params = {"k": 1.0}  # a soft leg: it bottoms out
        inst.init(**params)
        for call in (lambda: inst.set(m=2.0),
                     lambda: inst.fmu.doStep(currentCommunicationPoint=0.5, communicationStepSize=1e-3),
                     lambda: inst.fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=-1.0)):
            try:
                call()
            except FMICallException:
                pass
        if model.inputs and model.inputs[0].name not in model.integer_inputs:
            inst.set(**{model.inputs[0].name: math.nan})
            try:
                inst.step(1e-3)
            except FMICallException:
                pass
            inst.set(**{model.inputs[0].name: 0.0})
        for _ in range(4000):
            inst.step(1e-3)
    a, b = _refusals(name, script), _refusals(f"native/{name}", script)
    assert len(a) >= 5 and a == b


def test_the_event_log_is_the_python_fmus():
    run_a = simulate("PogoStickSMA", start_values={"log_events": 1})
    run_b = simulate("native/PogoStickSMA", start_values={"log_events": 1})
    events_a = [m for m in run_a.messages if m[1] == "logEvents"]
    assert len(events_a) > 10 and events_a == [m for m in run_b.messages if m[1] == "logEvents"]
    assert np.array_equal(run_a["t_last_event"], run_b["t_last_event"])


def test_every_native_fmu_was_built():
    assert sorted(p.stem for p in (DIST / "native").glob("*.fmu")) == FMUS


# ---- FMI 3.0 (dist/native/fmi3/) --------------------------------------------------------------

@pytest.mark.parametrize("name", FMUS)
def test_the_fmi3_model_description_is_the_python_hosted_fmus(name):
    """Model exchange and co-simulation, every variable (states, derivatives, indicators, time),
    the same; the token differs, and sources/buildDescription.xml lists the compilation units."""
    import xml.etree.ElementTree as ET

    a, b = _description(f"fmi3/{name}"), _description(f"native/fmi3/{name}")
    assert a.get("instantiationToken") != b.get("instantiationToken")
    for interface in ("ModelExchange", "CoSimulation"):  # (the native FMUs provide directional derivatives)
        assert b.find(interface).attrib.pop("providesDirectionalDerivatives") == "true"
        assert a.find(interface).attrib.pop("providesDirectionalDerivatives") == "false"
    for root in (a, b):
        for key in ("instantiationToken", "generationDateAndTime"):
            root.attrib.pop(key, None)
    assert ET.tostring(a) == ET.tostring(b)
    with zipfile.ZipFile(fmu_path(f"native/fmi3/{name}")) as z:
        units = sorted(n[len("sources/"):] for n in z.namelist() if n.startswith("sources/") and n.endswith(".c"))
        described = ET.fromstring(z.read("sources/buildDescription.xml"))
    listed = sorted(f.get("name") for f in described.iter("SourceFile"))
    assert listed == units and described.find("BuildConfiguration").get("modelIdentifier") == name


FMI3_RUNS = {  # fmpy simulate_fmu keywords: each way of running an FMI 3.0 FMU
    "cs": dict(fmi_type="CoSimulation"),
    "cs-early-return": dict(fmi_type="CoSimulation", early_return_allowed=True),
    "cs-event-mode": dict(fmi_type="CoSimulation", early_return_allowed=True, use_event_mode=True),
    "me-cvode": dict(fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-8),
}


@pytest.mark.parametrize("run", list(FMI3_RUNS))
@pytest.mark.parametrize("name", FMUS)
def test_fmi3_runs_give_the_python_fmus_outputs(name, run):
    """Through fmpy, each interface and co-simulation mode of the native FMI 3.0 FMU gives the
    Python-hosted FMI 3.0 FMU's rows, every column to the bit (model exchange: the same CVode steps
    because the same derivatives and indicators, to the bit)."""
    from fmpy import read_model_description, simulate_fmu

    md = read_model_description(str(fmu_path(f"fmi3/{name}")))
    stop = float(md.defaultExperiment.stopTime)
    kw = dict(FMI3_RUNS[run], stop_time=stop, output_interval=1e-3)
    a = simulate_fmu(str(fmu_path(f"fmi3/{name}")), **kw)
    b = simulate_fmu(str(fmu_path(f"native/fmi3/{name}")), **kw)
    assert a["time"][-1] == pytest.approx(stop) and len(a) == len(b)
    for column in a.dtype.names:
        assert np.array_equal(a[column], b[column]), f"{name} {run}: {column} differs"
    if name != "HopController":
        assert b["n_events"][-1] > 5
