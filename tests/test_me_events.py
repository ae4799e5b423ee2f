"""The event semantics of docs/solver.md ("Event semantics") in model exchange: the arming of the
guards is the engine's (pg_engine_me_indicators, pg_engine_me_fired), as in co-simulation, so an
accumulation ends with the storm naming the event in every model-exchange path too — fmpy's own
model exchange with CVode on the FMI 3.0 FMUs of both backends, and the SSP master's
``--algorithm model-exchange`` — never with the state carried through the wall or the floor.

The models are files a user writes (the wall of tests/test_event_semantics.py, the ball of
examples/ball), exported by ``pogofmu export`` in a temporary folder."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

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


def _me_run(path, stop_time):
    """fmpy's model exchange with CVode: (the exception or None, the log messages, every row)."""
    from fmpy import simulate_fmu

    messages, rows = [], []
    try:
        simulate_fmu(str(path), fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-10,
                     stop_time=stop_time, output_interval=1e-3, debug_logging=True,
                     logger=lambda *a: messages.append(a[-1].decode() if a[-1] else ""),
                     step_finished=lambda t, recorder: rows.extend(recorder.rows[len(rows):]) or True)
    except Exception as exc:  # noqa: BLE001 - the FMU's error, whatever fmpy wraps it in
        return exc, messages, rows
    return None, messages, rows


@pytest.mark.parametrize("name,wall", [("Wall", 0.05), ("Wall0", 0.0)])
def test_fmpy_model_exchange_against_a_pressed_wall_ends_in_the_storm(user_folder, name, wall):
    """fmpy's own model exchange (CVode, rel_tol 1e-10) on the FMI 3.0 FMUs of both backends: the
    mass pressed against the wall ends with the storm naming the impact, never carried through it
    by more than 1e-6 m. Before, the arming of the adapters (a guard armed only when an indicator
    evaluation saw it strictly on its before side) let the mass through the wall silently."""
    for kind in ME_KINDS:
        path = user_folder / "out" / kind.format(n=name)
        exc, messages, rows = _me_run(path, 3.0)
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
