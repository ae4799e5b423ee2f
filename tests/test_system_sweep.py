"""``pogofmu sweep SYSTEM.ssp``: the SSP master run per point on Dask, one Parquet row per run.

References: a direct ``pogofmu ssp run --set Component.parameter=VALUE`` of the same point (its
CSV, read with the csv module: every row value recomputed here from it), the event rows of that
CSV (the left limits, ``event = -1``, and the PogoStick's own event counter across each event),
and numpy's documented generator for the samples.
"""
import csv
import signal
import subprocess
import sys
import time
import uuid
import zipfile
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from pogofmu import cli
from support import DIST, saved_runs, wait_for

POGOFMU = Path(sys.executable).with_name("pogofmu")
SSP = DIST / "native" / "SpaceHopper.ssp"


@pytest.fixture(scope="module")
def scheduler():
    from distributed import LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    yield cluster.scheduler_address
    cluster.close()


def _sweep(*args):
    return cli.main(["sweep", *map(str, args), "--no-progress"])


def _direct(tmp, point, *options):
    """The CSV of ``pogofmu ssp run`` of one point (a fresh process, as a user runs it)."""
    out = tmp / f"direct-{uuid.uuid4().hex[:8]}"
    sets = [a for name, value in point.items() for a in ("--set", f"{name}={value!r}")]
    r = subprocess.run([str(POGOFMU), "ssp", "run", str(SSP), *options, *sets, "--out", str(out), "--quiet"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    (csv_path,) = out.glob("*.csv")
    return csv_path


def _table(csv_path):
    with csv_path.open(newline="") as f:
        rows = list(csv.reader(f))
    head, body = rows[0], rows[1:]
    return {name: [float(r[j]) for r in body] for j, name in enumerate(head)}


def test_each_row_is_a_direct_ssp_run_of_its_point_to_the_bit(tmp_path, scheduler):
    out, ts = tmp_path / "hop.parquet", tmp_path / "series"
    options = ["--parameters", "moon", "--stop-time", "4"]
    assert _sweep(SSP, *options, "--grid", "PogoStick.k=80,120", "--sample", "HopController.h_target=normal(1.5,0.1)",
                  "--samples", "2", "--seed", "3", "--summary", "PogoStick.y:max", "--summary", "PogoStick.y:t_max",
                  "--summary", "HopController.F_ext:mean", "--summary", "PogoStick.ydot:min",
                  "--summary", "PogoStick:first_event", "--summary", "HopController:last_event",
                  "--timeseries", ts, "--scheduler", scheduler, "--out", out) == 0
    rows = pq.read_table(out).to_pylist()
    assert [r["run_id"] for r in rows] == [0, 1, 2, 3] and all(r["status"] == "ok" for r in rows)
    import numpy as np

    draws = np.random.default_rng(3).normal(1.5, 0.1, 2)
    assert [r["HopController.h_target"] for r in rows] == [float(d) for d in draws] * 2
    assert [r["PogoStick.k"] for r in rows] == [80.0, 80.0, 120.0, 120.0]
    for r in (rows[0], rows[3]):
        point = {"PogoStick.k": r["PogoStick.k"], "HopController.h_target": r["HopController.h_target"]}
        direct = _direct(tmp_path, point, *options)
        series = ts / f"run_id={r['run_id']}" / "timeseries.csv"
        assert series.read_bytes() == direct.read_bytes()  # the run's rows, byte for byte
        c = _table(direct)
        t = c["time"]
        for name in ("PogoStick.y", "PogoStick.ydot", "PogoStick.E", "HopController.E_est", "HopController.phase"):
            assert r[f"{name}:final"] == c[name][-1], name
        assert r["PogoStick.y:max"] == max(c["PogoStick.y"]) and r["PogoStick.ydot:min"] == min(c["PogoStick.ydot"])
        assert r["PogoStick.y:t_max"] == t[c["PogoStick.y"].index(max(c["PogoStick.y"]))]
        f = c["HopController.F_ext"]
        mean = sum(0.5 * (f[i] + f[i + 1]) * (t[i + 1] - t[i]) for i in range(len(t) - 1)) / (t[-1] - t[0])
        assert r["HopController.F_ext:mean"] == pytest.approx(mean, rel=1e-12, abs=1e-15)
        # the events: one left-limit row per instant (an FMI 2.0 component stops a rounding unit before
        # its event: the instant is the next row's, the right limit); the PogoStick's are those across
        # which its own event counter grows
        lefts = [i for i, e in enumerate(c["event"]) if e == -1]
        assert r["events"] == len(lefts) > 0
        own = [t[i + 1] for i in lefts if c["PogoStick.n_events"][i + 1] > c["PogoStick.n_events"][i]]
        assert r["PogoStick:events"] == len(own) and r["PogoStick:first_event"] == own[0]
        assert r["PogoStick:events"] + r["HopController:events"] == r["events"]
        others = [t[i + 1] for i in lefts if t[i + 1] not in own]
        assert r["HopController:last_event"] == others[-1]


def test_a_failed_run_is_a_row_naming_why(tmp_path, scheduler):
    out = tmp_path / "f.parquet"
    status = _sweep(SSP, "--parameters", "moon", "--stop-time", "1", "--grid", "PogoStick.m=1,-1",
                    "--scheduler", scheduler, "--out", out)
    assert status == 1  # runs failed
    ok, bad = pq.read_table(out).to_pylist()
    assert ok["status"] == "ok" and bad["status"] == "error"
    assert "PogoStick" in bad["message"] and "m" in bad["message"] and bad["PogoStick.y:final"] is None
    direct = subprocess.run([str(POGOFMU), "ssp", "run", str(SSP), "--parameters", "moon", "--stop-time", "1",
                             "--set", "PogoStick.m=-1", "--out", str(tmp_path / "d"), "--quiet"],
                            capture_output=True, text=True, timeout=300)
    assert direct.returncode == 1  # the master's own message, on one line
    message = direct.stderr[direct.stderr.index("error: ") + len("error: "):]
    assert bad["message"] == " ".join(x.strip() for x in message.splitlines() if x.strip())
    assert "Terminate" not in direct.stderr  # (no FMI call out of its states while the master cleans up)


@pytest.mark.parametrize("args, words", [
    (["--grid", "Pogo.k=1,2"], ["'Pogo' is not a component", "PogoStick, HopController"]),
    (["--grid", "PogoStick.kk=1,2"], ["'kk' is not a parameter of Component PogoStick", "parameters:"]),
    (["--grid", "PogoStick.method=1,2.5"], ["PogoStick.method is an integer", "2.5"]),
    (["--set", "PogoStick.x=1", "--grid", "PogoStick.k=1,2"], ["'x' is not a parameter"]),
    (["--grid", "PogoStick.k=1,2", "--summary", "PogoStick.y:median"], ["'median' is no summary", "t_max"]),
    (["--grid", "PogoStick.k=1,2", "--summary", "PogoStick.q:max"], ["'q' is not a connector of Component PogoStick"]),
    (["--grid", "PogoStick.k=1,2", "--summary", "Stick:events"], ["'Stick' is not a component"]),
    (["--grid", "PogoStick.k=1,2", "--stop-time", "1.0005"], ["not a whole number of steps"]),
    (["--grid", "PogoStick.k=1,2", "--algorithm", "model-exchange", "--events", "off"], ["--events off"]),
    (["--grid", "PogoStick.k=1,2", "--parameters", "mars"], ["parameter set 'mars'", "moon"]),
])
def test_bad_options_are_refused_before_any_worker_starts(tmp_path, capsys, monkeypatch, args, words):
    from pogofmu.sweep import cluster

    def no_cluster(*a, **k):
        raise AssertionError("a cluster was opened")
    monkeypatch.setattr(cluster, "open_cluster", no_cluster)
    out = tmp_path / "x.parquet"
    assert _sweep(SSP, *args, "--out", out) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    for w in words:
        assert w in err, (w, err)
    assert list(tmp_path.iterdir()) == []  # nothing written


def _gate_system(tmp, gate_fmu):
    """An SSP of the sweep gate FMU (tests/_sweep_gate.py; an FMU without units, of pythonfmu)."""
    ssd = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" version="1.0" name="Gated">
  <ssd:System name="Gated">
    <ssd:Elements>
      <ssd:Component name="Gate" source="resources/Gate.fmu" type="application/x-fmu-sharedlibrary">
        <ssd:Connectors><ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector></ssd:Connectors>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="0.1"/>
</ssd:SystemStructureDescription>
"""
    path = tmp / "Gated.ssp"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
        z.write(gate_fmu, "resources/Gate.fmu")
    return path


def test_an_interrupted_system_sweep_resumes_with_the_missing_points(tmp_path, scheduler, gate_fmu):
    """Runs Gate.k = 0 and 1 pass the gate, the others wait: Ctrl-C once both are saved; --resume
    (gate open) runs only the others."""
    sys.path.insert(0, str(Path(__file__).parent))
    from _sweep_gate import gate_file

    number = uuid.uuid4().int % 10 ** 12
    gate = Path(gate_file(number))
    ssp = _gate_system(tmp_path, gate_fmu)
    out, parts = tmp_path / "g.parquet", tmp_path / "g.parquet.parts"
    n = 8
    cmd = [str(POGOFMU), "sweep", str(ssp), "--grid", f"Gate.k=0:{n - 1}:{n}", "--set", "Gate.hold=2",
           "--set", f"Gate.gate={number}", "--step", "0.05", "--chunk-size", "1", "--scheduler", scheduler,
           "--out", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(lambda: len(saved_runs(parts)) >= 2, proc)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        gate.touch()  # the held runs of the module's workers go on
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    try:
        assert proc.returncode == 130 and "--resume" in stdout, (stdout, stderr[-2000:])
        before = saved_runs(parts)
        assert sorted(before) == [0, 1]
        resumed = subprocess.run(cmd + ["--resume"], capture_output=True, text=True, timeout=300)
        assert resumed.returncode == 0, resumed.stderr[-2000:]
        assert f"2 of {n} runs done, running the other {n - 2}" in resumed.stdout
        rows = pq.read_table(out).to_pylist()
        assert [r["run_id"] for r in rows] == list(range(n)) and not parts.exists()
        for r in rows:
            assert r["status"] == "ok" and r["Gate.y:final"] == r["Gate.k"]
            if r["run_id"] in before:
                assert r == before[r["run_id"]]  # not run again
    finally:
        time.sleep(0.2)
        gate.unlink(missing_ok=True)


def test_study_landing_dispersion(tmp_path, scheduler):
    out = tmp_path / "study"
    status = cli.main(["study", "landing", "--samples", "6", "--stop-time", "4", "--scheduler", scheduler,
                       "--ssp", str(SSP), "--out", str(out), "--no-progress"])
    assert status == 0
    table = pq.read_table(out / "landing.parquet").to_pylist()
    assert len(table) == 6 and all(r["status"] == "ok" for r in table)
    png = out / "landing.png"
    assert png.stat().st_size > 10_000
    # each run's first touchdown against the free fall from rest at y_0 to the leg's length x_i:
    # t = sqrt(2 (y_0 - x_i) / g) with the run's own drawn gravity
    for r in table:
        g = r["PogoStick.g"]
        expected = (2 * (1.2 - 1.0) / g) ** 0.5
        assert r["PogoStick:first_event"] == pytest.approx(expected, rel=1e-7)
