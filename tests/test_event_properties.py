"""The event semantics (docs/solver.md, "Event semantics") for any model, not only the project's five:
hypothesis draws small hybrid models (tests/hybrid_draws.py: affine or quadratic flows, guards with
offsets, guards on a held input and on time, a time event, jumps that land on or across another
guard, restitution accumulations), writes each as a user's model file in a temporary folder,
exports it with `pogofmu export` (Python-hosted and native, FMI 2.0 co-simulation) and drives both
FMUs through fmpy with the input held over each communication step.

Checked against the independent reference (scipy's DOP853 at rtol 1e-12, restarted at every event,
with the documented rules written a second time in hybrid_draws.reference):

* both backends give the same bits: every row, every event record, every message;
* the same events in the same order, each at the reference's time within 1e-6 s; the states at every
  communication point within 1e-6 (1 + |x|);
* the invariant: between two reported events no guard goes from its before side to its after side
  on the returned rows;
* an accumulation ends the run with the storm naming its event, near the reference's accumulation
  time, never past it.

The same draws exported as FMI 3.0 FMUs run in model exchange through fmpy's CVode (rtol 1e-12), the
importer locating the event indicators' roots and the FMU arming and firing: the same bits in both
backends, the same events in the same order, their times and the states to CVode's accuracy (1e-3).

Budget: CI runs a derandomized set (POGOFMU_FUZZ unset: 60 draws in co-simulation, 30 in model
exchange); POGOFMU_FUZZ=long draws 200 and 100 models.
"""
from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, assume, event, example, given, note, settings

from hybrid_draws import N_STEPS, STEP, Draw, Undecided, draws, load_model, model_source, reference
from support import fmi2_callbacks, run_pogofmu

pytestmark = pytest.mark.own_fmus  # (exports its own FMUs, or needs none)

LONG = os.environ.get("POGOFMU_FUZZ") == "long"
TOL = 1e-10
T_TOL = 1e-6
ME_T_TOL = 1e-3  # model exchange: fmpy's CVode at rtol 1e-12 (its error, not the FMU's: it grows at each impact)
CACHE = Path(tempfile.mkdtemp(prefix="pogofmu-draws-cache-"))
atexit.register(shutil.rmtree, CACHE, True)  # the session's exports, gone with it


def run_cs(path: Path, d: Draw, tol: float = TOL):
    """One FMI 2.0 CS run through fmpy's FMU2Slave: the input held over each step of 0.01 s, the
    events logged (log_events = 1). Returns (rows (t, x, v, m), events, the error messages)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    from pogofmu.runtime.eventlog import parse_event_log

    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = extract(str(path))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="drawn")
    messages = []
    callbacks = fmi2_callbacks(messages)
    fmu.instantiate(loggingOn=True, callbacks=callbacks.struct)
    u = d.inputs()
    rows = []
    try:
        fmu.setupExperiment(tolerance=tol, startTime=0.0, stopTime=N_STEPS * STEP)
        fmu.enterInitializationMode()
        fmu.setInteger([vr["log_events"]], [1])
        fmu.setReal([vr["u"]], [float(u[0])])
        fmu.exitInitializationMode()
        for k in range(N_STEPS):
            if k:
                fmu.setReal([vr["u"]], [float(u[k])])
            fmu.doStep(currentCommunicationPoint=k * STEP, communicationStepSize=STEP)
            x, v = fmu.getReal([vr["x"], vr["v"]])
            rows.append(((k + 1) * STEP, x, v, fmu.getInteger([vr["m"]])[0]))
    except FMICallException:
        pass
    finally:
        try:
            fmu.terminate()
        except FMICallException:
            pass
        fmu.freeInstance()
    errors = [m[2] for m in messages if m[0] >= 3]
    return rows, parse_event_log(messages), errors


def run_me(path: Path, d: Draw):
    """One FMI 3.0 model-exchange run through fmpy's CVode (rtol 1e-12): the input held over each step
    of 0.01 s (a table with a step at each communication point: fmpy sets each new value in Event
    Mode), the events logged. Returns (rows (t, x, v, m) at the communication points, events, the
    error messages), as run_cs."""
    from fmpy import simulate_fmu
    from fmpy.fmi1 import FMICallException

    from pogofmu.runtime.eventlog import parse_event_log

    u = d.inputs()
    t = np.arange(N_STEPS + 1) * STEP
    table = [(0.0, float(u[0]))]
    for k in range(1, N_STEPS + 1):
        table += [(float(t[k]), float(u[k - 1])), (float(t[k]), float(u[k]))]
    table = np.array(table, dtype=[("time", float), ("u", float)])
    messages, seen = [], []
    try:
        simulate_fmu(str(path), fmi_type="ModelExchange", stop_time=N_STEPS * STEP, output_interval=STEP,
                     relative_tolerance=1e-12, input=table, output=["x", "v", "m"], record_events=False,
                     start_values={"log_events": 1}, debug_logging=True,
                     logger=lambda *a: messages.append((a[-3], *(b.decode() if b else "" for b in a[-2:]))),
                     step_finished=lambda time, recorder: seen.append(recorder) or True)
    except FMICallException:
        pass
    rows = [tuple(r) for r in (seen[-1].rows if seen else [])]
    rows = [(float(r[0]), float(r[1]), float(r[2]), int(r[3])) for r in rows if r[0] > STEP / 2]  # (not t = 0)
    errors = [m[2] for m in messages if m[0] >= 3]
    return rows, parse_event_log(messages), errors


def export(d: Draw, folder: Path, fmi: int = 2):
    (folder / "drawn.py").write_text(model_source(d, "Drawn"))
    proc = run_pogofmu("export", "drawn.py", "--out", "out", "--fmi", str(fmi), "--platforms", "x86_64-linux",
                       "--cache", CACHE, cwd=folder, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    sub = "" if fmi == 2 else "fmi3/"
    return folder / "out" / f"{sub}Drawn.fmu", folder / "out" / "native" / f"{sub}Drawn.fmu"


def check_invariant(model, d, rows, events):
    """Between two rows with no event of its own in between, no guard goes from its before side
    beyond the band to its after side beyond the band."""
    from pogofmu.runtime.model import Params

    p = Params(model.defaults())
    u = d.inputs()
    band = 1e-9 * (1 + abs(d.X0))
    times = {}
    for e in events:
        times.setdefault(e["name"], []).append(e["time"])
    prev = None
    for k, (t, x, v, m) in enumerate(rows):
        if prev is not None:
            t0, x0, v0, m0 = prev
            if m0 == m:
                for ev in model.events:
                    s = 1.0 if ev.direction > 0 else -1.0
                    g0 = s * ev.guard_t(t0, [x0, v0], {"m": m0}, [float(u[k])], p)
                    g1 = s * ev.guard_t(t, [x, v], {"m": m}, [float(u[k])], p)
                    fired = any(t0 - 1e-12 <= te <= t + 1e-12 for te in times.get(ev.name, ()))
                    assert fired or not (g0 < -band and g1 > band), (
                        f"{ev.name} crossed from {g0!r} to {g1!r} between t = {t0} and {t} with no event")
        prev = (t, x, v, m)


def compare(d, ref, rows, events, errors, t_tol=T_TOL, x_tol=1e-6):
    """The run against the reference: the same events in order, each within t_tol s, and the states at
    the communication points within x_tol (1 + |x|) away from the events (co-simulation: 1e-6 s and
    1e-6; model exchange: the importer's accuracy)."""
    got = [(e["time"], e["name"]) for e in events]
    want = [(t, name) for (t, name, _) in ref.events]
    if ref.accumulation is not None:
        storm = [e for e in errors if "storm" in e]
        assert storm, f"the events accumulate at t = {ref.accumulation}: no storm; errors {errors}; rows to {rows[-1][0] if rows else 0}"
        name = want[-1][1]
        assert name in storm[0], (storm[0], name)
        last = rows[-1][0] if rows else 0.0
        assert last <= ref.accumulation + STEP, (last, ref.accumulation)
        assert got and abs(got[-1][0] - ref.accumulation) < 1e-3, (got[-1], ref.accumulation)
        horizon = ref.accumulation - 1e-3
        got = [g for g in got if g[0] < horizon]
        want = [w for w in want if w[0] < horizon]
        ref_rows = [r for r in ref.rows if r[0] < horizon]
    else:
        assert not errors, errors
        assert len(rows) == N_STEPS, rows[-1]
        ref_rows = ref.rows
    assert [n for _, n in got] == [n for _, n in want], (got[:20], want[:20])
    dt = max((abs(a[0] - b[0]) for a, b in zip(got, want)), default=0.0)
    assert dt < t_tol, f"event times off by {dt:.3g} s"
    near = np.array([t for t, _ in got] + [t for t, _ in want])
    for r, w in zip(rows, ref_rows):
        assert r[0] == pytest.approx(w[0], abs=1e-12)
        if len(near) and np.min(np.abs(near - r[0])) < t_tol:
            continue  # an event at the point: on either side of it within the event times' tolerance
        assert r[3] == w[3], (r, w)
        assert abs(r[1] - w[1]) < x_tol * (1 + abs(w[1])), (r, w)
        assert abs(r[2] - w[2]) < x_tol * (1 + abs(w[2])), (r, w)


@settings(max_examples=200 if LONG else 60, deadline=None, derandomize=not LONG,
          phases=(Phase.explicit, Phase.reuse, Phase.generate) + ((Phase.shrink,) if LONG else ()),
          suppress_health_check=list(HealthCheck))
@given(d=draws())
# a draw that found a bug (a9ffde9): the level event's mode toggle fired twice, 1e-16 s apart
@example(d=Draw(X0=0.05, a0=-5.960464477539063e-08, k=13.148709379239, bu=-1.4253352641610046, y0=0.28999929747921155,
                v0=-0.9207480976935387, m0=1, U0=0.0, U1=4.4184382348551905, fu=1.2983583735754114, events=("level",),
                L=0.05, level_rising=False, Lu=5.713044395406264, input_rising=False))
# a draw that found a bug: a level event's own crossing, its jump located a rounding short of zero
# (G = -8e-17) 1.3 ms before a communication point, fired again there when the input change redid the
# run-ahead step up to it (crossed_in lacked step's rule for a disarmed guard within its band)
@example(d=Draw(X0=0.05, a0=-12.850679410604446, am=-3.391986467588353, k=51.17132379875001, c=0.5415696657768143,
                b2=0.0, bu=-1.1570443777699821, y0=0.02958758547680685, v0=-3.698705073536441e-73, m0=1,
                U0=-1.3576037039908681e-294, U1=6.8978331630000245, fu=0.8010072855710981, events=('level',),
                dhi=0.6647376103363235, ehi=0.7477875995825884, dlo=-0.3682551329925545, elo=0.5,
                L=0.008251463145851456, level_rising=True, landing='none', dx=0.15108809640997276,
                Lu=-0.6812137862044807, input_rising=True, Tg=1.805518982575146, tick=False, T0=0.0, P=0.37,
                dv=-0.46626215135050986))
# a draw that found a bug (CI, 2026-12-07): the mass rose past the gate's level and on to the level
# event within one step; the event's point ended that step, but the gate, seen there on its before side,
# was not armed, so the level's jump (down past the gate) did not fire it
@example(d=Draw(X0=0.0, a0=8.770678855142453, am=3.7541291426284324, k=51.53027996588951, c=0.4139981141951927,
                b2=0.0, bu=0.0, y0=0.24493756635042224, v0=-0.9241996545752262, m0=0, U0=0.2880677021286928,
                U1=2.00001, fu=0.3560612810635665, events=('level', 'gate'), dhi=0.9103414975589438,
                ehi=0.33984976259283506, dlo=-0.9760748107923942, elo=0.3514682770225182, L=0.11081265534253859,
                level_rising=True, landing='on floor', dx=0.012651089341923868, Lu=-0.5186008842613214,
                input_rising=False, Tg=0.6246604363824948, tick=False, T0=0.0, P=0.3, dv=0.7688553550634123,
                Af=0.0, wf=3.0, Lg=0.020661274498804668, gu=-0.07172367587940957, gate_rising=False))
def test_a_drawn_model_keeps_the_event_semantics_in_both_backends(d):
    note(repr(d))
    with tempfile.TemporaryDirectory(prefix="pogofmu-draw-") as folder:
        _check_draw(d, Path(folder))


def _check_draw(d: Draw, folder: Path, fmi: int = 2):
    """Export the drawn model in ``folder`` and hold both FMUs to the reference: FMI 2.0 co-simulation,
    or (fmi = 3) FMI 3.0 model exchange."""
    (folder / "drawn.py").write_text(model_source(d, "Drawn"))
    model = load_model(folder / "drawn.py")
    try:
        ref = reference(model, d)
    except Undecided as why:
        note(f"undecided: {why}")
        assume(False)
    n = len(ref.events)
    event("accumulation" if ref.accumulation is not None else f"events: {'0' if not n else '1-9' if n < 10 else '10+'}")
    for kind in {k for _, _, k in ref.events}:
        event(f"an event caused by {kind}")
    if d.landing != "none" and "level" in d.events:
        event(f"a jump that lands {d.landing.split()[0]} another guard")
    if d.X0:
        event("an offset")
    python_fmu, native_fmu = export(d, folder, fmi)
    run = run_cs if fmi == 2 else run_me
    py, nat = run(python_fmu, d), run(native_fmu, d)
    # the same bits: rows, event records, messages
    assert py[0] == nat[0] and py[1] == nat[1] and py[2] == nat[2], (py[2], nat[2])
    rows, events, errors = py
    check_invariant(model, d, rows, events)
    # model exchange: CVode at rtol 1e-12 places the first events within 1e-9 s, and its error grows by
    # each impact (2e-5 s after 20 impacts with restitution 0.95): the bound is its, the names and order exact
    compare(d, ref, rows, events, errors, **({} if fmi == 2 else dict(t_tol=ME_T_TOL, x_tol=ME_T_TOL)))


@settings(max_examples=100 if LONG else 30, deadline=None, derandomize=not LONG,
          phases=(Phase.explicit, Phase.reuse, Phase.generate) + ((Phase.shrink,) if LONG else ()),
          suppress_health_check=list(HealthCheck))
@given(d=draws())
# a draw that found a bug: the held input stepped the gate's level past the rising mass at five points in
# a row; fmpy applied each new value inside CVode's root search, and the FMU took the crossing for one
# the importer had located where the flow carries the guard back, and fired none of the five
@example(d=Draw(X0=0.0, a0=8.79061215401487, am=0.044352408060714055, k=52.4947733034341, c=0.40233320339815265,
                b2=0.0, bu=-0.0, y0=0.22556417438119808, v0=1.4941473788497843, m0=1, U0=4.0, U1=6.965480934504168,
                fu=0.9272381706652582, events=('floor', 'level', 'gate'), dhi=0.3626102098104842,
                ehi=0.799821739958952, dlo=-0.8044559366432208, elo=0.95, L=0.1155246490584787, level_rising=True,
                landing='on floor', dx=0.14112319152347277, Lu=1.7214267015104294, input_rising=True,
                Tg=0.13258996703447584, tick=True, T0=0.4654489314951379, P=0.3, dv=-0.505842927023245, Af=0.0,
                wf=3.0, Lg=-0.09969508480529385, gu=-0.03445939782951983, gate_rising=False))
def test_a_drawn_model_keeps_the_event_semantics_in_model_exchange(d):
    """The same draws in FMI 3.0 model exchange, where fmpy's CVode integrates and locates the event
    indicators' roots and the FMU arms and fires (docs/solver.md, "Model exchange"): both backends give
    the same bits, and the events, the states and an accumulation's storm hold to the same reference
    (CVode at rtol 1e-12: times within 1e-3 s, states within 1e-3 (1 + |x|), the events' names and order
    exact). A user's audit found two events that fired again after every importer step here (an input
    step across a moving guard, a cascade of a counter) while co-simulation was right."""
    note(repr(d))
    with tempfile.TemporaryDirectory(prefix="pogofmu-draw-me-") as folder:
        _check_draw(d, Path(folder), fmi=3)
