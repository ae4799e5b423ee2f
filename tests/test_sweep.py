"""`pogofmu sweep` and `pogofmu study`: Dask sweeps of the built FMUs, Parquet rows.

References: direct fmpy runs of the same FMU (support.simulate), numpy's documented generator
for the Monte Carlo draws, the closed-form events (pogofmu.references.closed_form) and
the work-precision expectations of tests/test_pogostick.py. The sweeps run on small local
clusters (2 worker processes, one shared by most tests through --scheduler), and every test
checks that no worker process outlives its cluster.
"""
import csv
import math
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import psutil
import pyarrow.parquet as pq
import pytest

from pogofmu import cli
from support import DIST, fmu_path, reference_events, simulate
from support import saved_runs as _saved
from support import wait_for as _wait_for

POGOFMU = Path(sys.executable).with_name("pogofmu")  # the console script of the venv


def _children():
    """Child processes, but multiprocessing's resource tracker (it lives as long as this process)."""
    out = set()
    for p in psutil.Process().children(recursive=True):
        try:
            if "resource_tracker" not in " ".join(p.cmdline()):
                out.add(p.pid)
        except psutil.Error:
            pass
    return out


# A leaked process never exits, so the wait can be long: a Dask cluster shutting down under the CPU
# burners on a 2-core machine shared with other work has taken over 20 s; the wait ends as soon as
# the processes are gone, so a generous deadline costs nothing where they go.
EXIT_DEADLINE = 180.0  # [s]


def _wait_gone(pids, timeout=EXIT_DEADLINE):
    deadline = time.monotonic() + timeout
    alive = set(pids)
    while alive and time.monotonic() < deadline:
        alive = {p for p in alive if psutil.pid_exists(p) and psutil.Process(p).status() != psutil.STATUS_ZOMBIE}
        time.sleep(0.1)
    return alive


@pytest.fixture(scope="module")
def scheduler():
    """A 2-worker local cluster that the sweeps join with --scheduler (as an existing cluster)."""
    from distributed import LocalCluster

    before = _children()
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    workers = _children() - before
    assert len(workers) >= 2
    yield cluster.scheduler_address
    cluster.close()
    assert not _wait_gone(workers), "worker processes left behind by the local cluster"


def _rows(path, drop=("wall_s",)):
    return [{k: v for k, v in r.items() if k not in drop} for r in pq.read_table(path).to_pylist()]


def _sweep(*args):
    return cli.main(["sweep", *map(str, args), "--no-progress"])


def test_grid_2x3_with_2_workers_equals_direct_fmpy_runs_and_1_worker(tmp_path):
    fmu = fmu_path("PogoStick")
    # no --step: the default experiment's 1 ms (the direct runs' grid below)
    grid = ["--grid", "k=80,120", "--grid", "c=0.2:1.0:3", "--stop-time", "4", "--outputs", "y,E"]
    # 2 workers: the console script as a user runs it, in its own process; its workers carry a mark
    mark = uuid.uuid4().hex
    env = dict(os.environ, POGOFMU_TEST_MARK=mark)
    proc = subprocess.run([str(POGOFMU), "sweep", str(fmu), *grid, "--workers", "2", "--out", str(tmp_path / "w2.parquet")],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "6 runs" in proc.stdout and "0 failed" in proc.stdout, proc.stdout
    left = []
    for p in psutil.process_iter():
        try:
            if p.environ().get("POGOFMU_TEST_MARK") == mark:
                left.append(p.pid)
        except (psutil.Error, OSError):
            pass
    assert not _wait_gone(left), f"worker processes of the sweep still running: {left}"

    ts = tmp_path / "series"
    assert _sweep(fmu, *grid, "--workers", "1", "--out", tmp_path / "w1.parquet", "--timeseries", ts) == 0
    import pyarrow.dataset as ds

    series = ds.dataset(ts, format="parquet", partitioning="hive").to_table()
    two, one = _rows(tmp_path / "w2.parquet"), _rows(tmp_path / "w1.parquet")
    assert one == two, "1 and 2 workers give different tables"
    assert [(r["run_id"], r["k"], r["c"]) for r in two] == [
        (0, 80.0, 0.2), (1, 80.0, 0.6), (2, 80.0, 1.0), (3, 120.0, 0.2), (4, 120.0, 0.6), (5, 120.0, 1.0)]
    for r in two:
        direct = simulate("PogoStick", start_values={"k": r["k"], "c": r["c"]}, stop_time=4.0, output_interval=1e-3)
        assert r["status"] == "ok" and r["message"] == ""
        assert r["n_events"] == direct["n_events"][-1] and r["n_events"] > 3
        assert r["t_last_event"] == direct["t_last_event"][-1]  # bit for bit
        for name in ("y", "E"):
            assert (r[f"{name}_final"], r[f"{name}_min"], r[f"{name}_max"]) == (
                direct[name][-1], np.min(direct[name]), np.max(direct[name]))
        mine = series.filter(ds.field("run_id") == r["run_id"])  # the time series of the run, on the grid
        assert mine.num_rows == 4001
        for name in ("time", "y", "E", "n_events"):
            assert np.array_equal(mine.column(name).to_numpy(), direct[name]), name
    assert len({r["t_last_event"] for r in two}) == 6  # the parameters did reach the FMU


def test_a_native_fmu_is_swept_by_its_own_c_loop_with_the_python_fmus_table(tmp_path, scheduler):
    """dist/native/PogoStick.fmu exports pogofmu_fmi2_run_grid: the sweep's runner steps it in C.
    Every column of its table (but the wall time), its time series and its failed rows (a leg that
    bottoms out, k = 1) are those of the Python-hosted FMU swept through fmpy."""
    from pogofmu.sweep import Runner, Settings

    native = DIST / "native" / "PogoStick.fmu"
    for path, has_loop in ((native, True), (fmu_path("PogoStick"), False)):
        runner = Runner(str(path))
        row, _ = runner.run({"k": 100.0}, Settings(stop_time=0.01))
        assert row["status"] == "ok" and bool(runner.c_loop) is has_loop, path
    grid = ["--grid", "k=1,80,120", "--grid", "c=0.2,1.0", "--set", "m=1", "--stop-time", "6", "--events"]
    for name, fmu in (("py", fmu_path("PogoStick")), ("native", native)):
        assert _sweep(fmu, *grid, "--scheduler", scheduler, "--out", tmp_path / f"{name}.parquet",
                      "--timeseries", tmp_path / f"ts-{name}") == 1  # two runs fail
    a, b = _rows(tmp_path / "py.parquet"), _rows(tmp_path / "native.parquet")
    assert a == b
    assert sum(r["status"] == "error" for r in a) == 2 and sum(r["status"] == "ok" for r in a) == 4
    import pyarrow.dataset as ds

    ta = ds.dataset(tmp_path / "ts-py", format="parquet", partitioning="hive").to_table()
    tb = ds.dataset(tmp_path / "ts-native", format="parquet", partitioning="hive").to_table()
    assert ta.num_rows == tb.num_rows > 4 * 6000
    assert ta.sort_by([("run_id", "ascending"), ("time", "ascending")]).equals(
        tb.sort_by([("run_id", "ascending"), ("time", "ascending")]))


def test_fmi3_fmus_of_both_backends_give_the_fmi2_table_to_the_bit(tmp_path, scheduler):
    """An FMI 3.0 FMU is swept as its FMI 2.0 twin (its parameters are Float64 and Int32): the
    Python-hosted one through fmpy, the native one by its own C loop (pogofmu_fmi3_run_grid); every
    column of the table (but the wall time), the event lists and the time series are those of
    dist/PogoStick.fmu, the failed rows too (a leg that bottoms out, k = 1), whose message names
    the FMI 3.0 function that failed."""
    from pogofmu.sweep import Runner, Settings

    fmus = {"fmi2": fmu_path("PogoStick"), "fmi3": DIST / "fmi3" / "PogoStick.fmu",
            "native-fmi3": DIST / "native" / "fmi3" / "PogoStick.fmu"}
    for name, has_loop in (("fmi3", False), ("native-fmi3", True)):
        runner = Runner(str(fmus[name]))
        row, _ = runner.run({"k": 100.0, "method": 8}, Settings(stop_time=0.01))
        assert row["status"] == "ok" and bool(runner.c_loop) is has_loop, name
    grid = ["--grid", "k=1,80,120", "--grid", "method=5,8", "--set", "m=1", "--stop-time", "6", "--events"]
    for name, fmu in fmus.items():
        assert _sweep(fmu, *grid, "--scheduler", scheduler, "--out", tmp_path / f"{name}.parquet",
                      "--timeseries", tmp_path / f"ts-{name}") == 1  # the two k = 1 runs fail
    import pyarrow.dataset as ds

    def series(name):
        t = ds.dataset(tmp_path / f"ts-{name}", format="parquet", partitioning="hive").to_table()
        return t.sort_by([("run_id", "ascending"), ("time", "ascending")])

    ref = _rows(tmp_path / "fmi2.parquet")
    assert sum(r["status"] == "ok" for r in ref) == 4 and all(r["event_t"] for r in ref if r["status"] == "ok")
    for name in ("fmi3", "native-fmi3"):
        rows = _rows(tmp_path / f"{name}.parquet")
        for r in rows:
            assert "fmi2" not in r["message"]
            r["message"] = r["message"].replace("fmi3DoStep", "fmi2DoStep")
        assert rows == ref, name
        assert series(name).equals(series("fmi2")), name


def test_monte_carlo_is_reproducible_from_the_seed(tmp_path, scheduler):
    fmu = fmu_path("PogoStick")
    mc = ["--sample", "k=uniform(60,150)", "--sample", "c=lognormal(-1,0.5)", "--samples", "5",
          "--stop-time", "2", "--step", "1e-2", "--outputs", "y", "--scheduler", scheduler]
    for name, seed in (("a", 7), ("b", 7), ("c", 8)):
        assert _sweep(fmu, *mc, "--seed", seed, "--out", tmp_path / f"{name}.parquet") == 0
    a, b, c = (_rows(tmp_path / f"{n}.parquet") for n in "abc")
    assert a == b
    assert [r["k"] for r in a] != [r["k"] for r in c]
    # the documented draw: numpy default_rng(seed), one parameter after the other, N values each
    rng = np.random.default_rng(7)
    assert [r["k"] for r in a] == list(rng.uniform(60, 150, 5))
    assert [r["c"] for r in a] == list(rng.lognormal(-1, 0.5, 5))
    assert all(r["status"] == "ok" for r in a)


def test_failed_runs_are_rows_and_the_others_complete(tmp_path, scheduler):
    """A refused parameter (at initialization) and a leg that bottoms out mid-run in one chunk,
    on one worker: each is a row with the FMU's message, the runs after them still complete."""
    out = tmp_path / "bad.parquet"
    assert _sweep(fmu_path("PogoStickMem"), "--grid", "beta=5,0", "--grid", "c=0.5,-1", "--stop-time", "6",
                  "--step", "1e-2", "--outputs", "y", "--chunk-size", "4", "--scheduler", scheduler, "--out", out) == 1
    rows = {(r["beta"], r["c"]): r for r in _rows(out)}
    bottom = rows[(5.0, 0.5)]
    assert bottom["status"] in ("error", "fatal") and "bottomed out" in bottom["message"], bottom
    assert bottom["n_events"] is None  # a truncated run never passes for a result
    assert "t = 4.98" in bottom["message"]  # README: the softening leg bottoms out at t = 4.989 s
    for beta in (5.0, 0.0):
        r = rows[(beta, -1.0)]
        assert r["status"] == "error" and "parameter c = -1.0" in r["message"] and "c >= 0" in r["message"], r
        assert r["n_events"] is None
    good = rows[(0.0, 0.5)]
    direct = simulate("PogoStickMem", start_values={"beta": 0.0, "c": 0.5}, stop_time=6.0, output_interval=1e-2)
    assert good["status"] == "ok" and good["n_events"] == direct["n_events"][-1]
    assert good["t_last_event"] == direct["t_last_event"][-1]


def test_bad_options_are_refused_before_anything_runs(tmp_path, capsys):
    fmu = fmu_path("PogoStick")
    out = tmp_path / "x.parquet"
    assert _sweep(fmu, "--grid", "kk=1,2", "--out", out) == 2
    err = capsys.readouterr().err
    assert "'kk' is not a parameter of PogoStick" in err and "k, " in err
    assert _sweep(fmu, "--sample", "k=normal(100,-1)", "--samples", "3", "--out", out) == 2
    assert "normal(mean=100.0, sd=-1.0) breaks the rule sd > 0" in capsys.readouterr().err
    assert _sweep(fmu, "--grid", "method=5,6.5", "--out", out) == 2
    assert "parameter method is an Integer: value 6.5 is not integral" in capsys.readouterr().err
    assert _sweep(fmu, "--grid", "k=80,120", "--step", "1", "--stop-time", "0.2", "--out", out) == 2
    err = capsys.readouterr().err
    assert "--step 1.0: longer than the run" in err and "0.2" in err
    assert not out.exists()


def test_the_exit_status_tells_that_runs_failed(tmp_path, scheduler, capsys):
    """Every run refused by the FMU (no method 7): the table is written, its rows say why, and
    the command's exit status is 1, not 0; a sweep without a failed run exits 0."""
    fmu = fmu_path("PogoStick")
    out = tmp_path / "bad.parquet"
    assert _sweep(fmu, "--grid", "k=80,120", "--set", "method=7", "--stop-time", "0.1", "--scheduler", scheduler,
                  "--out", out) == 1
    rows = _rows(out)
    assert len(rows) == 2 and all(r["status"] == "error" and "method" in r["message"] for r in rows), rows
    assert "2 failed" in capsys.readouterr().out
    assert _sweep(fmu, "--grid", "k=80,120", "--stop-time", "0.1", "--scheduler", scheduler,
                  "--out", tmp_path / "good.parquet") == 0


@pytest.fixture
def gate():
    """A fresh gate of tests/_sweep_gate.py: ``gate.set`` is the sweep's ``--set`` of its number,
    ``gate.open()`` lets the held runs go on; the file is removed afterwards."""
    sys.path.insert(0, str(Path(__file__).parent))
    from _sweep_gate import gate_file

    number = uuid.uuid4().int % 10 ** 12
    path = Path(gate_file(number))

    class Gate:
        set = f"gate={number}"

        def open(self):
            path.touch()
    gate = Gate()
    yield gate
    # Open the gate before removing it, so that a run still held by a failed test's sweep (its
    # workers are the module's cluster's) ends now instead of after GATE_TIMEOUT; the runs poll
    # every 5 ms.
    gate.open()
    time.sleep(0.5)
    path.unlink(missing_ok=True)


@pytest.fixture(params=["idle", "loaded"])
def machine_load(request):
    """'loaded': one CPU burner per core this process may run on, at most 4, for the length of the
    test (the outcome must not change). Not os.cpu_count(): a container limited to 2 of a host's
    64 cores would get 64 burners, and the sweep 1/30 of a core."""
    burners = []
    if request.param == "loaded":
        code = "import time\nwhile True: time.perf_counter()"
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 2)
        burners = [subprocess.Popen([sys.executable, "-c", code]) for _ in range(min(cores, 4))]
    yield request.param
    for b in burners:
        b.kill()
        b.wait()


def test_resume_after_an_interruption_runs_only_the_missing_points(tmp_path, scheduler, gate_fmu, gate, machine_load):
    """Runs k = 0 and 1 pass the gate, the other 18 wait for it: the sweep is interrupted (SIGINT,
    as Ctrl-C) exactly when the two free runs are saved, whatever the machine's speed or load; the
    resumed sweep, gate open, runs the 18 others only."""
    out = tmp_path / "r.parquet"
    parts = tmp_path / "r.parquet.parts"
    n = 20
    cmd = [str(POGOFMU), "sweep", str(gate_fmu), "--grid", f"k=0:{n - 1}:{n}", "--set", "hold=2", "--set", gate.set,
           "--stop-time", "0.1", "--step", "0.05", "--outputs", "y", "--chunk-size", "1", "--scheduler", scheduler,
           "--out", str(out), "--no-progress"]
    # (PYTHONFAULTHANDLER: a sweep that does not end after the Ctrl-C shows its threads' stacks)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONFAULTHANDLER": "1"})
    try:
        _wait_for(lambda: len(_saved(parts)) >= 2, proc)
        proc.send_signal(signal.SIGINT)  # Ctrl-C
        try:
            stdout, stderr = proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGABRT)  # faulthandler writes every thread's stack to stderr
            stdout, stderr = proc.communicate(timeout=60)
            pytest.fail(f"the interrupted sweep did not end within 120 s: {stdout[-1000:]}\n{stderr[-8000:]}")
    finally:  # a failure above must not leave the sweep holding the module's workers
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 130, (proc.returncode, stdout, stderr[-3000:])
    assert "--resume" in stdout and not out.exists()
    before = _saved(parts)
    assert sorted(before) == [0, 1], sorted(before)  # exactly the runs the gate let through

    gate.open()
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert again.returncode == 2 and "--resume" in again.stderr  # an interrupted sweep is not overwritten silently
    resumed = subprocess.run(cmd + ["--resume"], capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert f"2 of {n} runs done, running the other {n - 2}" in resumed.stdout
    assert f"({n - 2} run now)" in resumed.stdout
    rows = pq.read_table(out).to_pylist()
    assert [r["run_id"] for r in rows] == list(range(n)) and not parts.exists()
    for r in rows:
        assert r["status"] == "ok" and r["y_final"] == r["k"]
        if r["run_id"] in before:
            assert r == before[r["run_id"]]  # the same row, wall time included: not run again
    # a finished sweep resumed again does nothing
    done = subprocess.run(cmd + ["--resume"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and f"all {n} runs are done already" in done.stdout


def _csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_work_precision_study_reproduces_figs_21_22(tmp_path, scheduler):
    out = tmp_path / "wp"
    assert cli.main(["study", "work-precision", "--out", str(out), "--scheduler", scheduler, "--no-progress",
                     "--fmu", str(DIST / "PogoStick.fmu")]) == 0
    ref = [e["time"] for e in reference_events()]
    summary = _csv(out / "work_precision.csv")
    events = _csv(out / "work_precision_events.csv")
    assert len(summary) == 2 * 2 * 10 and (out / "work_precision.png").stat().st_size > 10_000
    key = lambda r: (int(r["method"]), float(r["max_step"]), float(r["rel_tol"]))  # noqa: E731
    err = {}
    for e in events:  # the error recomputed here from the located times and the closed form
        err[key(e)] = max(err.get(key(e), 0.0), abs(float(e["time_s"]) - ref[int(e["index"]) - 1]))
    for r in summary:
        assert r["status"] == "ok"
        assert float(r["max_event_error_s"]) == err[key(r)]
        if float(r["max_step"]) == 0.01:  # Fig. 22: every event located at every tolerance with max_step
            assert int(r["n_events"]) == 19, r
            assert err[key(r)] < 1e-5
    # Fig. 21: unbounded steps, method 5: the error falls in proportion to rel_tol
    tols = [10.0 ** -k for k in range(4, 11)]
    errs = [err[(5, 0.0, t)] for t in tols]
    assert all(int(r["n_events"]) == 19 for r in summary if key(r)[0] == 5)
    assert 0.7 <= np.polyfit(np.log10(tols), np.log10(errs), 1)[0] <= 1.3, errs
    assert errs[-1] < errs[0] / 1e4
    # the event times of the sweep are those of a direct fmpy run, bit for bit
    direct = simulate("PogoStick", start_values={"log_events": 1, "method": 8, "rel_tol": 1e-9}, output_interval=1e-3)
    got = sorted((int(e["index"]), float(e["time_s"])) for e in events if key(e) == (8, 0.01, 1e-9))
    assert [t for _, t in got] == [e["time"] for e in direct.events()]
    # the work-accuracy half of Fig. 21: work counted, the global error against the closed form
    from pogofmu.references.closed_form import basic_state

    y_exact = float(basic_state(10.0)[0])
    assert abs(y_exact - 0.890238635473) < 1e-11  # (the FMU at rel_tol 1e-12 agrees to 2e-14)
    unbounded5 = sorted((r for r in summary if key(r)[:2] == (5, 0.0)), key=lambda r: -float(r["rel_tol"]))
    flows = [int(r["n_flow"]) for r in unbounded5]
    assert flows == sorted(flows) and flows[-1] > 5 * flows[0], flows  # tighter tolerance, more work
    y_err = {float(r["rel_tol"]): float(r["y_error_m"]) for r in unbounded5}
    assert y_err[1e-10] < y_err[1e-4] / 1e4 and y_err[1e-10] < 1e-8, y_err
    peer = _csv(out / "work_precision_scipy.csv")
    assert len(peer) == 2 * 2 * 10 and (out / "work_precision_work.png").stat().st_size > 10_000
    rk45 = {float(r["rel_tol"]): r for r in peer if r["solver"] == "scipy RK45" and float(r["max_step"]) == 0.0}
    for r in unbounded5:  # the same pair and error control: the same work and accuracy within small factors
        other = rk45[float(r["rel_tol"])]
        if int(other["n_events"]) == 19 and float(r["rel_tol"]) <= 1e-5:
            assert 0.5 < int(r["n_flow"]) / int(other["n_flow"]) < 2.0, (r, other)
            assert 0.1 < float(r["y_error_m"]) / max(float(other["y_error_m"]), 1e-17) < 10.0, (r, other)


def test_soil_study_against_direct_runs(tmp_path, scheduler):
    out = tmp_path / "soil"
    assert cli.main(["study", "soil", "--out", str(out), "--samples", "4", "--seed", "3", "--stop-time", "3",
                     "--scheduler", scheduler, "--no-progress", "--fmu", str(DIST / "Penetrator.fmu")]) == 0
    rows = _csv(out / "soil.csv")
    assert len(rows) == 4 and (out / "soil.png").stat().st_size > 10_000
    assert len({r["K"] for r in rows}) == 4
    for r in rows:
        assert r["status"] == "ok"
        params = {"K": float(r["K"]), "n": float(r["n"]), "c_r": float(r["c_r"])}
        direct = simulate("Penetrator", start_values=params, stop_time=3.0, output_interval=1e-3)
        # the record of the deepest penetration is an exact event value: equal bit for bit
        assert float(r["delta_max_m"]) == direct["delta_max"][-1] > 0
        # hops = liftoffs: contact (s = 1) -> flight (s = 0) on the 1 ms grid
        s = direct["s"]
        lifts = np.flatnonzero((s[:-1] == 1) & (s[1:] == 0)) + 1
        assert int(r["n_hops"]) == len(lifts) >= 2
        # first rebound height: the highest sample of y in the first flight after a liftoff
        land = np.flatnonzero((s[:-1] == 0) & (s[1:] == 1))
        land = land[land > lifts[0]][0]
        apex = np.max(direct["y"][lifts[0]:land + 1])
        assert math.isclose(float(r["rebound_height_m"]), apex, abs_tol=1e-5), (r["rebound_height_m"], apex)
        assert float(r["rebound_height_m"]) >= apex


def test_run_and_ssp_are_subcommands_of_pogofmu(tmp_path):
    """The entry points moved under the console script: pogofmu run (the master), pogofmu ssp."""
    from support import DIST

    check = subprocess.run([str(POGOFMU), "ssp", "check", str(DIST / "SpaceHopper.ssp")],
                           capture_output=True, text=True, timeout=120)
    assert check.returncode == 0 and "is valid" in check.stdout, check.stdout + check.stderr
    bad = subprocess.run([str(POGOFMU), "ssp", "check", str(tmp_path / "none.ssp")], capture_output=True, text=True,
                         timeout=120)
    assert bad.returncode != 0
    run = subprocess.run([str(POGOFMU), "run", "--dist", str(DIST), "--out", str(tmp_path / "results"), "PogoStick"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    with open(tmp_path / "results" / "PogoStick" / "timeseries.csv") as f:
        rows = list(csv.DictReader(f))
    assert float(rows[-1]["time"]) == pytest.approx(10.0) and int(rows[-1]["n_events"]) == 19
    unknown = subprocess.run([str(POGOFMU), "nosuch"], capture_output=True, text=True, timeout=60)
    assert unknown.returncode == 2 and "unknown command 'nosuch'" in unknown.stderr


def test_a_worker_killed_mid_sweep_loses_no_run(tmp_path, gate_fmu, gate):
    """A worker process dies (SIGKILL) while it runs a chunk — held at the gate, so it is surely
    in the middle of one; Dask may not retry the task here (allowed-failures 0), so the sweep
    reruns the chunk's points one by one: every run is a row."""
    import dask
    from distributed import Client, LocalCluster

    before = _children()
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    try:
        client = Client(cluster)
        pids = client.run(os.getpid)
        out, parts = tmp_path / "k.parquet", tmp_path / "k.parquet.parts"
        n = 20
        proc = subprocess.Popen([str(POGOFMU), "sweep", str(gate_fmu), "--grid", f"k=0:{n - 1}:{n}",
                                 "--set", "hold=5", "--set", gate.set, "--stop-time", "0.1", "--step", "0.05", "--outputs", "y",
                                 "--chunk-size", "5", "--scheduler", cluster.scheduler_address, "--out", str(out),
                                 "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _wait_for(lambda: len(_saved(parts)) >= 5, proc)  # the free chunk (k = 0..4) is saved
        busy = []

        def a_worker_holds_a_chunk():
            busy[:] = [w for w, keys in client.processing().items() if keys and w in pids]
            return bool(busy)
        _wait_for(a_worker_holds_a_chunk, proc)  # every other chunk waits at the gate
        os.kill(pids[busy[0]], signal.SIGKILL)
        gate.open()
        stdout, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 0, stderr[-3000:]
        rows = pq.read_table(out).to_pylist()
        assert [r["run_id"] for r in rows] == list(range(n))
        assert all(r["status"] == "ok" and r["y_final"] == r["k"] for r in rows), [r["message"] for r in rows]
        assert len(list(parts.glob("*"))) == 0 and f"{n} runs" in stdout
        assert "KilledWorker" in stdout and "running them one by one" in stdout, stdout + stderr[-3000:]
    finally:
        client.close()
        cluster.close()
    assert not _wait_gone(_children() - before), "worker processes left behind"


_KILLED_WORKERS = r"""
import os, subprocess, sys, time
import psutil
from distributed import LocalCluster

if __name__ == "__main__":
    pogofmu, fmu, out = sys.argv[1:]
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    proc = subprocess.run([pogofmu, "sweep", fmu, "--grid", "k=80,90,100,120", "--stop-time", "0.2", "--chunk-size", "1",
                           "--scheduler", cluster.scheduler_address, "--out", out, "--no-progress"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and "0 failed" in proc.stdout, proc.stdout + proc.stderr[-2000:]
    workers = [p for p in psutil.Process().children(recursive=True) if "resource_tracker" not in " ".join(p.cmdline())]
    for p in workers:  # as the OOM killer or a batch system's limit ends them: no exit handler runs
        p.kill()
    psutil.wait_procs(workers, timeout=60)
    cluster.close()
    LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0").close()  # a later cluster
    print(len(workers), "workers killed")
"""


def test_workers_killed_after_a_sweep_leave_no_copy_of_the_fmu_behind(tmp_path):
    """Each worker writes the scattered FMU and its extraction to disk. A worker process that is
    killed runs no exit handler, so those copies must lie in the worker's own Dask folder, which Dask
    removes when a later worker starts there; in a folder of their own in the system's temporary
    folder (the sweep before this test) every killed worker left about 1 MB behind for good."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    script = tmp_path / "killed_workers.py"
    script.write_text(_KILLED_WORKERS)
    env = dict(os.environ, TMPDIR=str(tmp))  # the temporary folder of every process of the scenario
    proc = subprocess.run([sys.executable, str(script), str(POGOFMU), str(fmu_path("PogoStick")), str(tmp_path / "o.parquet")],
                          capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path)
    assert proc.returncode == 0 and "2 workers killed" in proc.stdout, proc.stdout + proc.stderr[-3000:]
    assert pq.read_table(tmp_path / "o.parquet").num_rows == 4
    # what remains is Dask's own two lock files of its scratch space, empty
    left = sorted(str(p.relative_to(tmp)) for p in tmp.rglob("*") if p.is_file() and p.name not in ("global.lock", "purge.lock"))
    assert not left, f"left in the temporary folder after the killed workers: {left}"


def test_a_lost_scheduler_stops_the_sweep_and_resume_finishes_it_elsewhere(tmp_path, scheduler, gate_fmu, gate):
    """The cluster goes away mid-sweep (while the held runs wait at the gate): the sweep stops at
    once, says so, keeps what it saved and records no run it did not do; --resume on another
    cluster, gate open, runs the rest."""
    from distributed import LocalCluster

    before = _children()
    lost = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0")
    out, parts = tmp_path / "l.parquet", tmp_path / "l.parquet.parts"
    n = 16
    args = [str(POGOFMU), "sweep", str(gate_fmu), "--grid", f"k=0:{n - 1}:{n}", "--set", "hold=4", "--set", gate.set,
            "--stop-time", "0.1", "--step", "0.05", "--outputs", "y", "--chunk-size", "2", "--out", str(out),
            "--no-progress"]
    proc = subprocess.Popen(args + ["--scheduler", lost.scheduler_address], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: len(_saved(parts)) >= 4, proc)  # the two free chunks (k = 0..3) are saved
    finally:
        lost.close()
    stdout, stderr = proc.communicate(timeout=120)
    assert not _wait_gone(_children() - before), "worker processes left behind"
    assert proc.returncode == 2 and "the sweep stopped" in stderr and "--resume runs the rest" in stderr, stderr[-2000:]
    saved = list(_saved(parts).values())
    assert sorted(r["run_id"] for r in saved) == [0, 1, 2, 3] and all(r["status"] == "ok" for r in saved)
    gate.open()
    resumed = subprocess.run(args + ["--scheduler", scheduler, "--resume"], capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    rows = pq.read_table(out).to_pylist()
    assert [r["run_id"] for r in rows] == list(range(n)) and all(r["status"] == "ok" for r in rows)


def _hide_pogofmu():
    sys.modules["pogofmu.sweep"] = None  # the worker's next import of it fails, as where it is not installed


def _unhide_pogofmu():
    sys.modules.pop("pogofmu.sweep", None)


def test_workers_without_pogofmu_are_refused_before_any_run(tmp_path, scheduler):
    from distributed import Client

    with Client(scheduler) as client:
        client.run(_hide_pogofmu)
        try:
            out = tmp_path / "n.parquet"
            proc = subprocess.run([str(POGOFMU), "sweep", str(fmu_path("PogoStick")), "--grid", "k=80,90",
                                   "--scheduler", scheduler, "--out", str(out), "--no-progress"],
                                  capture_output=True, text=True, timeout=120)
        finally:
            client.run(_unhide_pogofmu)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "the cluster's workers cannot run a sweep (ModuleNotFoundError" in proc.stderr
    assert "they need pogofmu" in proc.stderr and not out.exists()
