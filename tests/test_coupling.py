"""Event-exact system simulation: the SSP master's event-synchronized co-simulation (FMI 2.0
rollback, FMI 3.0 early return) and its strongly coupled model exchange.

References independent of the master and the FMUs: the continuous-time closed loop
(pogofmu.references.closed_loop: the thrust law inside a scipy ODE at rtol 1e-12), the free fall to the first
touchdown in closed form, the SSP 2.0 schemas (ssp/schema/ssp-2.0), the fixed-step master
(which libcosim confirms, tests/test_ssp.py), and perturbations of each FMU's inputs.
"""
import json
import math
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from pogofmu import ssp as master
from pogofmu.references.closed_loop import apex_of_run, first_apex, first_apex_sampled
from support import DIST, ROOT, clean_venv
from test_ssp import law, ssv_values, variant

SSP1 = DIST / "SpaceHopper.ssp"  # SSP 1.0, FMI 2.0 FMUs: the rollback path
SSP2 = DIST / "SpaceHopper-fmi3.ssp"  # SSP 2.0, FMI 3.0 FMUs: the early-return path
PACKAGES = {"fmi2": SSP1, "fmi3": SSP2}
SCHEMA2 = ROOT / "ssp" / "schema" / "ssp-2.0"


def first_apex_error(res, body):
    p = ssv_values(body)
    got = apex_of_run(res, p["g"])
    assert got is not None, "no flight row after the first contact"
    return abs(got - first_apex(p))


# ---------------------------------------------------------------------------------------------
# the SSP 2.0 package
# ---------------------------------------------------------------------------------------------

def test_the_fmi3_system_is_an_ssp_2_0_package_valid_against_its_schemas():
    from lxml import etree

    ssd_schema = etree.XMLSchema(file=str(SCHEMA2 / "SystemStructureDescription.xsd"))
    ssv_schema = etree.XMLSchema(file=str(SCHEMA2 / "SystemStructureParameterValues.xsd"))
    with zipfile.ZipFile(SSP2) as z:
        ssd = etree.fromstring(z.read("SystemStructure.ssd"))
        assert ssd.get("version") == "2.0"
        assert ssd_schema.validate(ssd), ssd_schema.error_log
        for body in ("earth", "moon", "ceres"):
            ssv = etree.fromstring(z.read(f"resources/{body}.ssv"))
            assert ssv.get("version") == "2.0" and ssv_schema.validate(ssv), (body, ssv_schema.error_log)
        for name in ("PogoStick", "HopController"):  # its components are the FMI 3.0 FMUs
            with zipfile.ZipFile(z.open(f"resources/{name}.fmu")) as fmu:
                assert b'fmiVersion="3.0"' in fmu.read("modelDescription.xml")
    # the schema does reject a broken document (the check above can fail)
    bad = etree.fromstring(etree.tostring(ssd).replace(b'kind="input"', b'kind="sideways"', 1))
    assert not ssd_schema.validate(bad)
    assert (SCHEMA2 / "LICENSE.txt").read_text().count("Redistribution") >= 1


# ---------------------------------------------------------------------------------------------
# convergence: the first apex against the continuous closed loop
# ---------------------------------------------------------------------------------------------

# The figures of README.md and docs/ssp-master.md (`pogofmu study coupling`), bounded at about 4x:
# where the thrust saturates over the first extension (Moon, Ceres) the synchronized master is exact
# to the FMUs' own rel_tol = 1e-6 at any step; model exchange to CVODE's 1e-10 (README: "1e-9 m").
STOP = {"moon": 2.1, "earth": 0.9, "ceres": 6.0}  # [s] past the first apex, a whole number of every step
SYNCHRONIZED = {"moon": 5.4e-9, "ceres": 4.2e-9}  # [m] measured, any step
EARTH_SYNCHRONIZED = {1e-2: 3.5e-3, 1e-3: 3.8e-4}  # [m] the sampled law's first-order error, measured
MODEL_EXCHANGE = 1e-9  # [m] the README's figure (measured: Moon 7.3e-10, Earth 4.3e-10, Ceres 2.7e-10)


@pytest.mark.parametrize("package", sorted(PACKAGES))
@pytest.mark.parametrize("body", sorted(SYNCHRONIZED))
def test_synchronized_first_apex_is_exact_to_the_fmus_tolerance_where_the_thrust_saturates(package, body):
    """Moon and Ceres, drop from 1.2 m: the first apex within 4x its figure at h = 1e-2 and 1e-3 s
    (fixed step: 1e-2 m and 1e-3 m, which the same test measures as a control; losing the
    input-crossing bisection costs 6.5e-4 m)."""
    for h in (1e-2, 1e-3):
        synced = master.simulate(PACKAGES[package], parameters=body, stop_time=STOP[body], step=h, echo_log=False)
        fixed = master.simulate(PACKAGES[package], parameters=body, stop_time=STOP[body], step=h, events=False,
                                echo_log=False)
        err, err_fixed = first_apex_error(synced, body), first_apex_error(fixed, body)
        assert err <= 4 * SYNCHRONIZED[body], (package, body, h, err)
        assert err_fixed > 1e4 * err, (package, body, h, err, err_fixed)  # the control can fail the test


@pytest.mark.parametrize("package", sorted(PACKAGES))
def test_synchronized_first_apex_on_the_earth_is_the_sampled_laws_first_order_error(package):
    """Earth (the law unsaturated in the extension, sampled once per step): the figures of the
    table to 10 %, first order between the steps, below the fixed-step master's error."""
    errs = {}
    for h, figure in EARTH_SYNCHRONIZED.items():
        synced = master.simulate(PACKAGES[package], parameters="earth", stop_time=STOP["earth"], step=h,
                                 echo_log=False)
        fixed = master.simulate(PACKAGES[package], parameters="earth", stop_time=STOP["earth"], step=h,
                                events=False, echo_log=False)
        errs[h] = first_apex_error(synced, "earth")
        assert errs[h] <= 1.1 * figure, (package, h, errs[h])
        assert first_apex_error(fixed, "earth") > 1.5 * errs[h], (package, h)
    assert 5 < errs[1e-2] / errs[1e-3] < 20


SAMPLED_EXACT = 1e-8  # [m] issue 43: the sampled-data loop met to the FMUs' tolerance


@pytest.mark.parametrize("package", sorted(PACKAGES))
def test_a_sampled_controller_meets_the_sampled_data_closed_loop(package):
    """HopController at 100 Hz (sample_period = 0.01 s, parameter set earth-100Hz: a zero-order
    hold updated by a periodic time event) against the sampled-data closed loop computed by scipy,
    restarted at every tick and every contact (pogofmu.references.closed_loop.first_apex_sampled):
    the first apex within 1e-8 m at communication steps of 1e-2 and 1e-3 s. The same bodies with
    the continuous law are 3.5e-3 m off their continuous loop (the law sampled once per step)."""
    p = ssv_values("earth-100Hz")
    ref = first_apex_sampled(p, p["sample_period"])
    assert abs(ref - first_apex(p)) > 1e-3  # the control: sampling at 100 Hz moves the apex
    for h in (1e-2, 1e-3):
        res = master.simulate(PACKAGES[package], parameters="earth-100Hz", stop_time=STOP["earth"], step=h,
                              echo_log=False)
        got = apex_of_run(res, p["g"])
        assert got is not None and abs(got - ref) < SAMPLED_EXACT, (package, h, got, ref)


@pytest.mark.parametrize("package", sorted(PACKAGES))
def test_the_first_touchdown_has_its_rows_and_the_controller_sees_it_there(package):
    """The free fall from y_0 touches down at sqrt(2 (y_0 - x_i)/g): the run has a left-limit row
    there (stick in flight) and a right-limit row in which both the stick's and the
    controller's s are 1 (feed-through at the event), at h = 1e-2 s, off the grid."""
    p = ssv_values("moon")
    t_td = math.sqrt(2 * (p["y_0"] - p["x_i"]) / p["g"])
    res = master.simulate(PACKAGES[package], parameters="moon", stop_time=0.6, step=1e-2, echo_log=False)
    t, kind = res["time"], res["event"]
    left = np.flatnonzero((kind == -1) & (np.abs(t - t_td) < 1e-9))
    right = np.flatnonzero((kind == 1) & (np.abs(t - t_td) < 1e-9))
    assert len(left) == 1 and len(right) == 1, (t[kind != 0], t_td)
    assert res["PogoStick.s"][left[0]] == 0 and res["HopController.s"][left[0]] == 0
    assert res["PogoStick.s"][right[0]] == 1 and res["HopController.s"][right[0]] == 1
    assert right[0] == left[0] + 1
    grid = t[kind == 0]  # the user's grid stays the grid
    np.testing.assert_allclose(grid, np.arange(61) * 1e-2, rtol=0, atol=1e-12)


@pytest.mark.parametrize("package", sorted(PACKAGES))
@pytest.mark.parametrize("h", [1e-3, 1e-2])
def test_jacobi_with_events_switches_at_the_continuous_loops_instants(package, h):
    """Moon (thrust saturated through the first extension, so only the switching instants
    matter): Jacobi with events synchronized has the touchdown, the controller's switch at the
    bottom of the stroke and the liftoff of the continuous closed loop, its first apex to the
    FMUs' tolerance as Gauss-Seidel does, and no thrust left in any flight row after the
    liftoff (the controller sees s = 0 at the liftoff instant, not one step later)."""
    from pogofmu.references.closed_loop import first_hop

    p = ssv_values("moon")
    ref = first_hop(p)
    res = master.simulate(PACKAGES[package], parameters="moon", stop_time=1.0, step=h, algorithm="jacobi",
                          echo_log=False)
    left = res["time"][res["event"] == -1]
    assert len(left) == 3, left
    np.testing.assert_allclose(left, [ref["touchdown"], ref["bottom"], ref["liftoff"]], rtol=0, atol=1e-7)
    assert first_apex_error(res, "moon") <= 4 * SYNCHRONIZED["moon"]
    after = (res["time"] >= ref["liftoff"]) & (res["event"] != -1)
    assert np.all(res["PogoStick.s"][after] == 0) and np.all(res["PogoStick.F_ext"][after] == 0.0)


def test_jacobi_with_events_keeps_the_jacobi_delay_between_events():
    """Earth (the law unsaturated in the extension): between events every grid row's thrust is
    the law at the previous grid row's state — the Jacobi step, whose inputs are those of the
    step's start, even though the master probes the controller at each step's end for its switch."""
    p = ssv_values("earth")
    res = master.simulate(SSP1, parameters="earth", stop_time=0.6, step=1e-2, algorithm="jacobi", echo_log=False)
    kind, y, yd, s = res["event"], res["PogoStick.y"], res["PogoStick.ydot"], res["PogoStick.s"]
    grid = np.flatnonzero(kind == 0)
    checked = 0
    for a, b in zip(grid[:-1], grid[1:]):
        if b == a + 1 and s[a] == s[b] == 1 and yd[a] > 0:  # two grid rows in an extension, no event between
            assert res["HopController.F_ext"][b] == pytest.approx(law(y[a], yd[a], s[a], p), rel=1e-12, abs=1e-12)
            checked += 1
    assert checked >= 5


def test_fmi2_rollback_and_fmi3_early_return_agree_on_every_grid_row():
    a = master.simulate(SSP1, parameters="moon", stop_time=10.0, step=1e-3, echo_log=False)
    b = master.simulate(SSP2, parameters="moon", stop_time=10.0, step=1e-3, echo_log=False)
    ga, gb = a["event"] == 0, b["event"] == 0
    assert ga.sum() == gb.sum() == 10001
    for name in ("PogoStick.y", "PogoStick.ydot", "PogoStick.E"):
        assert np.max(np.abs(a[name][ga] - b[name][gb])) <= 1e-9, name
    np.testing.assert_array_equal(a["PogoStick.s"][ga], b["PogoStick.s"][gb])
    ea, eb = a["time"][a["event"] == -1], b["time"][b["event"] == -1]
    assert len(ea) == len(eb) >= 10 and np.max(np.abs(ea - eb)) < 1e-12


# ---------------------------------------------------------------------------------------------
# model exchange: the strongly coupled solution
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("body", sorted(STOP))
def test_model_exchange_reaches_the_continuous_loop_at_any_output_step(body):
    """Every body (on the Earth, F_max = 20 N, the sampled law is what limits co-simulation: 3.5e-3 m
    at 1e-2 s): the first apex within 3x the README's 1e-9 m at output steps 5e-3 and 1e-2 s, the
    same solution on both grids."""
    g = ssv_values(body)["g"]
    apexes = {}
    for h in (5e-3, 1e-2):
        res = master.simulate(SSP2, parameters=body, stop_time=STOP[body], step=h, algorithm="model-exchange",
                              echo_log=False)
        assert first_apex_error(res, body) <= 3 * MODEL_EXCHANGE, (body, h, first_apex_error(res, body))
        apexes[h] = apex_of_run(res, g)
    assert abs(apexes[5e-3] - apexes[1e-2]) < 3e-10  # the grid moves CVODE's steps only (Earth: 7.6e-11 m)
    if body == "earth":
        cosim = master.simulate(SSP2, parameters="earth", stop_time=STOP["earth"], step=5e-3, echo_log=False)
        assert first_apex_error(cosim, "earth") > 1e-4  # the control: co-simulation does not reach it


def _plant_events(res):
    k = np.flatnonzero(res["event"] == -1)
    return np.array([res["time"][i] for i in k if res["PogoStick.s"][i] != res["PogoStick.s"][i + 1]])


def test_model_exchange_events_against_the_synchronized_cosimulation():
    """Moon, 6.5 s (8 events): while the thrust is saturated (the first contact) the synchronized co-simulation
    has model exchange's events to 1e-6 s; later, unsaturated, the sampled law differs at first
    order in the communication step (10x closer at a 10x smaller step), and model exchange is what
    it converges to."""
    me = _plant_events(master.simulate(SSP2, parameters="moon", stop_time=6.5, step=1e-3,
                                       algorithm="model-exchange", echo_log=False))
    tight = _plant_events(master.simulate(SSP2, parameters="moon", stop_time=6.5, step=1e-3,
                                          algorithm="model-exchange", rel_tol=1e-12, abs_tol=1e-14,
                                          echo_log=False))
    assert len(me) == len(tight) == 8 and np.max(np.abs(me - tight)) < 1e-8  # converged
    diffs = {}
    for h in (1e-3, 1e-4):
        cs = _plant_events(master.simulate(SSP2, parameters="moon", stop_time=6.5, step=h, echo_log=False))
        assert len(cs) == len(me)
        diffs[h] = np.abs(cs - me)
        assert np.all(diffs[h][:3] < 1e-6), (h, diffs[h])
    later = slice(3, None)
    assert np.all(diffs[1e-4][later] < diffs[1e-3][later] / 5), diffs


def test_model_exchange_needs_fmi3_model_exchange_and_says_so(capsys):
    assert master.main(["run", str(SSP1), "--algorithm", "model-exchange", "--stop-time", "0.1", "--quiet",
                        "--out", str(DIST / "unused-out")]) == 1
    err = capsys.readouterr().err
    assert "needs FMI 3.0 model exchange" in err and "FMI 2.0" in err and "Traceback" not in err
    assert not (DIST / "unused-out").exists() or not list((DIST / "unused-out").iterdir())


# ---------------------------------------------------------------------------------------------
# declared dependencies: generated from the model, checked by perturbing the FMUs
# ---------------------------------------------------------------------------------------------

def _me_instance(name):
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Model

    path = DIST / "fmi3" / f"{name}.fmu"
    md = read_model_description(str(path))
    fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="probe")
    fmu.instantiate()
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.updateDiscreteStates()  # and stay in Event Mode, where every input may be set (FMI 3.0)
    return md, fmu


PROBES = {  # inputs at which to perturb: the controller in extension, unsaturated; the stick in flight
    "HopController": {"y": 0.99, "ydot": 3.0, "s": 1},
    "PogoStick": {"F_ext": 1.0}, "PogoStickMem": {"F_ext": 1.0}, "PogoStickSMA": {"F_ext": 1.0},
    "Penetrator": {"F_ext": 1.0},
}


@pytest.mark.parametrize("name", sorted(PROBES))
def test_declared_feedthrough_is_what_perturbing_each_input_does(name):
    """Within one evaluation (no time passes): perturbing an input changes exactly the outputs
    that declare it (FMI 3.0 Output dependencies; FMI 2.0 the same), and the derivatives that
    declare it change with it."""
    md, fmu = _me_instance(name)
    try:
        by_vr = {v.valueReference: v for v in md.modelVariables}
        inputs = [v for v in md.modelVariables if v.causality == "input"]

        def put(v, value):
            (fmu.setFloat64 if v.type == "Float64" else fmu.setInt32)([v.valueReference], [value])

        def outputs():
            got = {}
            for u in md.outputs + md.derivatives:
                v = u.variable
                got[v.name] = (fmu.getFloat64 if v.type == "Float64" else fmu.getInt32)([v.valueReference])[0]
            return got

        for v in inputs:
            put(v, PROBES[name][v.name])
        base = outputs()
        for v in inputs:
            old = PROBES[name][v.name]
            put(v, (1 - old) if v.type == "Int32" else old * 1.01 + 0.01)
            moved = {k for k, val in outputs().items() if val != base[k]}
            put(v, old)
            declared = {u.variable.name for u in md.outputs + md.derivatives
                        if u.dependencies is not None and v in u.dependencies}
            assert moved <= declared, (name, v.name, moved - declared)
            outputs_declared = {u.variable.name for u in md.outputs if u.dependencies is not None and v in u.dependencies}
            if name == "HopController":  # in extension every law output moves with every input it reads
                assert moved & outputs_declared == outputs_declared - {"phase"} or v.name == "s", (v.name, moved)
            assert all(u.dependencies is not None for u in md.outputs), "every output declares its dependencies"
        del by_vr
    finally:
        fmu.terminate()
        fmu.freeInstance()


def test_fmi2_and_fmi3_declare_the_same_feedthrough():
    from fmpy import read_model_description

    for name in PROBES:
        md2 = read_model_description(str(DIST / f"{name}.fmu"))
        md3 = read_model_description(str(DIST / "fmi3" / f"{name}.fmu"))
        ft2 = {u.variable.name: sorted(v.name for v in u.dependencies) for u in md2.outputs}
        inputs3 = {v.name for v in md3.modelVariables if v.causality == "input"}
        ft3 = {u.variable.name: sorted(v.name for v in u.dependencies if v.name in inputs3) for u in md3.outputs}
        assert ft2 == {k: ft3[k] for k in ft2}, name
        assert any(ft2.values()) == (name == "HopController")


def _two_controllers(text):
    """A second HopController whose phase drives the first's s input and back: an algebraic loop
    (phase depends directly on s in each)."""
    comp = text[text.index('      <ssd:Component name="HopController"'):text.index("    </ssd:Elements>")]
    twin = comp.replace('name="HopController"', 'name="Twin"')
    text = text.replace("    </ssd:Elements>", twin + "    </ssd:Elements>")
    text = text.replace('<ssd:Connection startElement="PogoStick" startConnector="s" endElement="HopController" '
                        'endConnector="s"/>',
                        '<ssd:Connection startElement="Twin" startConnector="phase" endElement="HopController" '
                        'endConnector="s"/>\n      <ssd:Connection startElement="HopController" startConnector="phase" '
                        'endElement="Twin" endConnector="s"/>')
    return text


def test_an_algebraic_loop_is_named_refused_by_model_exchange_and_iterated_by_cosimulation(tmp_path):
    pkg = variant(tmp_path, edit_ssd=_two_controllers)
    with pytest.raises(master.SSPError, match=r"algebraic loop .*HopController\.s -> HopController\.phase -> "
                                              r"Twin\.s -> Twin\.phase -> HopController\.s|algebraic loop .*Twin"):
        master.simulate(pkg, parameters="moon", stop_time=0.1, step=1e-2, algorithm="model-exchange")
    proc = subprocess.run([sys.executable, "-m", "pogofmu.ssp", "run", str(pkg), "--parameters", "moon",
                           "--stop-time", "0.1", "--step", "1e-2", "--quiet", "--out", str(tmp_path / "out")],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "warning: algebraic loop" in proc.stderr and "Twin.phase" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_the_update_order_follows_the_dependencies_not_the_listing(tmp_path):
    """The .ssd lists the controller and its connection first; the stick's outputs do not depend
    on its input, the controller's do: the stick is updated first all the same."""
    def controller_first(text):
        a = text.index('      <ssd:Component name="PogoStick"')
        b = text.index('      <ssd:Component name="HopController"')
        e = text.index("    </ssd:Elements>")
        text = text[:a] + text[b:e] + text[a:b] + text[e:]
        return text.replace('      <ssd:Connection startElement="PogoStick" startConnector="y"',
                            '      <ssd:Connection startElement="HopController" startConnector="F_ext" '
                            'endElement="PogoStick" endConnector="F_ext"/>\n'
                            '      <ssd:Connection startElement="PogoStick" startConnector="y"', 1).replace(
            '      <ssd:Connection startElement="HopController" startConnector="F_ext" endElement="PogoStick" '
            'endConnector="F_ext"/>\n    </ssd:Connections>', '    </ssd:Connections>')
    pkg = variant(tmp_path, edit_ssd=controller_first)
    proc = subprocess.run([sys.executable, "-m", "pogofmu.ssp", "check", str(pkg)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "['PogoStick', 'HopController']" in proc.stdout
    a = master.simulate(pkg, parameters="moon", stop_time=1.0, step=1e-2, echo_log=False)
    b = master.simulate(SSP1, parameters="moon", stop_time=1.0, step=1e-2, echo_log=False)
    np.testing.assert_array_equal(a["PogoStick.y"], b["PogoStick.y"])


# ---------------------------------------------------------------------------------------------
# the bad cases: a clear message, no traceback
# ---------------------------------------------------------------------------------------------

class _Stub:
    """A component of the master's interface, scripted by the test."""

    fmi, can_save, rollback, counts_events, event_mode_used, early_return = 3, True, False, False, True, True
    events = None  # not a pogofmu FMU: it may return early at any time
    discrete_outputs: list = []

    def __init__(self, name, outputs=None, on_step=None, on_update=None):
        self.name, self.t, self.saved_at, self.outputs = name, 0.0, None, dict(outputs or {})
        self.on_step, self.on_update = on_step, on_update
        self.comp = type("C", (), {"model_description": None})()

    def set_values(self, names, values):
        self.inputs = dict(zip(names, values))

    def get_values(self, names):
        return [self.outputs[n] for n in names]

    def save(self):
        self.saved_at = self.t

    def restore(self):
        self.t = self.saved_at

    def do_step(self, t, h):
        return self.on_step(self, t, h)

    def enter_event_mode(self):
        pass

    def enter_step_mode(self):
        pass

    def update_discrete_states(self):
        return self.on_update(self) if self.on_update else (False, False, None)

    def fail(self, what, exc):
        return master.SSPError(f"Component {self.name}: {what} failed ({exc})")


def _exchange(stubs, connections):
    from pogofmu.ssp.algorithms import Exchange
    from pogofmu.ssp.package import Connection, Connector

    comps = {}
    for s in stubs:
        cons = {n: Connector(n, "output", "Integer", None) for n in s.outputs}
        cons.update({c[3]: Connector(c[3], "input", "Integer", None) for c in connections if c[2] == s.name})
        comps[s.name] = type("Comp", (), {"connectors": cons, "name": s.name})()
    system = type("Sys", (), {"components": comps,
                              "connections": [Connection(i + 1, *c) for i, c in enumerate(connections)]})()
    rows = []
    ex = Exchange(system, {s.name: s for s in stubs}, [s.name for s in stubs],
                  type("R", (), {"add": lambda self, r: rows.append(r)})())
    for s in stubs:
        ex.read(s)
    return ex


def test_a_discrete_iteration_that_does_not_settle_ends_with_the_components_and_the_time(monkeypatch):
    """Two components each flip their output when the other's changes: the event iteration at an
    instant never settles; the limit names both and the time."""
    from pogofmu.ssp.algorithms import MAX_EVENT_ITERATIONS, Synchronizer

    monkeypatch.setattr("pogofmu.ssp.algorithms.switching_outputs", lambda inst, ex: [])

    def flip(self):
        self.outputs["q"] = 1 - self.inputs.get("p", 0)
        return (False, False, None)
    a = _Stub("A", {"q": 0}, on_update=flip)
    b = _Stub("B", {"q": 0}, on_update=lambda self: (self.outputs.__setitem__("q", self.inputs.get("p", 0)),
                                                      (False, False, None))[1])
    ex = _exchange([a, b], [("A", "q", "B", "p"), ("B", "q", "A", "p")])
    sync = Synchronizer(ex, 1e-10, warn=lambda text: None)
    with pytest.raises(master.SSPError) as exc:
        sync.settle(0.25, [a, b])
    text = str(exc.value)
    assert f"t = 0.25 s did not settle after {MAX_EVENT_ITERATIONS} iterations" in text and "A" in text
    assert "B" in text


def test_an_event_reported_before_the_step_start_is_refused():
    from pogofmu.ssp.components import Fmi3CoSimulation

    inst = Fmi3CoSimulation.__new__(Fmi3CoSimulation)
    inst.name, inst.event_mode_used = "Plant", True
    import ctypes

    inst._flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
    inst._flag_refs = [ctypes.byref(f) for f in inst._flags]
    inst.fmu = type("F", (), {"component": None})()

    def do_step(c, t, h, no_set, e, m, r, last):
        inst._flags[0].value, inst._flags[2].value, inst._flags[3].value = True, True, t - 0.5
        return 0
    inst._do_step = do_step
    with pytest.raises(master.SSPError, match=r"Component Plant: fmi3DoStep from t = 1 s returned early at "
                                              r"lastSuccessfulTime = 0.5 s, before the start of the step"):
        inst.do_step(1.0, 0.1)


def test_a_component_that_refuses_the_shortened_step_is_named_with_the_event(monkeypatch):
    """B returns early at 0.04 s; A, already at 0.1 s, is restored and stepped to 0.04 s, and
    refuses: the message names A, its refusal and B's event."""
    from pogofmu.ssp.algorithms import Synchronizer
    from pogofmu.ssp.components import StepResult

    monkeypatch.setattr("pogofmu.ssp.algorithms.switching_outputs", lambda inst, ex: [])

    def a_step(self, t, h):
        if h < 0.1 - 1e-12:
            raise master.SSPError(f"Component A: fmi3DoStep from t = {t:g} s (step {h:g} s) failed (error)")
        self.t = t + h
        return StepResult(self.t)

    def b_step(self, t, h):
        self.t = min(t + h, 0.04)
        return StepResult(self.t, event_at=self.t, event_mode=True)
    a, b = _Stub("A", {"q": 0}, on_step=a_step), _Stub("B", {"r": 0}, on_step=b_step)
    ex = _exchange([a, b], [("A", "q", "B", "p")])
    sync = Synchronizer(ex, 1e-10, warn=lambda text: None)
    with pytest.raises(master.SSPError) as exc:
        sync.advance(0.0, 0.1)
    assert "Component A" in str(exc.value) and "shortened to the event of Component B at t = 0.04 s" in str(exc.value)


# ---------------------------------------------------------------------------------------------
# as the user runs it: a venv with only fmpy (and numpy), the project not installed
# ---------------------------------------------------------------------------------------------

def test_both_synchronized_paths_in_a_fresh_venv_without_the_project():
    """A fresh process of a venv that has only fmpy and numpy, the master's source on the path:
    the FMI 3.0 early-return and the FMI 2.0 rollback paths each reach the closed loop's first
    apex to 4x its figure (5.4e-9 m) at h = 1e-3 s, on the FMUs' own bundled code."""
    python = clean_venv()
    script = (
        "import json, sys\n"
        f"sys.path.insert(0, {str(ROOT / 'fmu_src')!r})\n"
        "from pogofmu.ssp import simulate\n"
        "from pogofmu.references.closed_loop import apex_of_run\n"
        "out = {}\n"
        f"for key, pkg in {json.dumps({k: str(v) for k, v in PACKAGES.items()})}.items():\n"
        "    res = simulate(pkg, parameters='moon', stop_time=2.0, step=1e-3, echo_log=False)\n"
        "    out[key] = [apex_of_run(res, 1.62), int((res['event'] != 0).sum())]\n"
        "out['fmu_code'] = sorted({m.split('.')[0] for m in sys.modules if m.startswith('_pogofmu_')})\n"
        "out['installed'] = [m for m in ('scipy', 'matplotlib', 'pogofmu.runtime.fmi2') if m in sys.modules]\n"
        "print(json.dumps(out))\n")
    proc = subprocess.run([str(python), "-c", script], capture_output=True, text=True, timeout=600,
                          env={"PATH": "/usr/bin:/bin", "HOME": str(ROOT / "build")})
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    ref = first_apex(ssv_values("moon"))
    for key in PACKAGES:
        apex, n_event_rows = got[key]
        assert abs(apex - ref) <= 4 * SYNCHRONIZED["moon"] and n_event_rows >= 4, (key, apex, ref)
    assert len(got["fmu_code"]) == 4 and not got["installed"], got


# ---------------------------------------------------------------------------------------------
# pogofmu study coupling
# ---------------------------------------------------------------------------------------------

def test_the_coupling_study_writes_the_table_the_figure_and_the_slopes(tmp_path, capsys):
    import csv

    from pogofmu import cli

    out = tmp_path / "coupling"
    assert cli.main(["study", "coupling", "--out", str(out), "--steps", "1e-2,1e-3", "--bodies", "moon",
                     "--algorithms", "gauss-seidel,fmi3-early-return,fmi2-rollback-jacobi,fmi3-early-return-jacobi,"
                     "model-exchange", "--quiet",
                     "--ssp", str(SSP1), "--ssp-fmi3", str(SSP2)]) == 0
    printed = capsys.readouterr().out
    with (out / "coupling.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 10 and all(r["status"] == "ok" for r in rows)
    err = {(r["algorithm"], float(r["step_s"])): float(r["error_m"]) for r in rows}
    assert 5 < err[("gauss-seidel", 1e-2)] / err[("gauss-seidel", 1e-3)] < 20  # first order
    for h in (1e-2, 1e-3):  # saturated thrust: synchronized, Gauss-Seidel or Jacobi, is exact to the FMUs' tolerance
        for algorithm in ("fmi3-early-return", "fmi2-rollback-jacobi", "fmi3-early-return-jacobi"):
            assert err[(algorithm, h)] <= 4 * SYNCHRONIZED["moon"], (algorithm, h)
        assert err[("model-exchange", h)] <= 3 * MODEL_EXCHANGE
    gs_slope = float(next(line for line in printed.splitlines() if "Gauss-Seidel" in line).split()[-1])
    assert 0.9 < gs_slope < 1.1
    assert (out / "coupling.png").read_bytes()[:4] == b"\x89PNG"
    # bad input: one line, exit status 2
    assert cli.main(["study", "coupling", "--out", str(out), "--steps", "4e-2", "--bodies", "moon"]) == 2
    assert "does not divide" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# saving only what is needed: FMU states every REPLAY_STEPS steps, the calls in between replayed
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("which", ["fmi2", "fmi3"])
def test_replayed_saves_give_the_run_of_a_save_before_every_step_to_the_bit(which, monkeypatch):
    """A restore that replays the journaled calls from an older FMU state must land on the very
    state a save before every step would have kept: the whole 6 s Moon run (events, rollbacks,
    bisected controller switches) is identical to the bit, with far fewer FMU states saved, and
    replays did happen."""
    from pogofmu.ssp import components

    counts = {}
    real_save, real_restore = components.Component.save, components.Component.restore

    def counting_save(self):
        n0 = self._journal is None or len(self._journal) >= 2 * components.REPLAY_STEPS
        counts["saves"] = counts.get("saves", 0) + bool(n0)
        return real_save(self)

    def counting_restore(self):
        counts["replays"] = counts.get("replays", 0) + bool(self._mark)
        return real_restore(self)

    monkeypatch.setattr(components.Component, "save", counting_save)
    monkeypatch.setattr(components.Component, "restore", counting_restore)
    runs = {}
    for k in (1, components.REPLAY_STEPS):
        monkeypatch.setattr(components, "REPLAY_STEPS", k)
        counts.clear()
        res = master.simulate(PACKAGES[which], parameters="moon", stop_time=6.0, step=1e-3, echo_log=False)
        runs[k] = (res, dict(counts))
    (eager, c1), (lazy, c16) = runs[1], runs[components.REPLAY_STEPS]
    assert eager.rows == lazy.rows > 6000
    for name in eager.names:
        assert np.array_equal(np.asarray(eager[name]), np.asarray(lazy[name])), name
    assert c16["saves"] * 4 < c1["saves"], (c1, c16)
    assert c16.get("replays", 0) > 5 and c1.get("replays", 0) == 0, (c1, c16)
