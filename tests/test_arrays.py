"""Array inputs and outputs (``Variable(..., shape=(N,))``), on examples/array_gain/array_gain.py:
one FMI 3.0 variable with ``<Dimension>`` whose values ``fmi3Get/SetFloat64`` count element by
element (both backends: the entry file expands an array's value reference), the scalars
``z[1]`` ... ``z[N]`` in FMI 2.0, directional derivatives seeded per element, and the checks of a
model file that refuse a bad declaration.

The reference is the model's closed form, written here: for constant inputs
``r[i] = g z[i] + w i``, ``y(t) = y_0 + t (z[1] + 2 z[2] + 3 z[3]) / tau`` (tau = 1 s), ``s = [y, 2 y]``.
"""
from __future__ import annotations

import ctypes
import textwrap
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from support import fmu_path, run_pogofmu

ROOT = Path(__file__).resolve().parents[1]
G, Y0 = 2.0, 0.5  # the example's defaults
Z, W = [1.0, -2.5, 0.75], 0.25


def closed_form(t, z=Z, w=W, g=G, y0=Y0):
    y = y0 + t * (z[0] + 2.0 * z[1] + 3.0 * z[2])
    return [g * z[i] + w * (i + 1) for i in range(3)], y, [y, 2.0 * y]


def _fmu3(name, messages, model_exchange=False):
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Model, FMU3Slave

    path = fmu_path(name)
    md = read_model_description(str(path))
    cls, iface = (FMU3Model, md.modelExchange) if model_exchange else (FMU3Slave, md.coSimulation)
    fmu = cls(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=iface.modelIdentifier,
              instanceName="arrays")
    fmu.instantiate(loggingOn=True, logMessage=lambda env, st, cat, msg: messages.append((st, msg.decode())))
    return fmu, {v.name: v for v in md.modelVariables}


FMI3 = ["examples/fmi3/ArrayGain", "examples/native/fmi3/ArrayGain"]


@pytest.mark.parametrize("name", FMI3)
def test_fmi3_description_declares_arrays_and_validates(name):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    path = str(fmu_path(name))
    assert validate_fmu(path) == []  # fmpy's schema and its checks of the model description
    md = read_model_description(path)
    dims = {v.name: [int(d.start) for d in v.dimensions] for v in md.modelVariables if v.dimensions}
    assert dims == {"z": [3], "r": [3], "s": [2]}
    assert not any("[" in v.name for v in md.modelVariables)
    with zipfile.ZipFile(path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    vr = {v.get("name"): v.get("valueReference") for v in root.find("ModelVariables")}
    assert root.find("ModelVariables/Float64[@name='z']").get("start") == "0.0 0.0 0.0"
    outputs = {o.get("valueReference"): o.get("dependencies").split() for o in root.iter("Output")}
    assert sorted(outputs[vr["r"]]) == sorted([vr["z"], vr["w"]])  # on whole variables
    assert outputs[vr["s"]] == [vr["y"]]
    der = root.find("ModelStructure/ContinuousStateDerivative")
    assert der.get("dependencies").split() == [vr["z"]]


@pytest.mark.parametrize("name", FMI3)
def test_fmi3_get_set_arrays_against_the_closed_form(name):
    messages = []
    fmu, v = _fmu3(name, messages)
    fmu.enterInitializationMode()
    fmu.setFloat64([v["z"].valueReference, v["w"].valueReference], Z + [W])  # nValues = 4
    fmu.exitInitializationMode()
    read = [v["r"].valueReference, v["y"].valueReference, v["s"].valueReference]
    r, y, s = closed_form(0.0)
    assert fmu.getFloat64(read, nValues=6) == r + [y] + s
    assert fmu.getFloat64([v["z"].valueReference], nValues=3) == Z
    t, h = 0.0, 0.125
    for _ in range(8):
        fmu.doStep(t, h)
        t += h
    r, y, s = closed_form(t)
    got = fmu.getFloat64(read, nValues=6)
    assert got[:3] == r and abs(got[3] - y) < 1e-12 and abs(got[4] - s[0]) < 1e-12 and abs(got[5] - s[1]) < 1e-12
    # an input array set while stepping: the outputs that feed through follow it
    fmu.setFloat64([v["z"].valueReference], [0.0, 1.0, 2.0])
    fmu.doStep(t, h)
    assert fmu.getFloat64([v["r"].valueReference], nValues=3) == [W, 2.0 + 2 * W, 4.0 + 3 * W]
    fmu.terminate()
    fmu.freeInstance()
    assert not [m for m in messages if m[0] >= 3], messages


def _raw(fmu, function, vrs, n_values):
    f = getattr(fmu.dll, function)
    f.restype = ctypes.c_int
    f.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_size_t]
    buf = (ctypes.c_double * max(n_values, 8))()
    return f(fmu.component, (ctypes.c_uint32 * len(vrs))(*vrs), len(vrs), buf, n_values)


@pytest.mark.parametrize("name", FMI3)
def test_nvalues_that_do_not_count_the_elements_are_refused(name):
    messages = []
    fmu, v = _fmu3(name, messages)
    fmu.enterInitializationMode()
    z, w = v["z"].valueReference, v["w"].valueReference
    for function in ("fmi3GetFloat64", "fmi3SetFloat64"):
        for vrs, n in (([z], 1), ([z, w], 2), ([z, w], 5)):
            assert _raw(fmu, function, vrs, n) == 3
            text = messages[-1][1]
            assert "\n" not in text and f"{function} refused: nValues = {n}" in text and \
                f"hold {3 + len(vrs) - 1} values" in text and f"value reference {z} is an array of 3" in text, text
        # an element's own value reference is not an FMI 3.0 variable
        assert _raw(fmu, function, [z + 1], 1) == 3
        assert f"value reference {z + 1} is not a variable" in messages[-1][1]
    assert _raw(fmu, "fmi3GetFloat64", [z, w], 4) == 0  # still usable
    fmu.exitInitializationMode()
    fmu.terminate()
    fmu.freeInstance()


def test_native_and_python_hosted_give_the_same_bits():
    results = []
    for name in FMI3:
        fmu, v = _fmu3(name, [])
        fmu.enterInitializationMode()
        fmu.setFloat64([v["z"].valueReference, v["w"].valueReference], Z + [W])
        fmu.exitInitializationMode()
        t, rows = 0.0, []
        for k in range(5):
            fmu.setFloat64([v["z"].valueReference], [Z[0] + k, Z[1] * k, 0.1 * k])
            fmu.doStep(t, 0.1)
            t += 0.1
            rows.append(fmu.getFloat64([v["r"].valueReference, v["s"].valueReference], nValues=5))
        fmu.terminate()
        fmu.freeInstance()
        results.append(rows)
    assert results[0] == results[1]


def test_model_exchange_with_arrays():
    messages = []
    fmu, v = _fmu3("examples/native/fmi3/ArrayGain", messages, model_exchange=True)
    fmu.enterInitializationMode()
    fmu.setFloat64([v["z"].valueReference], Z)
    fmu.exitInitializationMode()
    fmu.enterContinuousTimeMode()
    der = (ctypes.c_double * 1)()
    fmu.getContinuousStateDerivatives(der, 1)
    assert list(der) == [Z[0] + 2 * Z[1] + 3 * Z[2]]
    fmu.setContinuousStates((ctypes.c_double * 1)(3.0), 1)
    assert fmu.getFloat64([v["s"].valueReference], nValues=2) == [3.0, 6.0]
    fmu.terminate()
    fmu.freeInstance()


def test_directional_derivatives_are_per_element():
    """Native FMI 3.0: the seeds and sensitivities of an array are one per element (the standard's
    rule): d r / d z = g I, d der(y) / d z = [1 2 3], d s / d y = [1 2]."""
    messages = []
    fmu, v = _fmu3("examples/native/fmi3/ArrayGain", messages, model_exchange=True)
    fmu.enterInitializationMode()
    fmu.setFloat64([v["z"].valueReference], Z)
    fmu.exitInitializationMode()
    f = fmu.dll.fmi3GetDirectionalDerivative
    f.restype = ctypes.c_int
    f.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_size_t,
                  ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_size_t]

    def dd(unknowns, n_unknown, knowns, seed):
        out = (ctypes.c_double * n_unknown)()
        st = f(fmu.component, (ctypes.c_uint32 * len(unknowns))(*unknowns), len(unknowns),
               (ctypes.c_uint32 * len(knowns))(*knowns), len(knowns), (ctypes.c_double * len(seed))(*seed),
               len(seed), out, n_unknown)
        return st, list(out)

    r, z, der, y, s = (v[n].valueReference for n in ("r", "z", "der(y)", "y", "s"))
    for j in range(3):
        seed = [1.0 if i == j else 0.0 for i in range(3)]
        assert dd([r], 3, [z], seed) == (0, [G * e for e in seed])
        assert dd([der], 1, [z], seed) == (0, [float(j + 1)])
    assert dd([s, r], 5, [y], [1.0]) == (0, [1.0, 2.0, 0.0, 0.0, 0.0])
    assert dd([r], 3, [z], [1.0])[0] == 3
    assert "nSeed = 1" in messages[-1][1] and "array of 3" in messages[-1][1]
    fmu.terminate()
    fmu.freeInstance()


@pytest.mark.parametrize("name", ["examples/ArrayGain", "examples/native/ArrayGain"])
def test_fmi2_sees_the_elements_as_scalars(name):
    from fmpy import read_model_description, simulate_fmu

    path = str(fmu_path(name))
    md = read_model_description(path)
    assert md.variableNamingConvention == "structured"
    names = [v.name for v in md.modelVariables if v.causality in ("input", "output")]
    assert names[:8] == ["z[1]", "z[2]", "z[3]", "w", "r[1]", "r[2]", "r[3]", "y"]
    start = {f"z[{i + 1}]": Z[i] for i in range(3)}
    start["w"] = W
    res = simulate_fmu(path, start_values=start, stop_time=1.0, output_interval=0.25,
                       output=["r[1]", "r[2]", "r[3]", "y", "s[1]", "s[2]"])
    for row in res:
        r, y, s = closed_form(row["time"])
        assert [row["r[1]"], row["r[2]"], row["r[3]"]] == r
        assert abs(row["y"] - y) < 1e-12 and abs(row["s[2]"] - s[1]) < 1e-12


BAD = '''\
from pogofmu import HybridModel, Variable

MODEL = HybridModel(
    name="Bad", description="a bad array declaration", states=(), parameters=(),
    inputs=(Variable("z", "", "signals", shape={shape}),),
    outputs=(Variable("r", "", "copies", shape=(2,)),),
    flow=lambda t, x, q, u, p: [], events=(), initial=lambda p: ([], {{}}),
    output_fn=lambda t, x, q, u, p: {{"r": {out}}},
)
'''


@pytest.mark.parametrize("shape, out, expected", [
    ("(0,)", "[u[0], u[0]]", "input 'z' has shape=(0,), which violates the rule: shape=() (a scalar) or shape=(N,)"),
    ("(2, 3)", "[u[0], u[0]]", "input 'z' has shape=(2, 3), which violates the rule"),
    ("(2.0,)", "[u[0], u[0]]", "input 'z' has shape=(2.0,), which violates the rule"),
    ("(2,)", "[u[0], u[1], u[0]]", "output_fn returns r = [0.0, 0.0, 0.0], which violates the rule: r is an array "
                                   "of 2 (shape=(2,)): a list of 2 numbers"),
    ("(2,)", "u[0]", "output_fn returns r = 0.0, which violates the rule: r is an array of 2"),
])
def test_checks_refuse_bad_array_declarations(tmp_path, shape, out, expected):
    f = tmp_path / "bad.py"
    f.write_text(BAD.format(shape=shape, out=out))
    proc = run_pogofmu("export", f, "--check", cwd=tmp_path, timeout=300)
    err = proc.stderr.strip()
    assert proc.returncode == 2 and expected in err and len(err.splitlines()) == 1, err


def test_an_array_state_is_refused(tmp_path):
    f = tmp_path / "bad.py"
    f.write_text(textwrap.dedent('''\
        from pogofmu import HybridModel, Variable
        MODEL = HybridModel(
            name="Bad", description="an array state", states=(Variable("x", "", "x", shape=(2,)),),
            parameters=(), inputs=(), outputs=(), flow=lambda t, x, q, u, p: [0.0], events=(),
            initial=lambda p: ([0.0], {}), output_fn=lambda t, x, q, u, p: {})
        '''))
    proc = run_pogofmu("export", f, "--check", cwd=tmp_path, timeout=300)
    assert proc.returncode == 2 and "state 'x' has shape=(2,), which violates the rule: a state is a scalar" \
        in proc.stderr, proc.stderr


# ---------------------------------------------------------------------------------------------
# SSP 2.0: array connectors (ssc:Dimension) and connections into and out of their elements
# ---------------------------------------------------------------------------------------------

def _connector(name, kind, size=None):
    dim = f'<ssc:Dimension size="{size}"/>' if size else ""
    return f'<ssd:Connector name="{name}" kind="{kind}"><ssc:Float64 unit="m"/>{dim}</ssd:Connector>'


def _two_gains(tmp_path, connections, b_connectors=None):
    """An SSP 2.0 package of two ArrayGain instances A and B (FMI 3.0, native), A's y_0 = 0.25."""
    a = [_connector("y", "output"), _connector("s", "output", 2)]
    b = b_connectors or [_connector("z", "input", 3), _connector("y", "output"), _connector("r", "output", 3)]

    def comp(name, connectors, binding=""):
        return (f'<ssd:Component name="{name}" source="resources/ArrayGain.fmu"><ssd:Connectors>'
                + "".join(connectors) + "</ssd:Connectors>" + binding + "</ssd:Component>")

    ssd = ('<?xml version="1.0" encoding="UTF-8"?>\n'
           '<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
           'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="2.0" name="TwoGains">'
           '<ssd:System name="TwoGains"><ssd:Elements>'
           + comp("A", a, '<ssd:ParameterBindings><ssd:ParameterBinding source="resources/a.ssv"/>'
                          '</ssd:ParameterBindings>')
           + comp("B", b) + "</ssd:Elements><ssd:Connections>" + "".join(
               f'<ssd:Connection {c}/>' for c in connections)
           + '</ssd:Connections></ssd:System><ssd:DefaultExperiment startTime="0" stopTime="1"/>'
           '</ssd:SystemStructureDescription>\n')
    ssv = ('<?xml version="1.0" encoding="UTF-8"?>\n'
           '<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" '
           'version="2.0" name="a"><ssv:Parameters><ssv:Parameter name="y_0"><ssv:Float64 value="0.25"/>'
           '</ssv:Parameter></ssv:Parameters></ssv:ParameterSet>\n')
    path = tmp_path / "two_gains.ssp"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
        z.writestr("resources/a.ssv", ssv)
        z.write(fmu_path("examples/native/fmi3/ArrayGain"), "resources/ArrayGain.fmu")
    return path, ssd


ELEMENTS = ['startElement="A" startConnector="y" endElement="B" endConnector="z" endIndices="1"',
            'startElement="A" startConnector="s" startIndices="2" endElement="B" endConnector="z" endIndices="3"']


def test_the_element_connections_validate_against_the_ssp_2_0_schema(tmp_path):
    from lxml import etree

    from pogofmu.ssp.package import read_ssd, unpack

    schema = etree.XMLSchema(file=str(ROOT / "ssp" / "schema" / "ssp-2.0" / "SystemStructureDescription.xsd"))
    path, ssd = _two_gains(tmp_path, ELEMENTS)
    assert schema.validate(etree.fromstring(ssd.encode())), schema.error_log
    system = read_ssd(unpack(path, tmp_path / "x"))
    assert [(c.start_connector, c.end_connector) for c in system.connections] == [("y", "z[1]"), ("s[2]", "z[3]")]
    assert list(system.components["B"].connectors)[:3] == ["z[1]", "z[2]", "z[3]"]


@pytest.mark.parametrize("algorithm, events", [("gauss-seidel", False), ("gauss-seidel", True), ("jacobi", False),
                                               ("model-exchange", True)])
def test_the_master_runs_connections_into_array_elements(tmp_path, algorithm, events):
    """A.y = y_A (constant: A's inputs are 0) into B.z[1], A.s[2] = 2 y_A into B.z[3]; B.z[2]
    keeps its start 0: B.y = y_0 + t (1 y_A + 2 * 0 + 3 * 2 y_A) = 0.5 + 1.75 t, and the weights
    1, 2, 3 tell which element each value reached; B.r = [g y_A, 0, g 2 y_A] (w = 0)."""
    from pogofmu.ssp import master

    path, _ = _two_gains(tmp_path, ELEMENTS)
    res = master.simulate(path, stop_time=1.0, step=0.125, algorithm=algorithm, events=events, echo_log=False)
    t = res["time"]
    assert len(t) == 9 and abs(t[-1] - 1.0) < 1e-12
    for k in range(len(t)):
        assert abs(res["B.y"][k] - (0.5 + 1.75 * t[k])) < 1e-9, (k, t[k], res["B.y"][k])
        assert res["B.z[1]"][k] == 0.25 and res["B.z[2]"][k] == 0.0 and res["B.z[3]"][k] == 0.5
        assert [res[f"B.r[{i}]"][k] for i in (1, 2, 3)] == [0.5, 0.0, 1.0]


@pytest.mark.parametrize("connection, b, expected", [
    ('startElement="A" startConnector="y" endElement="B" endConnector="z" endIndices="4"', None,
     'endIndices=\'4\' violates the rule: one index from 1 to 3 (B.z is a 1-D array of 3)'),
    ('startElement="A" startConnector="y" endElement="B" endConnector="z"', None,
     "1 value(s) into 3: connect arrays of the same size"),
    ('startElement="A" startConnector="y" startIndices="1" endElement="B" endConnector="z" endIndices="1"', None,
     "startIndices='1' on A.y, which is not an array connector"),
    ('startElement="A" startConnector="y" endElement="B" endConnector="z" endIndices="1"',
     [_connector("z", "input", 2)], "Connector B.z: ssc:Dimension size=2 but the FMU's variable z has the dimensions [3]"),
    ('startElement="A" startConnector="y" endElement="B" endConnector="z"', [_connector("z", "input")],
     "Connector B.z: the FMU's variable z is an array of [3]: declare the connector with <ssc:Dimension size=\"3\"/>"),
])
def test_ssp_check_refuses_bad_array_connections(tmp_path, connection, b, expected):
    path, _ = _two_gains(tmp_path, [connection], b)
    proc = run_pogofmu("ssp", "check", path, cwd=tmp_path, timeout=300)
    assert proc.returncode != 0 and expected in proc.stderr + proc.stdout, proc.stderr + proc.stdout
