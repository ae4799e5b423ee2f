"""Time in a model (docs/solver.md, "Event semantics"): guards and jumps that read `t`, and
`TimeEvent`s hit exactly by the steps, in every FMU kind, on a model file written as a user writes
it. The references are closed forms: a thrust cut at t_cut (constant accelerations on each side),
a sampler that holds the height of each instant k dt_s, a flag raised by a guard on time."""
from __future__ import annotations

import math

import numpy as np
import pytest

from support import run_pogofmu

pytestmark = pytest.mark.own_fmus  # (exports its own FMUs, or needs none)

CUT = '''
from pogofmu import RISING, Event, HybridModel, Parameter, TimeEvent, Variable

MODEL = HybridModel(
    name="Cut", description="thrust cut at a given time, a sampled altitude, a flag raised by a guard on time",
    states=(Variable("h", "m", "height"), Variable("v", "m/s", "velocity")),
    parameters=(Parameter("g", 9.81, "m/s2", "gravity"), Parameter("T", 20.0, "m/s2", "thrust acceleration"),
                Parameter("t_cut", 2.0, "s", "thrust cut time"), Parameter("dt_s", 0.1, "s", "sample period"),
                Parameter("t_late", 3.3, "s", "time of the late flag")),
    inputs=(),
    outputs=(Variable("h", "m", "height"), Variable("on", "", "thrust on"),
             Variable("hs", "m", "height sampled every dt_s"), Variable("late", "", "late flag")),
    flow=lambda t, x, q, u, p: [x[1], q["on"] * p.T - p.g],
    events=(TimeEvent("cut", at=lambda p: p.t_cut, jump=lambda x, q, u, p: (x, {**q, "on": 0})),
            TimeEvent("sample", at=lambda p: 0.0, every=lambda p: p.dt_s,
                      jump=lambda t, x, q, u, p: (x, {**q, "hs": x[0]})),
            Event("late", RISING, guard=lambda t, x, q, u, p: t - p.t_late,
                  jump=lambda t, x, q, u, p: (x, {**q, "late": 1}), active=lambda q: q["late"] == 0)),
    initial=lambda p: ([0.0, 0.0], {"on": 1, "hs": 0.0, "late": 0}),
    output_fn=lambda t, x, q, u, p: {"h": x[0], "on": q["on"], "hs": q["hs"], "late": q["late"]},
    integer_outputs=frozenset({"on", "late"}),
    default_stop_time=5.0,
)
'''
G, T, T_CUT, DT_S, T_LATE, STOP = 9.81, 20.0, 2.0, 0.1, 3.3, 5.0


def h_ref(t):
    """The closed form: (T - g) t^2 / 2 up to the cut, then the ballistic arc."""
    a = T - G
    if t <= T_CUT:
        return 0.5 * a * t * t
    s = t - T_CUT
    return 0.5 * a * T_CUT ** 2 + a * T_CUT * s - 0.5 * G * s * s


@pytest.fixture(scope="module")
def cut(tmp_path_factory):
    folder = tmp_path_factory.mktemp("time_events")
    (folder / "cut.py").write_text(CUT)
    proc = run_pogofmu("export", "cut.py", "--out", "out", cwd=folder, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = folder / "out"
    return {"python 2": out / "Cut.fmu", "python 3": out / "fmi3" / "Cut.fmu",
            "native 2": out / "native" / "Cut.fmu", "native 3": out / "native" / "fmi3" / "Cut.fmu"}


def _simulate(path, **kw):
    from fmpy import simulate_fmu

    return simulate_fmu(str(path), stop_time=STOP, output_interval=0.01, start_values={"rel_tol": 1e-10}, **kw)


def _check(res, tol):
    t = res["time"]
    assert max(abs(res["h"][i] - h_ref(t[i])) for i in range(len(t))) < tol
    off = np.abs(t - T_CUT) > 1e-9
    assert np.array_equal(res["on"][off], (t[off] < T_CUT).astype(res["on"].dtype))
    # hs holds the height of the latest sampling instant k dt_s (rows at an instant itself skipped:
    # the grid's time and the instant's differ by rounding)
    k = np.floor(t / DT_S + 0.5)
    away = np.abs(t - k * DT_S) > 1e-9
    last = np.floor(t / DT_S) * DT_S
    ref = np.array([h_ref(s) for s in last])
    assert np.max(np.abs(res["hs"][away] - ref[away])) < tol
    off = np.abs(t - T_LATE) > 1e-9
    assert np.array_equal(res["late"][off], (t[off] > T_LATE).astype(res["late"].dtype))
    # every instant 0, dt_s, ..., STOP, the cut and the flag: each once
    assert res["n_events"][-1] == round(STOP / DT_S) + 1 + 2


def test_time_events_and_a_guard_on_time_in_co_simulation_match_the_closed_form(cut):
    """The cut and each sample happen at their instants exactly (the steps land on them), so the
    height follows the closed form to 1e-9 m; both backends give the same bits."""
    runs = {}
    for kind, path in cut.items():
        kw = {} if kind.endswith("2") else dict(fmi_type="CoSimulation")
        res = _simulate(path, **kw)
        _check(res, 1e-9)
        runs[kind] = res
    for version in "23":
        a, b = runs[f"python {version}"], runs[f"native {version}"]
        for name in a.dtype.names:
            assert np.array_equal(a[name], b[name]), (version, name)


def test_model_exchange_reports_next_event_time_and_fires_time_events(cut):
    """FMI 3.0 model exchange: fmi3UpdateDiscreteStates reports nextEventTime (the instant after
    the one just handled), and an importer that stops there (fmpy's CVode loop) fires each."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Model

    for kind in ("python 3", "native 3"):
        path = cut[kind]
        md = read_model_description(str(path))
        fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(str(path)),
                        modelIdentifier=md.modelExchange.modelIdentifier, instanceName="cut")
        fmu.instantiate()
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        flags = fmu.updateDiscreteStates()  # the sample at t = 0, due at the start
        assert flags[4] and flags[5] == pytest.approx(DT_S, abs=1e-15), (kind, flags)
        fmu.terminate()
        fmu.freeInstance()
        res = _simulate(path, fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10)
        _check(res, 1e-6)  # CVode's own error at its tolerance


def test_co_simulation_returns_early_at_each_time_event(cut):
    """FMI 3.0 co-simulation with early return: one long doStep stops at each instant exactly,
    the samples (k dt_s), the cut (t_cut) and the flag (t_late, a state event on time)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    for kind in ("python 3", "native 3"):
        path = cut[kind]
        md = read_model_description(str(path))
        fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                        modelIdentifier=md.coSimulation.modelIdentifier, instanceName="cut")
        fmu.instantiate(eventModeUsed=False, earlyReturnAllowed=True)
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        t, stops = 0.0, []
        while t < 3.5 - 1e-12:
            _, _, early, t_last = fmu.doStep(currentCommunicationPoint=t, communicationStepSize=3.5 - t)
            if early:
                stops.append(t_last)
            t = t_last
        fmu.terminate()
        fmu.freeInstance()
        # every instant once: the sample at 0 is handled at initialization; events at one instant
        # (the cut and the sample at t_cut = 20 dt_s; the flag at t_late and the sample at 33 dt_s,
        # 4e-16 s apart: one instant to the engine, docs/solver.md) are handled at one stop
        expected = sorted({round(k * DT_S, 12) for k in range(1, 35)} | {T_CUT, T_LATE})
        assert len(stops) == len(expected), (kind, stops)
        assert max(abs(a - b) for a, b in zip(stops, expected)) < 1e-12, (kind, stops)


def test_a_time_event_with_a_bad_period_is_refused_at_export(tmp_path):
    """every(p) < 0 is refused when the model file is exported, naming the time event and the rule."""
    (tmp_path / "cut.py").write_text(CUT.replace("every=lambda p: p.dt_s", "every=lambda p: -p.dt_s"))
    proc = run_pogofmu("export", "cut.py", "--out", "out", cwd=tmp_path, timeout=600)
    assert proc.returncode == 2
    assert "time event sample" in proc.stderr and "every" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
