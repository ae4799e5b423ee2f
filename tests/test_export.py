"""``pogofmu export`` as a user runs it: model files written in a temporary folder outside the
repository, exported by the command, validated, and simulated through fmpy in FMI 2.0 CS, FMI 3.0
CS with event mode and FMI 3.0 ME, native and Python-hosted giving the same bits.

References are independent of the project's code: closed forms (the ball, the thermostat) and
scipy models of the same equations written here (the hard stop, the mem-spring leg, a random
family of piecewise-linear hybrid models).
"""
from __future__ import annotations

import math
import subprocess
import textwrap
import zipfile

import numpy as np
import pytest

from support import parse_event_log, run_pogofmu

CS2, CS3, ME3 = "FMI 2.0 CS", "FMI 3.0 CS event mode", "FMI 3.0 ME"

BALL = '''\
"""A bouncing ball: free fall, and a bounce with restitution e at the floor."""
from pogofmu import FALLING, Event, HybridModel, Parameter, Variable, require

h, v = Variable("h", "m", "height above the floor"), Variable("v", "m/s", "velocity (up)")

MODEL = HybridModel(
    name="Ball",
    description="bouncing ball",
    states=(h, v),
    parameters=(Parameter("g", 9.81, "m/s2", "gravitational acceleration"),
                Parameter("e", 0.8, "", "coefficient of restitution"),
                Parameter("h_0", 1.0, "m", "initial height")),
    inputs=(),
    outputs=(h, v),
    flow=lambda t, x, q, u, p: [x[1], -p.g],
    events=(Event("bounce", FALLING, guard=lambda x, q, u, p: x[0],
                  jump=lambda x, q, u, p: ([x[0], -p.e * x[1]], q)),),
    initial=lambda p: ([p.h_0, 0.0], {}),
    output_fn=lambda t, x, q, u, p: {"h": x[0], "v": x[1]},
    check=lambda p: require(0 <= p.e < 1, "e", p.e, "0 <= e < 1"),
    default_stop_time=3.0,
)
'''

HARD_STOP = '''\
"""A mass on a spring and a dashpot pushed by the input force F into a stiff Hunt-Crossley stop."""
from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable, require_positive
from pogofmu.elements import HuntCrossley

STOP = HuntCrossley()


def stop_force(x, q, p):
    if q["s"] == 1:
        return STOP.force_of(p, p.d0dot, x[0] - p.z_s, x[1])
    return 0.0


def check(p):
    require_positive(p, "m", "k")
    STOP.check(p)


MODEL = HybridModel(
    name="HardStop",
    description="force-driven oscillator against a stiff stop",
    states=(Variable("z", "m", "position"), Variable("zdot", "m/s", "velocity")),
    parameters=(Parameter("m", 1.0, "kg", "mass"), Parameter("k", 100.0, "N/m", "spring"),
                Parameter("c", 0.5, "N.s/m", "damping"), Parameter("z_s", 0.1, "m", "stop position"),
                Parameter("K", 1.0e7, "N/m^n", "stop stiffness"), Parameter("n", 1.0, "", "stop exponent"),
                Parameter("c_r", 0.8, "", "stop restitution"), Parameter("d0dot", 1.0, "m/s", "reference speed"),
                Parameter("d0dot_from_impact", 0, "", "reference speed from impacts", integer=True)),
    inputs=(Variable("F", "N", "driving force", 30.0),),
    outputs=(Variable("z", "m", "position"), Variable("F_stop", "N", "stop force"), Variable("s", "", "mode")),
    flow=lambda t, x, q, u, p: [x[1], (u[0] - p.k * x[0] - p.c * x[1] - stop_force(x, q, p)) / p.m],
    events=(Event("contact", RISING, guard=lambda x, q, u, p: x[0] - p.z_s,
                  jump=lambda x, q, u, p: (x, {"s": 1}), active=lambda q: q["s"] == 0),
            Event("release", FALLING, guard=lambda x, q, u, p: x[0] - p.z_s,
                  jump=lambda x, q, u, p: (x, {"s": 0}), active=lambda q: q["s"] == 1)),
    initial=lambda p: ([0.0, 0.0], {"s": 0}),
    output_fn=lambda t, x, q, u, p: {"z": x[0], "F_stop": stop_force(x, q, p), "s": q["s"]},
    check=check,
    integer_outputs=frozenset({"s"}),
    default_stop_time=1.0,
)
'''

# a local module beside the model file, and the older import path of the project's own models
THERMO_LAWS = '''\
"""The heater's laws, a local module of thermostat.py."""
from pogofmu.runtime.model import require


def rate(T, on, p):
    return (p.T_a + on * p.P * p.R - T) / p.tau


def check(p):
    require(p.tau > 0, "tau", p.tau, "tau > 0")
    require(p.T_a < p.T_low < p.T_high, "T_low", p.T_low, "T_a < T_low < T_high")
    require(p.T_a + p.P * p.R > p.T_high, "P", p.P, "T_a + P R > T_high (the heater can reach T_high)")
'''

THERMOSTAT = '''\
"""A room heated by an on/off heater with a hysteresis band: integer outputs, parameter rules."""
import thermo_laws
from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable

MODEL = HybridModel(
    name="Thermostat",
    description="on/off thermostat",
    states=(Variable("T", "degC", "room temperature"),),
    parameters=(Parameter("T_a", 5.0, "degC", "outside temperature"),
                Parameter("T_low", 19.0, "degC", "heater switches on below"),
                Parameter("T_high", 21.0, "degC", "heater switches off above"),
                Parameter("P", 2.0, "kW", "heater power"), Parameter("R", 10.0, "K/kW", "thermal resistance"),
                Parameter("tau", 600.0, "s", "time constant"), Parameter("T_0", 15.0, "degC", "initial temperature")),
    inputs=(),
    outputs=(Variable("T", "degC", "room temperature"), Variable("heater", "", "1 on, 0 off"),
             Variable("cycles", "", "times the heater switched on")),
    flow=lambda t, x, q, u, p: [thermo_laws.rate(x[0], q["on"], p)],
    events=(Event("off", RISING, guard=lambda x, q, u, p: x[0] - p.T_high,
                  jump=lambda x, q, u, p: (x, dict(q, on=0)), active=lambda q: q["on"] == 1),
            Event("on", FALLING, guard=lambda x, q, u, p: x[0] - p.T_low,
                  jump=lambda x, q, u, p: (x, dict(q, on=1, cycles=q["cycles"] + 1)), active=lambda q: q["on"] == 0)),
    initial=lambda p: ([p.T_0], {"on": 1, "cycles": 0}),
    output_fn=lambda t, x, q, u, p: {"T": x[0], "heater": q["on"], "cycles": q["cycles"]},
    check=thermo_laws.check,
    integer_outputs=frozenset({"heater", "cycles"}),
    default_stop_time=7200.0,
    default_step=1.0,
)
'''

MEM_LEG = '''\
"""A hopping mass on a mem-spring leg (pogofmu.elements.MemSpring), flight and contact."""
import pogofmu.elements as el
from pogofmu import FALLING, RISING, Event, HybridModel, Parameter, Variable

SPRING = el.MemSpring()


def flow(t, x, q, u, p):
    if q["s"] == 1:
        d = x[0] - p.x_i
        return [x[1], -SPRING.force(d, x[1], (x[2],), q, p) / p.m - p.g, d]
    return [x[1], -p.g, 0.0]


MODEL = HybridModel(
    name="MemLeg",
    description="mass on a mem-spring leg",
    states=(Variable("y", "m", "height"), Variable("ydot", "m/s", "velocity"), Variable("a", "m.s", "absement")),
    parameters=(Parameter("m", 1.0, "kg", "mass"), Parameter("g", 9.81, "m/s2", "gravity"),
                Parameter("x_i", 1.0, "m", "free leg length"), Parameter("y_0", 1.5, "m", "initial height"))
    + SPRING.parameters,
    inputs=(),
    outputs=(Variable("y", "m", "height"), Variable("s", "", "mode")),
    flow=flow,
    events=(Event("touchdown", FALLING, guard=lambda x, q, u, p: x[0] - p.x_i,
                  jump=lambda x, q, u, p: (x, {"s": 1}), active=lambda q: q["s"] == 0),
            Event("liftoff", RISING, guard=lambda x, q, u, p: x[0] - p.x_i,
                  jump=lambda x, q, u, p: (x, {"s": 0}), active=lambda q: q["s"] == 1)),
    initial=lambda p: ([p.y_0, 0.0, p.a_0], {"s": 0}),
    output_fn=lambda t, x, q, u, p: {"y": x[0], "s": q["s"]},
    check=SPRING.check,
    integer_outputs=frozenset({"s"}),
    default_stop_time=4.0,
)
'''

USER_MODELS = {"ball.py": BALL, "hard_stop.py": HARD_STOP, "thermostat.py": THERMOSTAT, "thermo_laws.py": THERMO_LAWS,
               "mem_leg.py": MEM_LEG}


def pogofmu(*args, cwd):
    return run_pogofmu(*args, cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The user's folder, with the model files and ``out/`` exported by one command."""
    folder = tmp_path_factory.mktemp("user_models")
    for name, text in USER_MODELS.items():
        (folder / name).write_text(text)
    proc = pogofmu("export", "ball.py", "hard_stop.py", "thermostat.py", "mem_leg.py", "--out", "out", cwd=folder)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    return folder


def fmus(folder, name):
    out = folder / "out"
    return {("python", CS2): out / f"{name}.fmu", ("native", CS2): out / "native" / f"{name}.fmu",
            ("python", CS3): out / "fmi3" / f"{name}.fmu", ("native", CS3): out / "native" / "fmi3" / f"{name}.fmu",
            ("python", ME3): out / "fmi3" / f"{name}.fmu", ("native", ME3): out / "native" / "fmi3" / f"{name}.fmu"}


def run(path, mode, stop, step, start=None):
    """fmpy's run of one FMU in one mode, with every event logged: (result, events)."""
    from fmpy import simulate_fmu

    messages = []
    kw = {CS2: {}, CS3: dict(fmi_type="CoSimulation", early_return_allowed=True, use_event_mode=True),
          ME3: dict(fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10)}[mode]
    res = simulate_fmu(str(path), stop_time=stop, output_interval=step, debug_logging=True,
                       start_values={"log_events": 1, "rel_tol": 1e-10, **(start or {})},
                       logger=lambda *a: messages.append((a[-3], a[-2].decode() if a[-2] else "", a[-1].decode())), **kw)
    assert res["time"][-1] == pytest.approx(stop), f"{path.name} {mode} stopped at {res['time'][-1]}"
    return res, parse_event_log(messages)


def runs(folder, name, stop, step, start=None):
    """Every mode, both backends; the native run of each mode gives the Python-hosted one's bits."""
    out = {}
    for mode in (CS2, CS3, ME3):
        a = run(fmus(folder, name)[("python", mode)], mode, stop, step, start)
        b = run(fmus(folder, name)[("native", mode)], mode, stop, step, start)
        for column in a[0].dtype.names:
            assert np.array_equal(a[0][column], b[0][column]), f"{name} {mode}: {column} differs between backends"
        assert [e["time"] for e in a[1]] == [e["time"] for e in b[1]]
        out[mode] = a
    return out


def test_export_writes_the_four_validated_fmus_laid_out_as_dist(exported):
    from fmpy.validation import validate_fmu

    for name in ("Ball", "HardStop", "Thermostat", "MemLeg"):
        for path in set(fmus(exported, name).values()):
            assert path.exists(), path
            assert validate_fmu(str(path)) == [], path
        with zipfile.ZipFile(fmus(exported, name)[("native", CS3)]) as z:
            assert any(n.startswith("sources/") for n in z.namelist())
    assert not (exported / "out" / "Ball").exists()  # nothing but the FMUs
    assert sorted(p.name for p in (exported / "out").iterdir()) == [
        "Ball.fmu", "HardStop.fmu", "MemLeg.fmu", "Thermostat.fmu", "fmi3", "native", "pogofmu-build.json"]


def test_ball_bounces_at_the_closed_form(exported):
    """Bounce k at t_1 + 2 t_1 sum_{j=1}^{k-1} e^j, t_1 = sqrt(2 h_0/g): within 1e-9 s in
    co-simulation (the FMU's own event location), 1e-6 s in model exchange (CVode's)."""
    t1, e = math.sqrt(2 * 1.0 / 9.81), 0.8
    for mode, (res, events) in runs(exported, "Ball", 3.0, 1e-3).items():
        times = [ev["time"] for ev in events if ev["name"] == "bounce"]
        assert len(times) >= 6, mode
        ref = [t1 + 2 * t1 * sum(e ** j for j in range(1, k)) for k in range(1, len(times) + 1)]
        tol = 1e-6 if mode == ME3 else 1e-9
        assert max(abs(a - b) for a, b in zip(times, ref)) < tol, mode


def test_ball_past_its_accumulation_point_ends_in_an_event_storm(tmp_path):
    """The ball whose jump keeps h (a hop shorter than a step near t_inf = t_1 (1+e)/(1-e)) fell
    through the floor silently; now the FMU ends with the event storm at t_inf, never below it."""
    (tmp_path / "ball.py").write_text(BALL)
    proc = pogofmu("export", "ball.py", "--out", "out", "--fmi", "2", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    from fmpy import simulate_fmu
    from fmpy.fmi1 import FMICallException

    t_inf = math.sqrt(2 / 9.81) * 1.8 / 0.2
    for path in (tmp_path / "out" / "Ball.fmu", tmp_path / "out" / "native" / "Ball.fmu"):
        messages = []
        with pytest.raises(FMICallException):
            simulate_fmu(str(path), stop_time=5.0, output_interval=1e-3, debug_logging=True,
                         logger=lambda *a: messages.append(a[4].decode()))
        storm = [m for m in messages if "event storm" in m]
        assert storm, messages[-3:]
        at = float(storm[0].split("t = ")[1].split(" s")[0])
        assert abs(at - t_inf) < 1e-6, storm[0]


def scipy_events(flow, events, x0, q0, stop, rtol=1e-12, atol=1e-14, method="DOP853"):
    """An independent hybrid integration with scipy: ``events`` are ``(name, direction, guard(x, q),
    active(q), jump(x, q) -> (x, q))``; returns [(name, time)] and the final state."""
    from scipy.integrate import solve_ivp

    t, x, q, out = 0.0, list(x0), dict(q0), []
    while t < stop:
        act = [ev for ev in events if ev[3](q)]
        fns = []
        for name, direction, guard, _, _ in act:
            fn = (lambda g: lambda tt, xx: g(xx, q))(guard)
            fn.terminal, fn.direction = True, direction
            fns.append(fn)
        sol = solve_ivp(lambda tt, xx: flow(xx, q), (t, stop), x, method=method, rtol=rtol, atol=atol, events=fns)
        hits = [(sol.t_events[k][0], k) for k in range(len(fns)) if len(sol.t_events[k]) and sol.t_events[k][0] > t]
        if not hits:
            return out, sol.y[:, -1]
        te, k = min(hits)
        xe = sol.y_events[k][0]
        out.append((act[k][0], te))
        x, q = act[k][4](list(xe), q)
        t = te
    return out, x


def test_hard_stop_contacts_match_an_independent_stiff_solve(exported):
    """K = 1e7 N/m: the contact and release times of every mode against scipy Radau at rtol 1e-12."""
    K, cr, d0 = 1.0e7, 0.8, 1.0
    lam = 1.5 * (1 - cr) * K / d0

    def flow(x, q):
        f = (K + lam * x[1]) * max(x[0] - 0.1, 0.0) if q["s"] == 1 else 0.0
        return [x[1], (30.0 - 100.0 * x[0] - 0.5 * x[1] - f) / 1.0]

    events = [("contact", 1, lambda x, q: x[0] - 0.1, lambda q: q["s"] == 0, lambda x, q: (x, {"s": 1})),
              ("release", -1, lambda x, q: x[0] - 0.1, lambda q: q["s"] == 1, lambda x, q: (x, {"s": 0}))]
    ref, _ = scipy_events(flow, events, [0.0, 0.0], {"s": 0}, 1.0, method="Radau", rtol=1e-12, atol=1e-15)
    assert len(ref) >= 4
    for mode, (res, evs) in runs(exported, "HardStop", 1.0, 1e-3).items():
        got = [(e["name"], e["time"]) for e in evs]
        assert [n for n, _ in got] == [n for n, _ in ref], mode
        tol = 1e-5 if mode == ME3 else 1e-8
        assert max(abs(a[1] - b[1]) for a, b in zip(got, ref)) < tol, mode


def test_thermostat_switches_at_the_closed_form_with_integer_outputs(exported):
    """Heating towards T_a + P R and cooling towards T_a are exponentials: every switching time in
    closed form; ``heater`` and ``cycles`` are integers in both FMI versions."""
    from fmpy import read_model_description

    Ta, lo, hi, Th, tau = 5.0, 19.0, 21.0, 25.0, 600.0
    ref, t, T, on = [], 0.0, 15.0, True
    while t < 7200:
        if on:
            t += tau * math.log((Th - T) / (Th - hi))
            T, name = hi, "off"
        else:
            t += tau * math.log((T - Ta) / (lo - Ta))
            T, name = lo, "on"
        on = not on
        if t < 7200:
            ref.append((name, t))
    for mode, (res, evs) in runs(exported, "Thermostat", 7200.0, 1.0).items():
        assert [(e["name"]) for e in evs] == [n for n, _ in ref], mode
        tol = 1e-4 if mode == ME3 else 1e-8
        assert max(abs(e["time"] - r) for e, (_, r) in zip(evs, ref)) < tol, mode
        assert res["cycles"][-1] == sum(1 for n, _ in ref if n == "on")
    types = {2: "Integer", 3: "Int32"}
    for fmi, path in ((2, fmus(exported, "Thermostat")[("python", CS2)]),
                      (3, fmus(exported, "Thermostat")[("python", CS3)])):
        md = read_model_description(str(path))
        kinds = {v.name: v.type for v in md.modelVariables}
        assert kinds["heater"] == kinds["cycles"] == types[fmi] and kinds["T"] in ("Real", "Float64")
        assert "degC" in [u.name for u in md.unitDefinitions]  # the user's own unit, declared


@pytest.mark.parametrize("backend", ["python", "native"])
def test_a_parameter_rule_of_a_user_model_refuses_with_its_message(exported, backend):
    from fmpy import simulate_fmu
    from fmpy.fmi1 import FMICallException

    messages = []
    with pytest.raises(FMICallException):
        simulate_fmu(str(fmus(exported, "Thermostat")[(backend, CS2)]), stop_time=10, start_values={"T_low": 22.0},
                     logger=lambda *a: messages.append(a[4].decode()), debug_logging=True)
    assert any("parameter T_low = 22.0 violates the rule: T_a < T_low < T_high" in m for m in messages), messages


def test_mem_leg_of_the_building_blocks_matches_an_independent_model(exported):
    """The mem-spring's softening law k / (1 + beta |a|), written here, in a scipy model."""
    def flow(x, q):
        if q["s"] == 1:
            d = x[0] - 1.0
            return [x[1], -100.0 / (1 + 1.0 * abs(x[2])) * d - 9.81, d]
        return [x[1], -9.81, 0.0]

    events = [("touchdown", -1, lambda x, q: x[0] - 1.0, lambda q: q["s"] == 0, lambda x, q: (x, {"s": 1})),
              ("liftoff", 1, lambda x, q: x[0] - 1.0, lambda q: q["s"] == 1, lambda x, q: (x, {"s": 0}))]
    ref, _ = scipy_events(flow, events, [1.5, 0.0, 0.0], {"s": 0}, 4.0)
    assert len(ref) >= 6
    for mode, (res, evs) in runs(exported, "MemLeg", 4.0, 1e-3).items():
        assert [e["name"] for e in evs] == [n for n, _ in ref], mode
        tol = 1e-5 if mode == ME3 else 1e-8
        assert max(abs(e["time"] - r) for e, (_, r) in zip(evs, ref)) < tol, mode


# ---- a random family of piecewise-linear hybrid models ------------------------------------------

def relay_model(name, n, lam, target_hi, target_lo, hi, lo, kappa, kick):
    """The text of a model: a relay with hysteresis on x0 (mode 1 drives x0 up to ``target_hi``,
    mode 0 down to ``target_lo``, switching at ``hi`` / ``lo``), the other states driven by x0
    (``kappa``) and kicked at every switch (``kick``)."""
    rows = [f"-{lam[0]!r} * x[0] + {lam[0]!r} * (({target_hi!r}) if q['s'] == 1 else ({target_lo!r}))"]
    rows += [f"-{lam[i]!r} * x[{i}] + {kappa[i]!r} * x[0]" for i in range(1, n)]
    kicked = ", ".join(["x[0]"] + [f"x[{i}] + {kick[i]!r}" for i in range(1, n)])
    states = ", ".join(f'Variable("x{i}", "", "state {i}")' for i in range(n))
    outputs = ", ".join([f'Variable("x{i}", "", "state {i}")' for i in range(n)] + ['Variable("s", "", "mode")'])
    values = ", ".join([f'"x{i}": x[{i}]' for i in range(n)] + ['"s": q["s"]'])
    return textwrap.dedent(f'''\
        {name} = HybridModel(
            name="{name}", description="random relay",
            states=({states},), parameters=(), inputs=(), outputs=({outputs},),
            flow=lambda t, x, q, u, p: [{", ".join(rows)}],
            events=(Event("up", RISING, guard=lambda x, q, u, p: x[0] - {hi!r},
                          jump=lambda x, q, u, p: ([{kicked}], {{"s": 0}}), active=lambda q: q["s"] == 1),
                    Event("down", FALLING, guard=lambda x, q, u, p: x[0] - {lo!r},
                          jump=lambda x, q, u, p: ([{kicked}], {{"s": 1}}), active=lambda q: q["s"] == 0)),
            initial=lambda p: ([0.0] * {n}, {{"s": 1}}),
            output_fn=lambda t, x, q, u, p: {{{values}}},
            integer_outputs=frozenset({{"s"}}), default_stop_time=3.0)
        ''')


def test_random_piecewise_linear_models_match_scipy(tmp_path):
    """Hypothesis draws relays of 1-3 states (rates, thresholds, couplings, kicks); all of them go into
    one model file, exported at once (FMI 2.0, both backends); each one's events and final state
    against scipy DOP853 at rtol 1e-12, the native FMU giving the Python-hosted one's bits."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    drawn = []
    rate = st.floats(0.5, 5.0)

    @settings(max_examples=5, derandomize=True, deadline=None, suppress_health_check=list(HealthCheck),
              database=None)
    @given(n=st.integers(1, 3), lam=st.lists(rate, min_size=3, max_size=3), hi=st.floats(0.3, 0.8),
           band=st.floats(0.1, 0.25), over=st.floats(0.2, 1.0), kappa=st.lists(st.floats(-2, 2), min_size=3, max_size=3),
           kick=st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3))
    def draw(n, lam, hi, band, over, kappa, kick):
        drawn.append(dict(n=n, lam=lam, hi=hi, lo=hi - band, target_hi=hi + over, target_lo=hi - band - over,
                          kappa=kappa, kick=kick))

    draw()
    assert len(drawn) == 5
    text = "from pogofmu import FALLING, RISING, Event, HybridModel, Variable\n\n"
    text += "\n".join(relay_model(f"Relay{k}", **d) for k, d in enumerate(drawn))
    (tmp_path / "relays.py").write_text(text)
    proc = pogofmu("export", "relays.py", "--out", "out", "--fmi", "2", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    for k, d in enumerate(drawn):
        n = d["n"]

        def flow(x, q, d=d, n=n):
            target = d["target_hi"] if q["s"] == 1 else d["target_lo"]
            return [-d["lam"][0] * x[0] + d["lam"][0] * target] + \
                [-d["lam"][i] * x[i] + d["kappa"][i] * x[0] for i in range(1, n)]

        def kicked(x, d=d, n=n):
            return [x[0]] + [x[i] + d["kick"][i] for i in range(1, n)]

        events = [("up", 1, lambda x, q, d=d: x[0] - d["hi"], lambda q: q["s"] == 1, lambda x, q: (kicked(x), {"s": 0})),
                  ("down", -1, lambda x, q, d=d: x[0] - d["lo"], lambda q: q["s"] == 0, lambda x, q: (kicked(x), {"s": 1}))]
        ref, x_end = scipy_events(flow, events, [0.0] * n, {"s": 1}, 3.0)
        assert len(ref) >= 2
        a = run(tmp_path / "out" / f"Relay{k}.fmu", CS2, 3.0, 1e-2)
        b = run(tmp_path / "out" / "native" / f"Relay{k}.fmu", CS2, 3.0, 1e-2)
        for column in a[0].dtype.names:
            assert np.array_equal(a[0][column], b[0][column]), f"Relay{k}: {column}"
        assert [e["name"] for e in a[1]] == [r[0] for r in ref]
        assert max(abs(e["time"] - r[1]) for e, r in zip(a[1], ref)) < 1e-8
        assert np.allclose([a[0][f"x{i}"][-1] for i in range(n)], x_end, rtol=1e-7, atol=1e-9)


# ---- mistakes in a model file: one line naming the file and the line, no traceback -------------

def _line_of(text, needle):
    return next(i for i, line in enumerate(text.splitlines(), start=1) if needle in line)


MISTAKES = {
    # name: (replace this, with this, the line to name (a text on it), words of the message)
    "flow returns the wrong number of values": (
        "flow=lambda t, x, q, u, p: [x[1], -p.g]", "flow=lambda t, x, q, u, p: [x[1]]", "flow=",
        "flow returns 1 value(s) but the model has 2 state(s)"),
    "a guard that is not a number": (
        "guard=lambda x, q, u, p: x[0],", "guard=lambda x, q, u, p: x[0] > 0,", "guard=",
        "the guard returns True (bool): a guard is a number"),
    "an output returned but not declared": (
        'output_fn=lambda t, x, q, u, p: {"h": x[0], "v": x[1]}',
        'output_fn=lambda t, x, q, u, p: {"h": x[0], "v": x[1], "E": x[1] ** 2}', "output_fn=",
        "output_fn returns 'E', which is not declared in outputs"),
    "an input used but not declared": (
        "flow=lambda t, x, q, u, p: [x[1], -p.g]", "flow=lambda t, x, q, u, p: [x[1], -p.g + u[0]]", "flow=",
        "IndexError: tuple index out of range (in flow: u holds the 0 declared input(s)"),
    "a parameter used but not declared": (
        "flow=lambda t, x, q, u, p: [x[1], -p.g]", "flow=lambda t, x, q, u, p: [x[1], -p.gravity]", "flow=",
        "parameter 'gravity' is used in flow but not declared"),
    "duplicate names": (
        'Parameter("h_0", 1.0, "m", "initial height")', 'Parameter("g", 1.0, "m", "initial height")',
        'Parameter("g", 1.0', "duplicate name 'g': parameter here and parameter at"),
    "a name that is not a valid FMI name": (
        'Parameter("h_0", 1.0, "m", "initial height")', 'Parameter("h 0", 1.0, "m", "initial height")',
        'Parameter("h 0"', "parameter name 'h 0' is not a valid name"),
    "a name that collides with a solver parameter": (
        'Parameter("h_0", 1.0, "m", "initial height")', 'Parameter("rel_tol", 1.0, "m", "initial height")',
        'Parameter("rel_tol"', "parameter 'rel_tol' collides with a solver setting of every pogofmu FMU"),
    "a name that collides with an engine output": (
        "    outputs=(h, v),", '    outputs=(h, Variable("n_events", "", "count")),', "n_events",
        "output 'n_events' collides with an output the engine adds to every FMU"),
    "a default that breaks its own rule": (
        'Parameter("e", 0.8, "", "coefficient of restitution")', 'Parameter("e", 1.5, "", "coefficient of restitution")',
        'Parameter("e", 1.5', "the default breaks its own rule: parameter e = 1.5 violates the rule: 0 <= e < 1"),
    "a model whose initial raises": (
        "initial=lambda p: ([p.h_0, 0.0], {}),", "initial=lambda p: ([p.h_0 / 0.0, 0.0], {}),", "initial=",
        "ZeroDivisionError: float division by zero"),
    "a unit that is not a unit": (
        'Variable("h", "m", "height above the floor")', 'Variable("h", "m<2>", "height above the floor")',
        'Variable("h", "m<2>"', "has the unit 'm<2>': the character '<' has no place in a unit name"),
}


@pytest.mark.parametrize("mistake", list(MISTAKES))
def test_a_mistake_in_a_model_file_is_one_line_naming_file_and_line(tmp_path, mistake):
    old, new, where, words = MISTAKES[mistake]
    assert old in BALL
    text = BALL.replace(old, new)
    (tmp_path / "ball.py").write_text(text)
    for args in (("--check",), ("--out", "out")):
        proc = pogofmu("export", "ball.py", *args, cwd=tmp_path)
        assert proc.returncode == 2, (mistake, proc.stdout, proc.stderr)
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
        assert f"ball.py:{_line_of(text, where)}:" in lines[0], lines[0]
        assert words in lines[0], lines[0]
    assert not (tmp_path / "out").exists()  # nothing written


def test_an_int_default_without_integer_true_is_a_real_parameter(tmp_path):
    """docs/writing-models.md: the declaration sets the type, not how the default is written. An int
    default passes --check and the FMU declares a Real parameter that an importer sets to a value
    that is not whole: the first bounce at t_1 = sqrt(2 h_0/g) for h_0 = 1.5."""
    from fmpy import read_model_description

    old = 'Parameter("h_0", 1.0, "m", "initial height")'
    assert old in BALL
    (tmp_path / "ball.py").write_text(BALL.replace(old, 'Parameter("h_0", 2, "m", "initial height")'))
    proc = pogofmu("export", "ball.py", "--check", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    proc = pogofmu("export", "ball.py", "--out", "out", "--fmi", "2", "--backend", "python", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    path = tmp_path / "out" / "Ball.fmu"
    h_0 = next(v for v in read_model_description(str(path)).modelVariables if v.name == "h_0")
    assert h_0.type == "Real" and float(h_0.start) == 2.0
    _, events = run(path, CS2, 0.6, 1e-2, start={"h_0": 1.5})
    assert abs(events[0]["time"] - math.sqrt(2 * 1.5 / 9.81)) < 1e-8, events


@pytest.mark.parametrize("case", ["syntax", "third-party", "host-side", "no model"])
def test_files_that_cannot_be_exported_are_refused_in_one_line(tmp_path, case):
    text = {"syntax": BALL.replace("inputs=(),", "inputs=(,"),
            "third-party": BALL.replace('"""\n', '"""\nimport numpy\n', 1),
            "host-side": BALL.replace('"""\n', '"""\nimport pogofmu.ssp\n', 1),
            "no model": "x = 1\n"}[case]
    words = {"syntax": "syntax error", "third-party": "import of the third-party module 'numpy'",
             "host-side": "`pogofmu.ssp` is host-side pogofmu code", "no model": "defines no HybridModel"}[case]
    (tmp_path / "ball.py").write_text(text)
    proc = pogofmu("export", "ball.py", "--check", cwd=tmp_path)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert words in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    if case in ("syntax", "third-party", "host-side"):
        assert "ball.py:" in proc.stderr


def test_a_declared_third_party_requirement_is_recorded_and_imported_in_the_fmu(tmp_path):
    text = BALL.replace('"""\n', '"""\nimport numpy\n', 1).replace("-p.g]", "-p.g * float(numpy.float64(1.0))]")
    (tmp_path / "ball.py").write_text(text)
    proc = pogofmu("export", "ball.py", "--out", "out", "--requires", "numpy", "--backend", "python", "--fmi", "2",
                   cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    with zipfile.ZipFile(tmp_path / "out" / "Ball.fmu") as z:
        assert z.read("documentation/requirements.txt").decode().split() == ["numpy"]
        assert "numpy" in z.read("documentation/index.html").decode()
    res, events = run(tmp_path / "out" / "Ball.fmu", CS2, 1.0, 1e-3)
    assert len(events) == 1


NATIVE_REFUSALS = {
    # name: (replace, with, the line, the construct, the rewrite)
    "a loop whose trip count depends on a state": (
        "guard=lambda x, q, u, p: x[0],", "guard=lambda x, q, u, p: steps(x[0]),", "while h > n",
        "a loop whose trip count depends on a state", "a loop of a fixed count"),
    "a call into math outside fmath": (
        "flow=lambda t, x, q, u, p: [x[1], -p.g]", "flow=lambda t, x, q, u, p: [x[1], -math.sqrt(p.g * p.g)]",
        "math.sqrt", "math.sqrt(...) of a traced value", "fmath.sqrt(...)"),
    "an unsupported builtin": (
        "flow=lambda t, x, q, u, p: [x[1], -p.g]", "flow=lambda t, x, q, u, p: [x[1], -round(p.g)]",
        "round(p.g)", "__round__", "math.trunc(v + 0.5)"),
    "a value that is not a float": (
        "flow=lambda t, x, q, u, p: [x[1], -p.g]", "flow=lambda t, x, q, u, p: [x[1], -p.g * int(p.e + 1)]",
        "int(p.e + 1)", "int() of a traced value", "math.trunc(v)"),
    "a linear map whose matrix is not a constant": (
        "flow=lambda t, x, q, u, p: [x[1], -p.g]", "flow=lambda t, x, q, u, p: [x[1], -fmath.matvec([[p.g]], [1.0])[0]]",
        "fmath.matvec([[p.g]]", "Ball: flow: fmath.matvec: the matrix entry [0][0] is a computed value",
        "rule: the matrix of fmath.matvec is a constant known when the model is built"),
}
HELPERS = '''import math

from pogofmu import fmath


def steps(h):
    n = 0.0
    while h > n:
        n = n + 1.0
    return h - n + 1.0

'''


@pytest.mark.parametrize("case", list(NATIVE_REFUSALS))
def test_a_construct_the_native_generator_cannot_follow_is_refused_naming_line_and_rewrite(tmp_path, case):
    """The Python-hosted FMUs are still written; no native FMU; exit status 1; one line each."""
    old, new, where, construct, rewrite = NATIVE_REFUSALS[case]
    text = BALL.replace('h, v = Variable', HELPERS + 'h, v = Variable').replace(old, new)
    (tmp_path / "ball.py").write_text(text)
    check = pogofmu("export", "ball.py", "--check", cwd=tmp_path)
    proc = pogofmu("export", "ball.py", "--out", "out", "--fmi", "2", cwd=tmp_path)
    for p in (check, proc):
        assert p.returncode == 1, p.stderr
        assert len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr, p.stderr
        assert f"ball.py:{_line_of(text, where)}:" in p.stderr and construct in p.stderr and rewrite in p.stderr, p.stderr
    assert (tmp_path / "out" / "Ball.fmu").exists() and not (tmp_path / "out" / "native").exists()
    res, events = run(tmp_path / "out" / "Ball.fmu", CS2, 1.0, 1e-3)  # the Python-hosted FMU runs
    assert len(events) == 1


def test_a_users_fmus_run_in_a_venv_with_fmpy_only(exported):
    """As a colleague runs them: a venv with fmpy and numpy only (no pogofmu), a fresh process."""
    from support import clean_venv

    script = textwrap.dedent('''\
        import sys
        from fmpy import simulate_fmu
        for path in sys.argv[1:]:
            res = simulate_fmu(path, stop_time=3.0, output_interval=1e-3)
            print(int(res["n_events"][-1]), repr(float(res["h"][-1])))
        ''')
    out = exported / "out"
    paths = [out / "Ball.fmu", out / "native" / "Ball.fmu", out / "fmi3" / "Ball.fmu", out / "native" / "fmi3" / "Ball.fmu"]
    proc = subprocess.run([str(clean_venv()), "-I", "-c", script, *map(str, paths)], capture_output=True, text=True,
                          cwd=exported, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.split()
    assert len(lines) == 8 and len(set(lines[0::2])) == 1 and int(lines[0]) >= 6  # the same events everywhere
    assert len(set(lines[1::2])) == 1  # and the same final height, to the bit


def wide_ball(n_inputs):
    """The ball with ``n_inputs`` unused inputs (the engine holds at most 1024: a reconstructor of a
    12-ring segmented mirror takes 469)."""
    return BALL.replace("inputs=(),", f'inputs=tuple(Variable(f"u{{i}}", "N", "unused force") for i in range({n_inputs})),')


def test_a_model_wider_than_the_engine_is_refused_in_one_line_for_every_backend(tmp_path):
    (tmp_path / "ball.py").write_text(wide_ball(1025))
    for backend in ("python", "native"):
        proc = pogofmu("export", "ball.py", "--check", "--backend", backend, cwd=tmp_path)
        assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
        assert "1025 inputs" in proc.stderr and "at most 1024 (PG_MAX_U" in proc.stderr, proc.stderr
    (tmp_path / "ball.py").write_text(wide_ball(1024))
    proc = pogofmu("export", "ball.py", "--check", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr


def test_the_engine_itself_refuses_a_model_wider_than_it_naming_the_count(tmp_path):
    """Past the exporter (a model handed to the engine directly): the engine's own refusal; one
    input fewer runs."""
    from pogofmu.exporter.source import load_model_file
    from pogofmu.runtime.solver.cengine import Simulator
    from pogofmu.runtime.model import ModelError

    models = {}
    for n in (1024, 1025):
        (tmp_path / f"ball_{n}.py").write_text(wide_ball(n))
        models[n] = load_model_file(tmp_path / f"ball_{n}.py")[0].model
    with pytest.raises(ModelError, match=r"the model has 1025 inputs; the engine takes at most 1024 \(PG_MAX_U\)"):
        Simulator(models[1025], u=[0.0] * 1025)
    sim = Simulator(models[1024], u=[0.0] * 1024)
    x, _ = sim.advance(0.1)
    assert x[0] == pytest.approx(1.0 - 9.81 * 0.1 ** 2 / 2, rel=1e-9)


def test_platforms_chooses_the_native_binaries_and_an_unknown_one_is_refused(tmp_path):
    """``--platforms``: the native FMUs carry exactly the binaries asked for (FMI 2.0's folder names
    for them, FMI 3.0's tuples); an unknown platform is a command-line mistake (exit 2, one line)."""
    (tmp_path / "ball.py").write_text(BALL)
    bad = pogofmu("export", "ball.py", "--out", "out", "--platforms", "x86_64-linux,sparc-solaris", cwd=tmp_path)
    assert bad.returncode == 2 and "sparc-solaris" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
    proc = pogofmu("export", "ball.py", "--out", "out", "--backend", "native", "--platforms",
                   "aarch64-darwin,x86_64-linux", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    for fmu, want in ((tmp_path / "out" / "native" / "Ball.fmu", {"darwin64/Ball.dylib", "linux64/Ball.so"}),
                      (tmp_path / "out" / "native" / "fmi3" / "Ball.fmu",
                       {"aarch64-darwin/Ball.dylib", "x86_64-linux/Ball.so"})):
        with zipfile.ZipFile(fmu) as z:
            got = {n.split("/", 1)[1] for n in z.namelist() if n.startswith("binaries/")}
        assert got == want, (fmu, got)


# ---- a failed export: nothing left behind, the failure named, exit status 1 ---------------------

def _leftovers(folder):
    """Every file under ``folder`` (an FMU, a temporary file, the build record)."""
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()) if folder.exists() else []


def _export_failing_on_the_machine(proc, cwd, out, reason):
    """``out``: the FMU the export could not write (relative to ``cwd``, as the command shows it)."""
    assert proc.returncode == 1, (proc.returncode, proc.stdout, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert f"cannot write {out}" in lines[0] and reason in lines[0], lines[0]
    assert "ball.py" not in lines[0], lines[0]  # the model is not blamed
    folder = (cwd / out).parent
    assert _leftovers(folder) == [], _leftovers(folder)


def _limit_file_size(limit):
    """preexec_fn: files larger than ``limit`` bytes cannot be written (write fails with EFBIG:
    SIGXFSZ ignored, which the exec'd Python keeps)."""
    import resource
    import signal

    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


def test_an_fmu_too_large_for_the_file_system_leaves_nothing_and_blames_the_output(tmp_path):
    """RLIMIT_FSIZE below the FMU's size (the cache of compiled launchers warm, so that only the FMU
    itself is too large): exit status 1, one line naming the FMU and the reason, no temporary file,
    no FMU; the same export without the limit writes it."""
    import errno
    import os
    import sys

    (tmp_path / "ball.py").write_text(BALL)
    args = [sys.executable, "-m", "pogofmu.cli", "export", "ball.py", "--backend", "python", "--fmi", "2",
            "--cache", "cache"]
    warm = subprocess.run([*args, "--out", "warm"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert warm.returncode == 0, warm.stderr
    size = (tmp_path / "warm" / "Ball.fmu").stat().st_size
    limit = size * 3 // 4
    proc = subprocess.run([*args, "--out", "out"], cwd=tmp_path, capture_output=True, text=True, timeout=600,
                          preexec_fn=_limit_file_size(limit))
    _export_failing_on_the_machine(proc, tmp_path, "out/Ball.fmu", os.strerror(errno.EFBIG))


def test_an_export_under_a_file_leaves_nothing_and_blames_the_output(tmp_path):
    """--out below a regular file (a folder that cannot be made, as a read-only one cannot be
    written, even by root): exit status 1 naming the FMU and the reason."""
    import errno
    import os

    (tmp_path / "ball.py").write_text(BALL)
    (tmp_path / "taken").write_text("a file, not a folder\n")
    proc = pogofmu("export", "ball.py", "--out", "taken/out", "--backend", "python", "--fmi", "2", cwd=tmp_path)
    _export_failing_on_the_machine(proc, tmp_path, "taken/out/Ball.fmu", os.strerror(errno.ENOTDIR))
    assert (tmp_path / "taken").read_text() == "a file, not a folder\n"


def test_an_export_into_a_full_file_system_leaves_nothing_and_blames_the_output(tmp_path):
    """A 64 KiB tmpfs (an FMU is ~140 KiB): "No space left on device", exit status 1, nothing left.
    Skipped where tmpfs cannot be mounted (not root, no CAP_SYS_ADMIN)."""
    import errno
    import os

    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)], capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs here")  # (a privilege, not a package: RLIMIT_FSIZE tests cover the rest)
    try:
        (tmp_path / "ball.py").write_text(BALL)
        proc = pogofmu("export", "ball.py", "--out", "mnt", "--backend", "python", "--fmi", "2", cwd=tmp_path)
        _export_failing_on_the_machine(proc, tmp_path, "mnt/Ball.fmu", os.strerror(errno.ENOSPC))
    finally:
        subprocess.run(["umount", str(mnt)], check=True)


@pytest.mark.parametrize("failure", [KeyboardInterrupt, OSError(28, "No space left on device"), "invalid"])
def test_an_fmu_is_written_whole_or_not_at_all(tmp_path, monkeypatch, failure):
    """Ctrl-C or a failed write half-way through an FMU, or an FMU that does not validate: the
    earlier FMU of that name is untouched and no temporary file stays; Ctrl-C stays Ctrl-C, a failed
    write is an OutputError naming the FMU."""
    from pogofmu.exporter import package
    from pogofmu.exporter.errors import BuildError, OutputError

    out = tmp_path / "Ball.fmu"
    out.write_bytes(b"the earlier FMU")
    members = [(f"resources/{k}.txt", b"x" * 1000, False) for k in range(5)]
    if failure == "invalid":
        with pytest.raises(BuildError, match="Ball.fmu .FMI 2.0.: fmpy validation failed"):
            package.write_zip(out, members, "FMI 2.0")
    else:
        calls = []
        real = zipfile.ZipFile.writestr

        def writestr(self, *a, **kw):
            calls.append(a)
            if len(calls) == 3:
                raise failure
            return real(self, *a, **kw)
        monkeypatch.setattr(zipfile.ZipFile, "writestr", writestr)
        expected = (KeyboardInterrupt, None) if failure is KeyboardInterrupt else \
            (OutputError, f"cannot write {out}: No space left on device")
        with pytest.raises(expected[0], match=expected[1]):
            package.write_zip(out, members)
        assert len(calls) == 3
    assert out.read_bytes() == b"the earlier FMU"
    assert _leftovers(tmp_path) == ["Ball.fmu"]


def test_export_help_tells_the_exit_statuses():
    proc = run_pogofmu("export", "--help", cwd=".", timeout=60)
    assert proc.returncode == 0
    text = " ".join(proc.stdout.split())
    assert "exit status: 0" in text and "2 a mistake in a model file or the command line" in text
    assert "1 the machine failed the export" in text


# ---- a function of the model that fails during the run: one message naming it ----------------

NAN_LINE = "NAN = float('nan')\n"
FAILING = {  # (name, the line of BALL replaced, its replacement, the function the message names)
    "flow returns NaN": ("BallNaN", "    flow=lambda t, x, q, u, p: [x[1], -p.g],",
                         "    flow=lambda t, x, q, u, p: [x[1], -p.g if t < 0.3 else NAN],", "the flow"),
    "flow raises": ("BallDiv", "    flow=lambda t, x, q, u, p: [x[1], -p.g],",
                    "    flow=lambda t, x, q, u, p: [x[1], -p.g / (1.0 if t < 0.3 else 0.0)],", "the flow"),
    "guard returns NaN": ("BallGuard", "guard=lambda x, q, u, p: x[0],",
                          "guard=lambda x, q, u, p: x[0] if x[1] > -2.0 else NAN,", "the guard of event bounce"),
    "output returns NaN": ("BallOut", 'output_fn=lambda t, x, q, u, p: {"h": x[0], "v": x[1]},',
                           'output_fn=lambda t, x, q, u, p: {"h": x[0], "v": x[1] if t < 0.3 else NAN},',
                           "the outputs"),
    # (an output of a state's name that is not the state: FMI 2.0 served the function's value and FMI 3.0
    # the state's, silently, in every kind (a user's audit); the export checks only the default start)
    "output of a state's name is not the state": ("BallAlias", 'output_fn=lambda t, x, q, u, p: {"h": x[0], "v": x[1]},',
                                                  'output_fn=lambda t, x, q, u, p: {"h": x[0] + (0.0 if t < 0.3 else 1.0), "v": x[1]},',
                                                  "the outputs"),
    "jump raises": ("BallJump", "jump=lambda x, q, u, p: ([x[0], -p.e * x[1]], q)),),",
                    "jump=lambda x, q, u, p: ([x[0], -p.e * x[1] / (1.0 if x[1] > -1.0 else 0.0)], q)),),", "the jump of event bounce"),
}


# the ball whose flow is NaN for a start height h_0 >= 5 m and whose guard is NaN for 4 <= h_0 < 5 (the
# default start, 1 m, is clean: the export runs it)
BALL_START = BALL.replace('name="Ball"', 'name="BallStart"').replace(
    "    flow=lambda t, x, q, u, p: [x[1], -p.g],", "    flow=lambda t, x, q, u, p: [x[1], -p.g if p.h_0 < 5.0 else NAN],").replace(
    "guard=lambda x, q, u, p: x[0],", "guard=lambda x, q, u, p: x[0] if not 4.0 <= p.h_0 < 5.0 else NAN,").replace(
    "from pogofmu import", NAN_LINE + "from pogofmu import", 1)


@pytest.fixture(scope="module")
def failing(tmp_path_factory):
    """The ball, six ways broken, exported by one command (every kind of FMU)."""
    folder = tmp_path_factory.mktemp("failing_models")
    files = []
    for case, (name, old, new, _) in FAILING.items():
        assert old in BALL, case
        text = BALL.replace('name="Ball"', f'name="{name}"').replace(old, new).replace(
            "from pogofmu import", NAN_LINE + "from pogofmu import", 1)
        (folder / f"{name.lower()}.py").write_text(text)
        files.append(f"{name.lower()}.py")
    (folder / "ballstart.py").write_text(BALL_START)
    files.append("ballstart.py")
    proc = pogofmu("export", *files, "--out", "out", cwd=folder)
    assert proc.returncode == 0, proc.stderr
    return folder


def _failure_text(path, mode):
    """fmpy's run of ``path`` to 1 s (co-simulation, or model exchange through fmpy's CVode): it must
    fail; the FMU's first Error message."""
    from fmpy import simulate_fmu
    from fmpy.fmi1 import FMICallException

    messages = []
    kw = {CS2: {}, CS3: dict(fmi_type="CoSimulation", early_return_allowed=True, use_event_mode=True),
          ME3: dict(fmi_type="ModelExchange", relative_tolerance=1e-8)}[mode]
    # (fmpy's CVode takes a failing right-hand side for a recoverable one and raises its own RuntimeError)
    with pytest.raises(FMICallException if mode != ME3 else (FMICallException, RuntimeError)):
        simulate_fmu(str(path), stop_time=1.0, output_interval=1e-2, debug_logging=True,
                     logger=lambda *a: messages.append((a[-3], a[-1].decode())), **kw)
    errors = [text for status, text in messages if status >= 3]
    assert errors, messages[-5:]
    return errors[0]


@pytest.mark.parametrize("case", list(FAILING))
def test_a_function_of_the_model_that_fails_is_named_with_time_state_and_cause(failing, case):
    """A flow, guard, jump or output that returns NaN or raises ends the run of every kind of FMU with one
    message naming the function, the time (the model's own threshold: NaN/division from t = 0.3 s,
    the output's NaN from t = 0.3 s, the guard's NaN once v < -2 m/s, the jump at the first
    bounce), the state, and the cause: NaN,
    or the exception — in a Python-hosted FMU its type, the model file and the line; in a native
    FMU (C, no exception) the failure's kind. Not a collapsed step, not "exceed floating-point
    range". In FMI 3.0 model exchange too, where the importer integrates: there the flow's NaN went
    to CVode with status OK (no message from the FMU, CVode's own "mxstep" error), the output's NaN
    was served by fmi3GetFloat64 with status OK (a result with NaN from 0.3 s, no error), and a
    guard's failure came without the model's name (a user's audit). The times there are CVode's: the
    first point it tried past the threshold."""
    import re

    name, old, new, function = FAILING[case]
    text = (failing / f"{name.lower()}.py").read_text()
    line = next(k for k, row in enumerate(text.splitlines(), 1) if new.strip() in row)
    t_bounce = math.sqrt(2 * 1.0 / 9.81)
    for backend in ("python", "native"):
        for mode in (CS2, CS3, ME3):
            msg = _failure_text(fmus(failing, name)[(backend, mode)], mode)
            where = (backend, mode, msg)
            assert msg.startswith(f"{name}: ") or mode != ME3, where
            assert f"{function} failed at t = " in msg and "(state h = " in msg and ", v = " in msg, where
            t = float(re.search(r"failed at t = ([0-9.eE+-]+) s", msg).group(1))
            if case.startswith(("flow", "output")):
                assert 0.3 <= t < (0.31 if mode != ME3 else 0.4), where
            elif case.startswith("guard"):
                assert 2.0 / 9.81 <= t < t_bounce, where
            else:
                assert t == pytest.approx(t_bounce, abs=1e-6 if mode != ME3 else 1e-4), where
            assert "stiff or singular" not in msg and "exceed floating-point range" not in msg, where
            if "NaN" in case:
                assert "it returned " in msg and " = nan" in msg or "returned nan" in msg, where
            elif "state's name" in case:
                h = float(re.search(r"\(state h = ([0-9.eE+-]+)", msg).group(1))
                assert f"it returned h = {h + 1.0!r}, which violates the rule: an output that shares a state's name " \
                       f"carries that state's value (h = {h!r})" in msg, where
            elif backend == "python":
                assert f"ZeroDivisionError: float division by zero at {name.lower()}.py:{line}" in msg, where
            else:
                assert "floating-point division by zero (float division by zero)" in msg, where


@pytest.mark.parametrize("backend", ["python", "native"])
def test_initialization_mode_refuses_a_start_whose_flow_or_guard_is_not_finite(failing, backend):
    """FMI 3.0 model exchange in Initialization Mode: an importer asks the rates and the event
    indicators at the start before fmi3ExitInitializationMode. They came from the model with status
    OK even when the flow or a guard returned NaN there: the NaN went to the importer (the exit
    refused the start only afterwards, and named no function: "the values exceed floating-point
    range"). Now the call is refused, as the exit is, naming the function, the start's time and
    state, and the value."""
    import ctypes

    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi3 import FMU3Model

    path = fmus(failing, "BallStart")[(backend, ME3)]
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = extract(str(path))
    cases = [(6.0, "getContinuousStateDerivatives", "fmi3GetContinuousStateDerivatives", 2,
              "the flow failed at t = 0.0 s (state h = 6.0, v = 0.0): it returned dv/dt = nan "
              "(a model function must return finite numbers)"),
             (4.5, "getEventIndicators", "fmi3GetEventIndicators", 1,
              "the guard of event bounce failed at t = 0.0 s (state h = 4.5, v = 0.0): it returned nan "
              "(a model function must return finite numbers)")]
    for h_0, call, name, n, cause in cases:
        for when in ("initialization mode", "exit"):
            messages = []
            fmu = FMU3Model(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.modelExchange.modelIdentifier,
                            instanceName="start")
            fmu.instantiate(loggingOn=True, logMessage=lambda env, status, cat, msg: messages.append((status, msg.decode())))
            fmu.setFloat64([vr["h_0"]], [h_0])
            fmu.enterInitializationMode(startTime=0.0)
            values = (ctypes.c_double * n)()
            with pytest.raises(FMICallException):
                if when == "exit":
                    fmu.exitInitializationMode()
                else:
                    getattr(fmu, call)(values, n)
            errors = [text for status, text in messages if status >= 3]
            prefix = f"{name} refused: " if when != "exit" else ""
            assert errors == [f"BallStart: {prefix}initialization failed: {cause}"], (backend, h_0, when, messages)
            fmu.freeInstance()
