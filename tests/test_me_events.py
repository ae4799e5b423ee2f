"""The event semantics of docs/solver.md ("Event semantics") in model exchange: the arming of the
guards is the engine's (pg_engine_me_indicators, pg_engine_me_fired), as in co-simulation, so an
accumulation ends with the storm naming the event in every model-exchange path too — fmpy's own
model exchange with CVode on the FMI 3.0 FMUs of both backends, and the SSP master's
``--algorithm model-exchange`` — never with the state carried through the wall or the floor.

The models are files a user writes (the wall of tests/test_event_semantics.py, the ball of
examples/ball), exported by ``pogofmu export`` in a temporary folder."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, example, given, note, settings
from hypothesis import strategies as st

from support import ROOT, run_pogofmu

from test_event_semantics import WALL  # the forced oscillator pressed against a wall (Zeno)

pytestmark = pytest.mark.own_fmus  # (exports its own FMUs, or needs none)

# a system of one component: the exported ball, its outputs h and v
BALL_SSD = '''<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
                                xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
                                version="2.0" name="BallSystem" generationTool="pogofmu tests">
  <ssd:System name="BallSystem" description="a bouncing ball alone">
    <ssd:Elements>
      <ssd:Component name="Ball" source="resources/Ball.fmu" type="application/x-fmu-sharedlibrary">
        <ssd:Connectors>
          <ssd:Connector name="h" kind="output"><ssc:Float64 unit="m"/></ssd:Connector>
          <ssd:Connector name="v" kind="output"><ssc:Float64 unit="m/s"/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
</ssd:SystemStructureDescription>
'''

ME_KINDS = ("fmi3/{n}.fmu", "native/fmi3/{n}.fmu")
LONG = os.environ.get("POGOFMU_FUZZ") == "long"


@pytest.fixture(scope="module")
def user_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("me_events")
    (folder / "wall.py").write_text(WALL.format(name="Wall", shift="0.0", wall="p.d"))
    (folder / "wall0.py").write_text(WALL.format(name="Wall0", shift="p.d", wall="0.0"))
    (folder / "ball.py").write_text((ROOT / "examples" / "ball" / "ball.py").read_text())
    proc = run_pogofmu("export", "wall.py", "wall0.py", "ball.py", "--out", "out", "--fmi", "3", cwd=folder,
                       timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return folder


def _me_run(path, stop_time, table=None, interval=1e-3, rtol=1e-10):
    """fmpy's model exchange with CVode (the input ``table`` if any, the events logged): (the exception
    or None, the log messages, every row, the events)."""
    from fmpy import simulate_fmu

    from pogofmu.runtime.eventlog import parse_event_log

    messages, rows, exc = [], [], None
    try:
        simulate_fmu(str(path), fmi_type="ModelExchange", solver="CVode", relative_tolerance=rtol,
                     stop_time=stop_time, output_interval=interval, input=table, start_values={"log_events": 1},
                     debug_logging=True,
                     logger=lambda *a: messages.append((a[-3], *(b.decode() if b else "" for b in a[-2:]))),
                     step_finished=lambda t, recorder: rows.extend(recorder.rows[len(rows):]) or True)
    except Exception as e:  # noqa: BLE001 - the FMU's error, whatever fmpy wraps it in
        exc = e
    return exc, [m[2] for m in messages], rows, parse_event_log(messages)


@pytest.mark.parametrize("name,wall", [("Wall", 0.05), ("Wall0", 0.0)])
def test_fmpy_model_exchange_against_a_pressed_wall_ends_in_the_storm(user_folder, name, wall):
    """fmpy's own model exchange (CVode, rel_tol 1e-10) on the FMI 3.0 FMUs of both backends: the
    mass pressed against the wall ends with the storm naming the impact, never carried through it
    by more than 1e-6 m. Before, the arming of the adapters (a guard armed only when an indicator
    evaluation saw it strictly on its before side) let the mass through the wall silently."""
    for kind in ME_KINDS:
        path = user_folder / "out" / kind.format(n=name)
        exc, messages, rows, _ = _me_run(path, 3.0)
        storm = [m for m in messages if "event storm" in m]
        x = np.array([r[1] for r in rows])
        assert exc is not None, (path, "ran to the end", x.max())
        assert storm and "impact" in storm[0], (path, exc, messages[-3:])
        assert x.max() <= wall + 1e-6, (path, x.max())


def _ball_ssp(folder, kind):
    pkg = folder / ("ssp-" + kind.format(n="Ball").replace("/", "-"))
    (pkg / "resources").mkdir(parents=True, exist_ok=True)
    (pkg / "SystemStructure.ssd").write_text(BALL_SSD)
    (pkg / "resources" / "Ball.fmu").write_bytes((folder / "out" / kind.format(n="Ball")).read_bytes())
    return pkg


@pytest.mark.parametrize("kind", ME_KINDS)
def test_the_ssp_master_model_exchange_ends_a_bouncing_ball_in_the_storm(user_folder, kind):
    """An SSP holding only the exported ball (t_inf = 4.0637 s), run to 6 s by the master's model
    exchange: exit 1 with the storm naming the bounce, the rows so far kept in
    <set>.incomplete.csv as Gauss-Seidel keeps them, never a result with h below the floor. Before,
    it exited 0 with the ball fallen through the floor."""
    pkg = _ball_ssp(user_folder, kind)
    out = pkg / "out"
    proc = subprocess.run([sys.executable, "-m", "pogofmu.cli", "ssp", "run", str(pkg), "--algorithm",
                           "model-exchange", "--stop-time", "6", "--out", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 1, (proc.returncode, proc.stdout[-2000:], proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr, proc.stderr
    assert "event storm" in proc.stderr and "bounce" in proc.stderr, proc.stderr
    assert "default.incomplete.csv" in proc.stderr, proc.stderr
    assert not (out / "default.csv").exists()
    lines = (out / "default.incomplete.csv").read_text().splitlines()
    head = lines[0].split(",")
    h = np.array([float(r.split(",")[head.index("Ball.h")]) for r in lines[1:]])
    t_last = float(lines[-1].split(",")[0])
    assert 4.0 < t_last < 4.07, t_last  # the accumulation point t_inf = 4.0637 s
    assert h.min() > -1e-6, h.min()


# ---- the importer's observations out of time order -----------------------------------------------
# Four counters on one closed-form trajectory (x = sin t, v = cos t), each guard a drawn mix of the
# state, the time and an input, its sign drawn (events n1, n3 RISING, n2, n4 FALLING): the jumps
# change no state, so the trajectory stays sin t and each counter's count is the number of crossings of
# its guard in its direction, which the reference reads off the guard's closed form (the input: the
# table fmpy interpolates linearly). CVode's root search tries points beyond a root, then comes back:
# a guard seen on its before side only beyond the root is not armed at it.
CROSSINGS = '''"""Four counters on x = sin t: guard k = s_k (ax_k x + at_k sin(w_k t + ph_k) + au_k u - L_k)."""
from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable, fmath

K = (1, 2, 3, 4)
NAMES = ("s", "ax", "at", "au", "w", "ph", "L")
MODEL = HybridModel(
    name="Crossings", description="four counters of the crossings of drawn guards",
    states=(Variable("x", "1", "x = sin t"), Variable("v", "1", "v = cos t")),
    parameters=tuple(Parameter(f"{n}{k}", 1.0 if n in ("s", "w") else 0.0, "1", f"{n} of guard {k}")
                     for k in K for n in NAMES),
    inputs=(Variable("u", "1", "the input a guard may read", 0.0),),
    outputs=tuple(Variable(f"n{k}", "", f"crossings of guard {k}") for k in K),
    flow=lambda t, x, q, u, p: [x[1], -x[0]],
    events=(
{events}    ),
    initial=lambda p: ([0.0, 1.0], {"n1": 0, "n2": 0, "n3": 0, "n4": 0}),
    output_fn=lambda t, x, q, u, p: {"n1": q["n1"], "n2": q["n2"], "n3": q["n3"], "n4": q["n4"]},
    integer_outputs=frozenset({"n1", "n2", "n3", "n4"}),
    default_stop_time=6.0,
)
'''
CROSSING_EVENT = ('        Event("n{k}", {d}, guard=lambda t, x, q, u, p: p.s{k} * (p.ax{k} * x[0] + p.at{k} * '
                  'fmath.sin(p.w{k} * t + p.ph{k}) + p.au{k} * u[0] - p.L{k}),\n'
                  '              jump=lambda x, q, u, p: (x, {{**q, "n{k}": q["n{k}"] + 1}})),\n')
CROSSING_DIRS = {1: "RISING", 2: "FALLING", 3: "RISING", 4: "FALLING"}
T_CROSS = 6.0


@pytest.fixture(scope="module")
def crossings(tmp_path_factory):
    folder = tmp_path_factory.mktemp("crossings")
    events = "".join(CROSSING_EVENT.format(k=k, d=d) for k, d in CROSSING_DIRS.items())
    (folder / "crossings.py").write_text(CROSSINGS.replace("{events}", events))
    proc = run_pogofmu("export", "crossings.py", "--out", "out", "--fmi", "3", "--platforms", "x86_64-linux",
                       cwd=folder, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return [folder / "out" / kind.format(n="Crossings") for kind in ME_KINDS]


@st.composite
def crossing_draws(draw):
    """(parameters, the input's (w, phase, table step), the output interval, the tolerance)."""
    level = draw(st.floats(-0.8, 0.8))  # (a level two guards may share)
    p = {}
    for k in CROSSING_DIRS:
        kind = draw(st.sampled_from(["state", "time", "input", "mix"]))
        ax, at, au = {"state": (1, 0, 0), "time": (0, 1, 0), "input": (0, 0, 1)}.get(kind, (None,) * 3)
        if kind == "mix":
            ax, at, au = (draw(st.floats(-1, 1)) for _ in range(3))
        w = draw(st.sampled_from([1.0, None])) or draw(st.floats(0.3, 3.0))
        ph = draw(st.sampled_from([0.0, None]))
        ph = draw(st.floats(0.0, 6.2)) if ph is None else ph  # (w 1, ph 0: the state's own sine)
        L = draw(st.sampled_from([level, None]))
        L = draw(st.floats(-0.8, 0.8)) if L is None else L
        p.update({f"s{k}": draw(st.sampled_from([1.0, -1.0])), f"ax{k}": float(ax), f"at{k}": float(at),
                  f"au{k}": float(au), f"w{k}": w, f"ph{k}": ph, f"L{k}": L})
    wu = draw(st.sampled_from([1.0, None])) or draw(st.floats(0.3, 3.0))
    phu = draw(st.sampled_from([0.0, None]))
    phu = draw(st.floats(0.0, 6.2)) if phu is None else phu
    dt_u = draw(st.sampled_from([1e-3, 1e-2]))
    interval = draw(st.sampled_from([0.01, 0.1, 0.5]))
    rtol = draw(st.sampled_from([None, 1e-8]))  # (None: the FMU's default experiment, 1e-6)
    return p, (wu, phu, dt_u), interval, rtol


def _crossing_reference(p, signal):
    """Each guard's crossings in its direction, (times per counter), from its closed form on a grid of
    2.5e-5 s, or None where a guard comes within 5e-3 of zero at a rate below 0.2 /s (a tangency, a
    start or a stop at zero: the count would depend on rounding, not on the rule)."""
    wu, phu, dt_u = signal
    t_u = np.arange(0.0, T_CROSS + dt_u / 2, dt_u)
    t = np.union1d(np.linspace(0.0, T_CROSS, 240001), t_u)
    u = np.interp(t, t_u, np.sin(wu * t_u + phu))
    times = {}
    for k, d in CROSSING_DIRS.items():
        G = p[f"s{k}"] * (p[f"ax{k}"] * np.sin(t) + p[f"at{k}"] * np.sin(p[f"w{k}"] * t + p[f"ph{k}"])
                          + p[f"au{k}"] * u - p[f"L{k}"])
        rate = np.gradient(G, t)
        near = np.abs(G) < 5e-3
        if (near & (np.abs(rate) < 0.2)).any() or near[:20].any() or near[-20:].any():
            return None
        before = G < 0 if d == "RISING" else G > 0
        i = np.flatnonzero(before[:-1] & ~before[1:])
        times[f"n{k}"] = t[i] - G[i] * (t[i + 1] - t[i]) / (G[i + 1] - G[i])
    return times


def _crossing_run(path, p, signal, interval, rtol):
    from fmpy import simulate_fmu

    wu, phu, dt_u = signal
    t_u = np.arange(0.0, T_CROSS + dt_u / 2, dt_u)
    table = np.array(list(zip(t_u, np.sin(wu * t_u + phu))), dtype=[("time", float), ("u", float)])
    r = simulate_fmu(str(path), fmi_type="ModelExchange", stop_time=T_CROSS, output_interval=interval,
                     relative_tolerance=rtol, start_values=p, input=table, output=list(f"n{k}" for k in CROSSING_DIRS),
                     record_events=True)
    return r


def _crossing_cs_events(path, p, interval):
    """Co-simulation of the same FMU (no input read by a guard): the events of its log, (name, time)."""
    from fmpy import simulate_fmu

    from pogofmu.runtime.eventlog import parse_event_log

    messages = []
    simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=T_CROSS, output_interval=interval,
                 start_values={**p, "log_events": 1}, debug_logging=True,
                 logger=lambda *a: messages.append((a[-3], *(b.decode() if b else "" for b in a[-2:]))))
    return [(r["name"], r["time"]) for r in parse_event_log(messages)]


def _one_crossing(k, s=1.0, ax=0.0, at=0.0, au=0.0, w=1.0, ph=0.0, L=0.5):
    return {f"s{k}": s, f"ax{k}": ax, f"at{k}": at, f"au{k}": au, f"w{k}": w, f"ph{k}": ph, f"L{k}": L}


@settings(max_examples=300 if LONG else 40, deadline=None, derandomize=not LONG,
          suppress_health_check=list(HealthCheck))
@given(case=crossing_draws())
# the user's audit: a counter on sin t (FALLING sin t - 0.5 as RISING 0.5 - sin t) beside a counter on the
# state x = sin t at the same level counted at every crossing of the other
@example(case=({**_one_crossing(1, ax=1.0), **_one_crossing(2, at=1.0), **_one_crossing(3, s=-1.0, at=1.0),
                **_one_crossing(4, s=-1.0, ax=1.0)}, (1.0, 0.0, 1e-2), 0.01, None))
# the user's audit: an alarm on the input u = 1 + sin 2t through 1.5 (RISING u - 1.5 here as u' = sin 2t
# through 0.5) counted one falling crossing too
@example(case=({**_one_crossing(1, au=1.0), **_one_crossing(2, s=-1.0, au=1.0), **_one_crossing(3, ax=1.0, L=-0.3),
                **_one_crossing(4, at=1.0, w=2.0, L=0.2)}, (2.0, 0.0, 1e-3), 0.01, None))
# a drawn model: a counter on 0.25 x + u (u = sin(t + 2)) counted one crossing twice, 5e-14 s apart
@example(case=({**_one_crossing(1, ax=1.0), **_one_crossing(2, s=-1.0, ax=0.25, au=1.0, L=0.0),
                **_one_crossing(3, ax=1.0), **_one_crossing(4, ax=1.0)}, (1.0, 2.0, 1e-3), 0.01, None))
# a drawn model: a counter on the input u = sin t (plus 6e-8 sin t, so that it reads the time) at the level
# of three counters on x = sin t fired five times from zero, 1.1e-14 s apart, into a false storm
@example(case=({**_one_crossing(1, at=5.960464477539063e-08, au=1.0), **_one_crossing(2, ax=1.0),
                **_one_crossing(3, ax=1.0), **_one_crossing(4, ax=1.0)}, (1.0, 0.0, 1e-3), 0.01, 1e-8))
def test_model_exchange_fires_each_drawn_guard_only_in_its_direction(crossings, case):
    """fmpy's model exchange (CVode) on both backends: each counter counts exactly the crossings of its
    guard in its direction, each within 1e-3 s of the reference's, and both backends give the same
    bits. Before, a guard that CVode's root search saw on its before side only beyond another event's
    root (or, for a guard on the input, beyond its own root of the other direction, the input set for
    the later point first) fired at that root: a rising guard counted where it fell (a user's audit,
    2026-12-07: an input alarm 8 times instead of 7, a counter on sin t at every crossing of a state
    counter on x = sin t); then a counter on the input, its guard's motion at zero taken from the flow
    alone, fired again and again at one crossing. Where no guard reads the input, the FMU's
    co-simulation (its own engine) gives the same crossings, each at the reference's time within 1e-8 s."""
    p, signal, interval, rtol = case
    note(repr((p, signal, interval, rtol)))
    ref = _crossing_reference(p, signal)
    assume(ref is not None)
    runs = [_crossing_run(path, p, signal, interval, rtol) for path in crossings]
    assert runs[0].tobytes() == runs[1].tobytes(), "the two backends differ"
    r = runs[0]
    for name, t_ref in ref.items():
        n = r[name]
        up = np.flatnonzero(np.diff(n)) + 1
        assert n[-1] == len(t_ref), (name, int(n[-1]), len(t_ref), list(r["time"][up]), list(t_ref), p, signal)
        assert (np.diff(n) >= 0).all() and (np.diff(n) <= 1).all(), (name, list(r["time"][up]))
        assert np.allclose(r["time"][up], t_ref, rtol=0, atol=1e-3), (name, list(r["time"][up]), list(t_ref))
    if all(p[f"au{k}"] == 0.0 for k in CROSSING_DIRS):  # (co-simulation holds the input over a step)
        event("co-simulation checked too")
        runs = [_crossing_cs_events(path, p, interval) for path in crossings]
        assert runs[0] == runs[1], "the two backends differ in co-simulation"
        for name, t_ref in ref.items():  # the engine's own steps: each crossing located to rounding
            t_fmu = [t for n, t in runs[0] if n == name]
            assert len(t_fmu) == len(t_ref), ("co-simulation", name, t_fmu, list(t_ref))
            assert np.allclose(t_fmu, t_ref, rtol=0, atol=1e-8), ("co-simulation", name, t_fmu, list(t_ref))


# ---- inputs that move a guard: a platform under a ball, an input's step onto a counter's level ----------
PLATFORM_BALL = '''"""A ball bouncing on a platform whose position p and velocity vp are inputs."""
from pogofmu import FALLING, Event, HybridModel, Parameter, Variable

MODEL = HybridModel(
    name="PlatBall", description="a ball on a platform the importer moves",
    states=(Variable("h", "m", "ball height"), Variable("v", "m/s", "ball velocity")),
    parameters=(Parameter("g", 9.81, "m/s2", "gravity"), Parameter("e", 0.8, "", "restitution"),
                Parameter("h_0", 1.0, "m", "initial height")),
    inputs=(Variable("p", "m", "platform position", 0.0), Variable("vp", "m/s", "platform velocity", 0.0)),
    outputs=(Variable("h", "m", "ball height"), Variable("gap", "m", "h - p")),
    flow=lambda t, x, q, u, p: [x[1], -p.g],
    events=(Event("bounce", FALLING, guard=lambda x, q, u, p: x[0] - u[0],
                  jump=lambda x, q, u, p: ([x[0], u[1] - p.e * (x[1] - u[1])], q)),),
    initial=lambda p: ([p.h_0, 0.0], {}),
    output_fn=lambda t, x, q, u, p: {"h": x[0], "gap": x[0] - u[0]},
    feedthrough={"gap": ("p",)},
    default_stop_time=3.0,
)
'''
STEPS = '''"""A ramp x = 0.2 t against an input with steps: counters of x - u both ways."""
from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable

MODEL = HybridModel(
    name="Steps", description="a ramp against an input with steps",
    states=(Variable("x", "1", "ramp"),),
    parameters=(Parameter("a", 0.2, "1/s", "ramp rate"),),
    inputs=(Variable("u", "1", "input", 0.05),),
    outputs=(Variable("nR", "", "x - u rising"), Variable("nF", "", "x - u falling")),
    integer_outputs=frozenset({"nR", "nF"}),
    flow=lambda t, x, q, u, p: [p.a],
    events=(Event("nR", RISING, guard=lambda x, q, u, p: x[0] - u[0], jump=lambda x, q, u, p: (x, {**q, "nR": q["nR"] + 1})),
            Event("nF", FALLING, guard=lambda x, q, u, p: x[0] - u[0], jump=lambda x, q, u, p: (x, {**q, "nF": q["nF"] + 1}))),
    initial=lambda p: ([0.0], {"nR": 0, "nF": 0}),
    output_fn=lambda t, x, q, u, p: {"nR": q["nR"], "nF": q["nF"]},
)
'''

TOUCH = '''"""Counters of an input's crossings of a level, both ways, beside a clock."""
from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable

MODEL = HybridModel(
    name="Touch", description="counters of an input's crossings of a level",
    states=(Variable("c", "s", "clock"),),
    parameters=(Parameter("L", 0.5, "1", "level"),),
    inputs=(Variable("u", "1", "input", 0.0),),
    outputs=(Variable("nup", "", "u - L rising"), Variable("ndn", "", "u - L falling")),
    integer_outputs=frozenset({"nup", "ndn"}),
    flow=lambda t, x, q, u, p: [1.0],
    events=(Event("up", RISING, guard=lambda x, q, u, p: u[0] - p.L, jump=lambda x, q, u, p: (x, {**q, "nup": q["nup"] + 1})),
            Event("dn", FALLING, guard=lambda x, q, u, p: u[0] - p.L, jump=lambda x, q, u, p: (x, {**q, "ndn": q["ndn"] + 1}))),
    initial=lambda p: ([0.0], {"nup": 0, "ndn": 0}),
    output_fn=lambda t, x, q, u, p: {"nup": q["nup"], "ndn": q["ndn"]},
)
'''


@pytest.fixture(scope="module")
def input_models(tmp_path_factory):
    folder = tmp_path_factory.mktemp("input_models")
    (folder / "platball.py").write_text(PLATFORM_BALL)
    (folder / "steps.py").write_text(STEPS)
    (folder / "touch.py").write_text(TOUCH)
    proc = run_pogofmu("export", "platball.py", "steps.py", "touch.py", "--out", "out", "--fmi", "3", "--platforms",
                       "x86_64-linux", cwd=folder, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return folder / "out"


def _assert_me_counts(folder, name, stop_time, table, interval, rtol, ref):
    """Model exchange of both backends' FMU ``name`` under fmpy's input ``table``: no error, each event's
    times those of ``ref`` ({event: [times]}) within 1e-6 s, and the two backends' events the same."""
    runs = []
    for kind in ME_KINDS:
        exc, messages, _, events = _me_run(folder / kind.format(n=name), stop_time, table, interval, rtol)
        assert exc is None, (kind, exc, messages[-3:])
        runs.append([(e["name"], e["time"]) for e in events])
        for event_name, t_ref in ref.items():
            t_fmu = [t for n, t in runs[-1] if n == event_name]
            assert len(t_fmu) == len(t_ref) and np.allclose(t_fmu, t_ref, rtol=0, atol=1e-6), (kind, event_name, t_fmu)
    assert runs[0] == runs[1], "the two backends differ"


@pytest.mark.parametrize("speed", [0.05, -0.05, 0.3])
def test_a_ball_on_a_platform_the_importer_moves_ends_in_the_storm_never_under_it(input_models, speed):
    """The platform at a constant speed (the input table p = speed t, vp = speed), fmpy's CVode at 1e-8, run
    past the bounces' accumulation: each backend ends with the storm naming the bounce, the ball never
    under the platform on any row. Before, a change of the platform's position at the importer's next
    point, 2.3e-12 s after a bounce, was taken for an input step carrying the guard past zero: the
    bounce fired again with the ball moving away, its jump turned the ball into the platform, and it
    passed through (18.5 m under it at 6 s, status OK; a user's audit, 2026-12-07)."""
    table = np.array([(0.0, 0.0, speed), (10.0, 10 * speed, speed)], dtype=[("time", float), ("p", float), ("vp", float)])
    for kind in ME_KINDS:
        exc, messages, rows, events = _me_run(input_models / kind.format(n="PlatBall"), 6.0, table, 0.1, 1e-8)
        assert exc is not None, (kind, "ran to the end", len(events))
        storm = [m for m in messages if "event storm" in m]
        assert storm and "bounce" in storm[0], (kind, messages[-3:])
        gap = [r[-1] for r in rows]
        assert min(gap) > -1e-6, (kind, min(gap))
        assert 3.9 < events[-1]["time"] < 4.2, (kind, events[-1])  # (the accumulation: 4.04 to 4.07 s)


@pytest.mark.parametrize("interval,rtol", [(0.01, None), (0.1, 1e-8), (0.5, None), (0.5, 1e-8)])
def test_an_input_step_onto_a_counters_level_counts_once(input_models, interval, rtol):
    """x = 0.2 t against an input with steps (fmpy's table, two rows at a step's time): x - u falls through
    zero at 1 s (a step) and at 3 s (a step from 0.5 onto x = 0.6, u rising on at 0.3/s against x's 0.2/s),
    rises through it at 0.5 s, 5/3 s and 4 s (a step down). Each crossing is counted once, at its time,
    both backends the same. Before, the count at 3 s was made twice, 5.6e-14 s apart: the jump's
    re-arming, the input's rate after its step unknown, took the guard at zero for a rebound on the ramp's
    rate alone, and fmpy's re-setting of the input's value from before the step at that instant armed it
    (a user's audit, 2026-12-07)."""
    rows = [(0, .05), (1, .15), (1, .4), (2, .3), (2.5, .3), (2.5, .45), (3, .5), (3, .6), (4, .9), (4, .2), (5, .2)]
    table = np.array(rows, dtype=[("time", float), ("u", float)])
    ref = {"nR": [0.5, 5 / 3, 4.0], "nF": [1.0, 3.0]}  # (x - u is piecewise linear: its zeros by hand)
    _assert_me_counts(input_models, "Steps", 5.0, table, interval, rtol, ref)


@pytest.mark.parametrize("interval", [0.01, 0.1])
@pytest.mark.parametrize("start,peak,ref", [
    (0.0, 0.5, {"up": [0.5], "dn": []}),            # touches the level from below and turns back
    (1.0, 0.5, {"up": [], "dn": [0.5]}),            # from above
    (0.0, 0.51, {"up": [0.5 / 1.02], "dn": [0.5 + 0.01 / 1.02]}),  # crosses it and back (u = 1.02 t, ...)
])
def test_an_input_that_touches_a_counters_level_and_turns_counts_what_it_crosses(input_models, interval, start,
                                                                                  peak, ref):
    """fmpy's table u: a vertex at t = 0.5 (start -> peak -> start, straight lines), counters of u - 0.5 both
    ways: a touch from below is a rising crossing (RISING fires at >= 0) and no falling one (FALLING needs
    u > 0.5 first), a touch from above the reverse, and a peak 0.01 over the level both crossings, at their
    times, both backends the same. Until 2026-12-07 model exchange counted the touch from below as both: the
    re-arming at the rising count took the importer's secant (u still rising) for the input's future, armed
    the falling counter as a rebound at zero, and fired it as u turned back (a user's audit)."""
    rows = [(0.0, start), (0.5, peak), (1.0, start), (2.0, start)]
    table = np.array(rows, dtype=[("time", float), ("u", float)])
    _assert_me_counts(input_models, "Touch", 1.5, table, interval, 1e-8, ref)
