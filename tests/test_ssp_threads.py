"""The SSP master at scale on a 1-ring native mirror (docs/ssp-master.md, "Threads and
recording"): ``--threads 2`` gives the bits of ``--threads 1`` (Gauss–Seidel and Jacobi, events
on, actuators on their stops), an error of a component stepped on a worker thread is the
master's one line, and ``--record`` writes exactly the selected columns of the full run."""
from __future__ import annotations

import zipfile

import numpy as np
import pytest

from support import run_pogofmu

STOP = "0.8"  # the gust (0.3-0.7 s) has put segments on both stops by then


def pogofmu(*args, cwd):
    return run_pogofmu(*args, cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def mirror(tmp_path_factory):
    folder = tmp_path_factory.mktemp("threads")
    proc = pogofmu("mirror", "--rings", "1", "--backend", "native", "--out", "m.ssp", cwd=folder)
    assert proc.returncode == 0, proc.stderr
    return folder


def run(folder, name, *args, ssp="m.ssp"):
    proc = pogofmu("ssp", "run", ssp, "--step", "1e-3", "--stop-time", STOP, "--out", name, "--quiet", *args,
                   cwd=folder)
    return proc, folder / name / "default.csv"


def table(path):
    return np.genfromtxt(path, delimiter=",", names=True, deletechars="")


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_two_threads_give_the_bits_of_one(mirror, algorithm):
    got = {}
    for threads in ("1", "2"):
        proc, csv = run(mirror, f"{algorithm}-{threads}", "--algorithm", algorithm, "--threads", threads)
        assert proc.returncode == 0, proc.stderr
        got[threads] = table(csv)
    one, two = got["1"], got["2"]
    modes = np.array([one[f"Actuator_{i}.mode"] for i in range(1, 8)])
    assert (modes == 1).any() and (modes == -1).any()  # stops hit: rollbacks and cut steps on both threads
    assert (one["event"] != 0).any()
    assert one.dtype.names == two.dtype.names and len(one) == len(two)
    for col in one.dtype.names:
        assert np.array_equal(one[col], two[col]), col


def _failing(mirror):
    """The mirror with Actuator_2 allowed 3 solver steps per call: its first step fails."""
    edited = mirror / "failing.ssp"
    if edited.exists():
        return edited
    with zipfile.ZipFile(mirror / "m.ssp") as src, zipfile.ZipFile(edited, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "resources/actuator_2.ssv":
                data = data.decode().replace(
                    "  </ssv:Parameters>",
                    '    <ssv:Parameter name="max_steps_per_call"><ssv:Real value="3"/></ssv:Parameter>\n'
                    "  </ssv:Parameters>").encode()
            dst.writestr(item, data)
    return edited


def test_a_component_failing_on_a_worker_thread_ends_the_run_in_one_line(mirror):
    """Actuator_2 is stepped on a worker thread (C: the level's components are taken in order by
    both threads; the first step of Actuator_2 fails there)."""
    proc, _ = run(mirror, "failing", "--threads", "2", ssp=_failing(mirror))
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and "Component Actuator_2" in errors[0] and "max_steps_per_call" in errors[0], proc.stderr


def test_recorded_columns_are_those_of_the_full_run(mirror):
    proc, full = run(mirror, "full")
    assert proc.returncode == 0, proc.stderr
    proc, part = run(mirror, "part", "--record", "Actuator_*.z,Reconstructor.piston_rms")
    assert proc.returncode == 0, proc.stderr
    full, part = table(full), table(part)
    assert part.dtype.names == ("time", "event", *[f"Actuator_{i}.z" for i in range(1, 8)],
                                "Reconstructor.piston_rms")
    assert len(part) == len(full)
    for col in part.dtype.names:
        assert np.array_equal(part[col], full[col]), col


def test_a_record_pattern_matching_nothing_is_one_line_naming_it(mirror):
    proc, _ = run(mirror, "none", "--record", "Actuator_*.z,Actuator_*.nothing")
    assert proc.returncode == 1
    assert proc.stderr.strip().count("\n") == 0 and "'Actuator_*.nothing'" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr


# ---- the C stepping of a level (pogofmu/ssp/native_level.py) against the Python path ---------------

class Calls(list):
    slow = 0
    macro = 0  # macro steps of several levels in one C call


def _simulate(ssp, monkeypatch, native, calls, **kw):
    """The run in this process, with the C path on or off; ``calls`` gets the size of every C
    level call it made (a macro step of several levels in one call: each level's), and
    ``calls.slow`` the number of components of those levels left to the Python path."""
    import pogofmu.ssp.native_level as nl
    from pogofmu.ssp import simulate

    monkeypatch.setenv("POGOFMU_SSP_NATIVE_LEVELS", "1" if native else "0")
    go, macro_go = nl.Batch.go, nl.Macro.go

    def count(batch):
        calls.append(len(batch.fast))
        if hasattr(calls, "slow"):
            calls.slow += len(batch.slow)

    def counted(self, t, h):
        count(self)
        return go(self, t, h)

    def counted_macro(self, t, h):
        stop, bad = macro_go(self, t, h)
        if hasattr(calls, "macro"):
            calls.macro += 1
        for batch in self.batches[:stop + 1]:
            count(batch)
        return stop, bad
    monkeypatch.setattr(nl.Batch, "go", counted)
    monkeypatch.setattr(nl.Macro, "go", counted_macro)
    try:
        return simulate(str(ssp), stop_time=float(STOP), step=1e-3, echo_log=False, **kw)
    finally:
        monkeypatch.setattr(nl.Batch, "go", go)
        monkeypatch.setattr(nl.Macro, "go", macro_go)


@pytest.mark.parametrize("algorithm,events", [("gauss-seidel", True), ("jacobi", True), ("gauss-seidel", False),
                                              ("jacobi", False)])
def test_the_c_path_gives_the_bits_of_the_python_path(mirror, monkeypatch, algorithm, events):
    """Every column of the 1-ring mirror (actuators on their stops: rollbacks, cut steps), the C
    path on two threads against the Python path (POGOFMU_SSP_NATIVE_LEVELS=0) on one."""
    calls, none = Calls(), []
    c = _simulate(mirror / "m.ssp", monkeypatch, True, calls, algorithm=algorithm, events=events, threads=2)
    py = _simulate(mirror / "m.ssp", monkeypatch, False, none, algorithm=algorithm, events=events)
    assert max(calls) == (15 if algorithm == "jacobi" else 7) and not none  # every component in C: a level, or all
    # the controllers and the reconstructor take their inputs as lines (Gauss-Seidel): set in C too
    assert calls.slow == 0
    # synchronized Gauss-Seidel: the levels of a macro step in one C call (a level's own call at events)
    assert (calls.macro > 100) == (algorithm == "gauss-seidel" and events), calls.macro
    assert (c["event"] != 0).any() == events
    modes = np.array([c[f"Actuator_{i}.mode"] for i in range(1, 8)])
    assert (modes == 1).any() and (modes == -1).any()
    assert c.names == py.names and len(c.names) > 80 and len(c["time"]) == len(py["time"])
    for name in c.names:
        a, b = np.asarray(c[name], dtype=np.float64), np.asarray(py[name], dtype=np.float64)
        assert np.array_equal(a.view(np.int64), b.view(np.int64)), name


def test_an_fmu_error_in_a_c_stepped_level_is_the_masters_error(mirror, monkeypatch):
    """Actuator_2 fails its first step inside the C call (one thread, two threads): the run ends
    with the master's error naming it, the call and the FMU's message, in the Python path's words."""
    from pogofmu.ssp.package import SSPError

    texts = []
    for native, threads in ((True, 1), (True, 2), (False, 1)):
        calls = []
        with pytest.raises(SSPError) as exc:
            _simulate(_failing(mirror), monkeypatch, native, calls, threads=threads)
        assert bool(calls) == native
        texts.append(str(exc.value))
    assert texts[0] == texts[1] == texts[2], texts
    assert texts[0].startswith("Component Actuator_2: fmi2DoStep from t = 0 s") and "max_steps_per_call" in texts[0]
