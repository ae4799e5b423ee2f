"""Units on connections (docs/ssp-master.md, "Units"): in SSP a connector's unit is optional and an
FMU variable without a unit has no unit to convert, so either connects to any unit as it is (no
conversion, as libcosim and OMSimulator do); two units both declared and different are refused.

The system: the project's PogoStick (``y`` in m) and HopController (inputs in m and m/s), and Tally, a model file written
here and exported by ``pogofmu export`` as a user does, whose variables have no unit: it integrates
its input ``u`` and wraps its integral ``z`` back to 0 at ``z_max`` (an event, counted in ``n``).
``PogoStick.y -> Tally.u`` (the stick's connector written without a unit), ``Tally.z ->
HopController.ydot`` (m/s) and ``PogoStick.y -> HopController.y`` (m to m). The values must cross unchanged: ``z`` is checked against the trapezoidal
integral of the recorded ``y``."""
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from support import DIST, run_pogofmu

from pogofmu import ssp as master

TALLY = '''
from pogofmu import RISING, Event, HybridModel, Parameter, Variable

z = Variable("z", "", "integral of the input, wrapped at z_max")

MODEL = HybridModel(
    name="Tally",
    description="the integral of its input, wrapped to 0 at z_max (no units anywhere)",
    states=(z,),
    parameters=(Parameter("z_max", 0.5, "", "the level z wraps at"),),
    inputs=(Variable("u", "", "the integrand"),),
    outputs=(z, Variable("n", "", "wraps so far")),
    flow=lambda t, x, q, u, p: [u[0]],
    events=(Event("wrap", RISING, guard=lambda x, q, u, p: x[0] - p.z_max,
                  jump=lambda x, q, u, p: ([0.0], {"n": q["n"] + 1})),),
    initial=lambda p: ([0.0], {"n": 0}),
    output_fn=lambda t, x, q, u, p: {"z": x[0], "n": q["n"]},
    integer_outputs=frozenset({"n"}),
    default_stop_time=1.0,
)
'''

SSD = '''<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="{version}" name="Units">
  <ssd:System name="Units">
    <ssd:Elements>
      <ssd:Component name="PogoStick" source="resources/PogoStick.fmu" type="application/x-fmu-sharedlibrary">
        <ssd:Connectors>
          <ssd:Connector name="y" kind="output"><ssc:{real}{y_unit}/></ssd:Connector>
          <ssd:Connector name="ydot" kind="output"><ssc:{real}/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
      <ssd:Component name="Tally" source="resources/Tally.fmu" type="application/x-fmu-sharedlibrary">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"><ssc:{real}{u_unit}/></ssd:Connector>
          <ssd:Connector name="z" kind="output"><ssc:{real}/></ssd:Connector>
          <ssd:Connector name="n" kind="output"><ssc:{integer}/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
      <ssd:Component name="HopController" source="resources/HopController.fmu" type="application/x-fmu-sharedlibrary">
        <ssd:Connectors>
          <ssd:Connector name="y" kind="input"><ssc:{real}/></ssd:Connector>
          <ssd:Connector name="ydot" kind="input"><ssc:{real} unit="m/s"/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="PogoStick" startConnector="y" endElement="Tally" endConnector="u"/>
      <ssd:Connection startElement="Tally" startConnector="z" endElement="HopController" endConnector="ydot"/>
      <ssd:Connection startElement="PogoStick" startConnector="{to_controller}" endElement="HopController" endConnector="y"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="2"/>
</ssd:SystemStructureDescription>
'''


@pytest.fixture(scope="module")
def tally(tmp_path_factory):
    """Tally exported by ``pogofmu export`` (FMI 2.0 and 3.0, Python-hosted and native): its folder."""
    d = tmp_path_factory.mktemp("tally")
    (d / "tally.py").write_text(TALLY)
    proc = run_pogofmu("export", "tally.py", "--out", "fmus", cwd=d, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return d / "fmus"


def package(tmp_path, tally, fmi, backend="", y_unit="", u_unit="", to_controller="y"):
    """The system as an unpacked SSP (1.0 with FMI 2.0 FMUs, 2.0 with FMI 3.0 ones)."""
    sub = backend + ("fmi3/" if fmi == 3 else "")
    d = tmp_path / f"pkg{fmi}{backend.strip('/')}"
    (d / "resources").mkdir(parents=True)
    for name in ("PogoStick", "HopController"):
        (d / "resources" / f"{name}.fmu").write_bytes((DIST / sub / f"{name}.fmu").read_bytes())
    (d / "resources" / "Tally.fmu").write_bytes((tally / sub / "Tally.fmu").read_bytes())
    unit = lambda u: f' unit="{u}"' if u else ""  # noqa: E731
    (d / "SystemStructure.ssd").write_text(SSD.format(
        version="2.0" if fmi == 3 else "1.0", real="Float64" if fmi == 3 else "Real",
        integer="Int32" if fmi == 3 else "Integer", y_unit=unit(y_unit), u_unit=unit(u_unit),
        to_controller=to_controller))
    return d


def the_fmus_declare_no_unit(tally):
    from fmpy import read_model_description

    for sub in ("", "fmi3/"):
        md = read_model_description(str(tally / sub / "Tally.fmu"))
        assert all(getattr(v, "unit", None) is None and getattr(v, "declaredType", None) is None
                   for v in md.modelVariables if v.name in ("u", "z")), sub


CASES = [(2, "", "gauss-seidel", True), (2, "", "jacobi", True), (3, "", "gauss-seidel", True),
         (3, "", "jacobi", True), (2, "native/", "gauss-seidel", True), (3, "native/", "jacobi", True),
         (2, "", "gauss-seidel", False)]


@pytest.mark.parametrize("fmi, backend, algorithm, events", CASES)
def test_a_variable_or_connector_without_a_unit_connects_without_conversion(tmp_path, tally, fmi, backend,
                                                                            algorithm, events):
    the_fmus_declare_no_unit(tally)
    pkg = package(tmp_path, tally, fmi, backend)
    res = master.simulate(pkg, stop_time=2.0, step=1e-3, algorithm=algorithm, events=events)
    grid = res["event"] == 0
    t, y, z, n = res["time"][grid], res["PogoStick.y"][grid], res["Tally.z"][grid], res["Tally.n"][grid]
    assert n[-1] >= 2 and (res["event"] != 0).any() == events  # Tally wrapped; the events located or not
    # the values cross as they are: each input holds its source's output, no factor
    assert np.array_equal(res["Tally.u"], res["PogoStick.y"])
    assert np.array_equal(res["HopController.ydot"], res["Tally.z"])
    # Tally integrates the stick's height as it is: z = integral of y - z_max n, to the coupling
    # delay of one step (h max|y| = 1.2e-3) and the trapezoidal rule
    integral = np.concatenate([[0.0], np.cumsum(np.diff(t) * (y[1:] + y[:-1]) / 2)])
    assert np.max(np.abs(z - (integral - 0.5 * n))) < 3e-3


@pytest.mark.parametrize("fmi", [2, 3])
def test_units_both_declared_and_different_are_refused(tmp_path, tally, fmi):
    # two connectors' units
    pkg = package(tmp_path / "a", tally, fmi, y_unit="m", u_unit="s")
    with pytest.raises(master.SSPError, match=r"Connection 1 \(PogoStick.y -> Tally.u\): unit mismatch: "
                                              r"PogoStick.y is in 'm', Tally.u in 's' \(no unit conversion\)"):
        master.simulate(pkg, stop_time=0.01, step=1e-3)
    # a connector's unit against its FMU's
    pkg = package(tmp_path / "b", tally, fmi, y_unit="s")
    with pytest.raises(master.SSPError, match=r"Connector PogoStick.y: unit mismatch: connector unit 's', "
                                              r"FMU unit 'm'"):
        master.simulate(pkg, stop_time=0.01, step=1e-3)
    # connectors without units between two FMU variables whose units differ (m/s and m)
    pkg = package(tmp_path / "c", tally, fmi, to_controller="ydot")
    proc = subprocess.run([sys.executable, "-m", "pogofmu.ssp", "check", str(pkg)], capture_output=True, text=True)
    assert proc.returncode == 1, proc
    assert proc.stderr.endswith("\n") and "Traceback" not in proc.stderr, proc.stderr
    assert ("Connection 3 (PogoStick.ydot -> HopController.y): unit mismatch: PogoStick.ydot is in 'm/s', "
            "HopController.y in 'm' (no unit conversion)") in proc.stderr, proc.stderr


def test_the_check_command_accepts_units_left_out(tmp_path, tally):
    pkg = package(tmp_path, tally, 2)
    proc = subprocess.run([sys.executable, "-m", "pogofmu.ssp", "check", str(pkg)], capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stderr == "", proc
    assert proc.stdout.endswith("\n") and proc.stdout.count("\n") == 1 and "is valid" in proc.stdout, proc.stdout
