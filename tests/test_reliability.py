"""Reliability, third round: each reproduction of the issue as a regression test.

Sweeps that write only what they were told to; bad sweep inputs refused in one line before any
worker starts; FMU states that carry their model, build and integrity; the standard's call
sequence enforced; concurrency; messages that name the real cause.
"""
import contextlib
import io
import os
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from pogofmu.fmpy_raw import raw_call
from support import DIST, fmu_path

POGOFMU = Path(sys.executable).with_name("pogofmu")


def sweep(*args, timeout=300):
    return subprocess.run([str(POGOFMU), "sweep", *map(str, args), "--no-progress"], capture_output=True, text=True,
                          timeout=timeout)


# ---------------------------------------------------------------------------------------------
# 4. the sweep writes only regular files it created or was told to overwrite; bad input is one line
# ---------------------------------------------------------------------------------------------

def test_overwrite_never_replaces_a_device_a_pipe_a_folder_or_a_link(tmp_path):
    fifo = tmp_path / "pipe.parquet"
    os.mkfifo(fifo)
    link = tmp_path / "null.parquet"
    link.symlink_to("/dev/null")
    folder = tmp_path / "folder.parquet"
    folder.mkdir()
    (folder / "keep").write_text("mine")
    null_before = os.stat("/dev/null")
    for out, kind in ((fifo, "not a regular file"), (link, "a symbolic link"), (folder, "a folder")):
        proc = sweep(fmu_path("PogoStick"), "--grid", "k=90,100", "--stop-time", "0.1", "--overwrite", "--out", out)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.count("\n") == 1 and kind in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and os.readlink(link) == "/dev/null"
    assert (folder / "keep").read_text() == "mine"
    now = os.stat("/dev/null")
    assert stat.S_ISCHR(now.st_mode) and (now.st_ino, now.st_rdev) == (null_before.st_ino, null_before.st_rdev)


def test_an_existing_output_is_replaced_only_with_overwrite(tmp_path):
    """Without --overwrite an existing table is refused (one line, exit 2) and left byte for byte;
    with --overwrite the sweep replaces it by its own table."""
    import pyarrow.parquet as pq

    out = tmp_path / "table.parquet"
    out.write_bytes(b"a table from yesterday")
    proc = sweep(fmu_path("PogoStick"), "--grid", "k=90,100", "--stop-time", "0.1", "--workers", "1", "--out", out)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "exists: give --resume or --overwrite" in proc.stderr and str(out) in proc.stderr, proc.stderr
    assert out.read_bytes() == b"a table from yesterday"
    proc = sweep(fmu_path("PogoStick"), "--grid", "k=90,100", "--stop-time", "0.1", "--workers", "1", "--overwrite",
                 "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert sorted(r["k"] for r in pq.read_table(out).to_pylist()) == [90.0, 100.0]


def _not_an_fmu(tmp_path):
    bad = tmp_path / "notzip.fmu"
    bad.write_text("not a zip")
    nomd = tmp_path / "nomd.fmu"
    with zipfile.ZipFile(nomd, "w") as z:
        z.writestr("other.txt", "x")
    broken = tmp_path / "broken.fmu"
    with zipfile.ZipFile(broken, "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription")
    return bad, nomd, broken


@pytest.mark.parametrize("case", ["seed -1", "out in /proc", "out a folder", "not a zip", "zip without md",
                                  "broken md", "scheduler ::::", "workers 0", "outputs empty", "set and grid",
                                  "grid nan inf", "grid 1e400", "set inf"])
def test_each_bad_sweep_input_is_one_line_before_any_worker(case, tmp_path):
    fmu = fmu_path("PogoStick")
    bad, nomd, broken = _not_an_fmu(tmp_path)
    out = tmp_path / "r.parquet"
    args, words = {
        "seed -1": ([fmu, "--sample", "k=uniform(80,120)", "--samples", 2, "--seed", -1, "--out", out], "--seed -1"),
        "out in /proc": ([fmu, "--grid", "k=90,100", "--out", "/proc/x.parquet"], "cannot be written"),
        "out a folder": ([fmu, "--grid", "k=90,100", "--out", tmp_path], "a folder"),
        "not a zip": ([bad, "--grid", "k=90,100", "--out", out], "not an FMU (not a zip archive)"),
        "zip without md": ([nomd, "--grid", "k=90,100", "--out", out], "without modelDescription.xml"),
        "broken md": ([broken, "--grid", "k=90,100", "--out", out], "modelDescription.xml cannot be read"),
        "scheduler ::::": ([fmu, "--grid", "k=90,100", "--scheduler", "::::", "--out", out], "--scheduler '::::'"),
        "workers 0": ([fmu, "--grid", "k=90,100", "--workers", 0, "--out", out], "--workers 0: must be >= 1"),
        "outputs empty": ([fmu, "--grid", "k=90,100", "--outputs=", "--out", out], "--outputs '': names no output"),
        "set and grid": ([fmu, "--grid", "k=90,100", "--set", "k=1", "--out", out], "both swept"),
        "grid nan inf": ([fmu, "--grid", "k=nan,inf", "--out", out], "'nan' is not a finite number"),
        "grid 1e400": ([fmu, "--grid", "k=1e400", "--out", out], "'1e400' is not a finite number"),
        "set inf": ([fmu, "--grid", "k=90,100", "--set", "c=inf", "--out", out], "'inf' is not a finite number"),
    }[case]
    proc = sweep(*args, timeout=120)
    assert proc.returncode in (1, 2), proc.stderr
    assert proc.stderr.startswith("error: ") and proc.stderr.count("\n") == 1, proc.stderr
    assert words in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert not out.exists() and not Path(str(out) + ".parts").exists()


# ---------------------------------------------------------------------------------------------
# 2. an FMU state carries its model, build, FMI version and an integrity seal
# ---------------------------------------------------------------------------------------------

from support import Instance  # noqa: E402


def _fmi3(name):
    """An FMI 3.0 co-simulation instance of dist/fmi3/<name>.fmu through fmpy, initialized."""
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    path = DIST / "fmi3" / f"{name}.fmu"
    md = read_model_description(str(path))
    messages = []
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=f"{name}3")
    fmu.instantiate(loggingOn=True, logMessage=lambda env, status, cat, msg: messages.append((status, msg.decode())))
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return fmu, messages


@pytest.mark.parametrize("own,foreign", [("PogoStick", "Penetrator"), ("PogoStickSMA", "HopController"),
                                         ("PogoStickSMA", "PogoStick")])
def test_another_models_state_is_refused_with_error_naming_both(own, foreign):
    """fmi2SetFMUstate with another model's in-memory state: Error (not OK and silently wrong, not
    Fatal), both models named, and the instance runs on as if nothing happened."""
    from fmpy.fmi1 import FMICallException

    a, b = Instance(own, "own").init(), Instance(foreign, "foreign").init()
    ref = Instance(own, "reference").init()
    try:
        b.run_to(0.5, 1e-3)
        st = b.fmu.getFMUstate()
        with pytest.raises(FMICallException) as exc:
            a.fmu.setFMUstate(st)
        assert "(error)" in str(exc.value)
        text = a.messages[-1][2]
        assert f"model '{foreign}'" in text and f"model '{own}'" in text and "refused" in text, text
        b.fmu.freeFMUstate(st)
        for inst in (a, ref):
            inst.run_to(1.0, 1e-3)
        assert a.outputs() == ref.outputs()
    finally:
        for inst in (a, b, ref):
            inst.close()


def test_another_builds_serialized_state_is_refused_naming_the_build(tmp_path):
    """Two builds of one model and FMI version (here: the session's and one with another token
    seed, as a rebuilt FMU would be) share names and variables but not their states: a state
    serialized by one is refused by the other with Error naming the build, and the instance runs on."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    from pogofmu import build

    with contextlib.redirect_stdout(io.StringIO()):
        other = build.build_one("PogoStick", tmp_path, token_seed="another build")
    md = read_model_description(str(other))
    assert md.guid != read_model_description(str(fmu_path("PogoStick"))).guid
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(other)), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="other", fmiCallLogger=None)
    from support import fmi2_callbacks

    callbacks = fmi2_callbacks([])
    fmu.instantiate(loggingOn=True, callbacks=callbacks.struct)
    own = Instance("PogoStick", "own").init()
    try:
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        own.run_to(0.3, 1e-3)
        blob = bytes(own.fmu.serializeFMUstate(own.fmu.getFMUstate()))
        with pytest.raises(FMICallException) as exc:
            fmu.deSerializeFMUstate(blob)
        assert "(error)" in str(exc.value)
        fmu.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.1)  # still usable
        own_blob = bytes(fmu.serializeFMUstate(fmu.getFMUstate()))
        with pytest.raises(FMICallException):
            own.fmu.deSerializeFMUstate(own_blob)
        text = own.messages[-1][2]
        assert "build" in text and "refused" in text, text
    finally:
        own.close()
        fmu.terminate()
        fmu.freeInstance()


def test_fmi3_refuses_the_fmi2_builds_state_and_every_flipped_bit():
    """The FMI 2.0 and FMI 3.0 builds of one model share their code but not their states; a
    serialized FMI 3.0 state with any one bit flipped is refused as damaged (20 of 20), with
    Error, and the instance stays usable."""
    from fmpy.fmi1 import FMICallException

    two = Instance("PogoStick", "two").init()
    three, messages = _fmi3("PogoStick")
    try:
        two.run_to(0.3, 1e-3)
        blob2 = bytes(two.fmu.serializeFMUstate(two.fmu.getFMUstate()))
        with pytest.raises(Exception) as exc:
            three.deserializeFMUState(blob2)
        assert "error" in str(exc.value).lower()
        assert "FMI 2.0" in messages[-1][1] and "FMI 3.0" in messages[-1][1], messages[-1]
        three.doStep(0.0, 0.3)
        blob3 = bytes(three.serializeFMUState(three.getFMUState()))
        import random

        rng = random.Random(20)
        for _ in range(20):
            i = rng.randrange(len(blob3) * 8)
            flipped = bytearray(blob3)
            flipped[i // 8] ^= 1 << (i % 8)
            with pytest.raises(FMICallException) as exc:
                three.deserializeFMUState(bytes(flipped))
            assert "(error)" in str(exc.value)
            assert "damaged" in messages[-1][1] or "not a serialized pogofmu FMU state" in messages[-1][1], messages[-1]
        state = three.deserializeFMUState(blob3)  # the intact bytes still restore
        three.setFMUState(state)
        three.doStep(0.3, 0.1)
    finally:
        two.close()
        three.terminate()
        three.freeInstance()


# ---------------------------------------------------------------------------------------------
# 1. concurrent first instantiation: one interpreter start, one import of a build, any thread
# ---------------------------------------------------------------------------------------------

import json  # noqa: E402

from support import ROOT, compile_c_host  # noqa: E402

SAME = ["PogoStick"] * 4
MIXED = ["PogoStick", "PogoStickMem", "Penetrator", "HopController", "PogoStickSMA"]


def _sequential(names):
    """What each thread must report: the same FMU alone, 100 steps of 1 ms (fmpy, this process)."""
    out = {}
    for n in set(names):
        inst = Instance(n, "alone").init()
        try:
            for k in range(100):  # the threads' communication points, k * 1e-3
                inst.fmu.doStep(currentCommunicationPoint=k * 1e-3, communicationStepSize=1e-3)
            y = next(v for v in inst.md.modelVariables if v.causality == "output" and v.type == "Real")
            out[n] = (y.name, inst.get(y.name))
        finally:
            inst.close()
    return out


@pytest.mark.parametrize("names", [SAME, MIXED], ids=["same FMU x4", "five FMUs"])
def test_first_instantiations_from_threads_in_fmpy(names):
    """Each of 5 fresh processes releases the threads together before fmi2Instantiate: every one
    instantiates (3 of 4 returned NULL before) and computes what the FMU computes alone."""
    expected = _sequential(names)
    for _ in range(5):
        proc = subprocess.run([sys.executable, str(ROOT / "tests" / "_threads_fmpy.py"), str(DIST), ",".join(names)],
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        got = json.loads(proc.stdout.strip().splitlines()[-1])
        for n, r in zip(names, got):
            # (a failure: the FMU's log, which fmpy prints to stdout, says why)
            assert r == ["ok", *expected[n]], (n, r, proc.stdout[-3000:], proc.stderr[-1000:])


def test_instantiations_while_another_thread_calls_py_getversion(tmp_path):
    """The launcher reads the host's CPython version without Py_GetVersion's static buffer, which
    every call rewrites from an empty text: with a C thread of the process calling Py_GetVersion
    without pause, each of the five Python-hosted FMUs (five copies of the launcher, each checking
    the host's CPython) instantiates in each of 3 fresh processes. Before, about a third of them
    failed here ("this process runs CPython 3.11.7 ... needs 3.10 to 3.13"), and about 1 in 250 of
    the fmpy-threads starts above under load."""
    from pogofmu.codegen.build import c_compiler

    hammer = tmp_path / "py_version_hammer.so"
    subprocess.run([*c_compiler(), "-O2", "-shared", "-fPIC", "-pthread", str(ROOT / "tests" / "c_host" / "py_version_hammer.c"),
                    "-o", str(hammer)], check=True)
    for _ in range(3):
        proc = subprocess.run([sys.executable, str(ROOT / "tests" / "_version_race.py"), str(DIST), ",".join(MIXED),
                               str(hammer)], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        got = json.loads(proc.stdout.strip().splitlines()[-1])
        assert got == ["ok"] * len(MIXED), (got, proc.stdout[-3000:])


def test_a_build_instantiated_a_thousand_times_imports_its_code_once():
    """docs/using-fmus.md: "the same build instantiated a thousand times imports its code once" —
    in a fresh process, after 1 000 instances (one after the other, each stepped and freed) the
    FMU's private modules are the very module objects the first instance imported, and the boot
    code created each of its modules once."""
    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "_thousand_instances.py"), str(DIST / "PogoStick.fmu"),
                           "1000"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["first"] and got["last"] == got["first"], (len(got["first"]), len(got["last"]))
    assert any(name.endswith("_slave") for name in got["first"]), sorted(got["first"])
    assert got["created"] and len(got["created"]) == len(set(got["created"])), got["created"]


def _unzipped(tmp_path, name):
    d = tmp_path / name
    if not d.exists():
        with zipfile.ZipFile(DIST / f"{name}.fmu") as z:
            z.extractall(d)
    return d


NATIVE = [f"native/{n}" for n in MIXED]


@pytest.mark.parametrize("names", [SAME, MIXED, SAME[:2] + MIXED, NATIVE + MIXED],
                         ids=["same FMU x4", "five FMUs", "seven", "native and Python-hosted, ten"])
def test_first_instantiations_from_pthreads_in_a_c_host_without_python(names, tmp_path):
    """A pthreads C host with an empty environment: the threads call fmi2Instantiate of the same or of
    different FMUs at once (libraries that each start the interpreter under a lock of their own
    crash here: SIGSEGV, SIGABRT). 8 fresh processes each, every thread ends with the value the FMU computes alone."""
    from fmpy import read_model_description

    host = compile_c_host(ROOT / "tests" / "c_host" / "fmi2_threads.c", tmp_path / "fmi2_threads")
    expected = _sequential(names)
    args = []
    for n in names:
        d = _unzipped(tmp_path, n)
        md = read_model_description(str(d / "modelDescription.xml"))
        vr = next(v.valueReference for v in md.modelVariables if v.name == expected[n][0])
        args.append(f"{d}:{md.coSimulation.modelIdentifier}:{md.guid}#{vr}")
    for _ in range(8):
        proc = subprocess.run([str(host), *args], capture_output=True, text=True, timeout=300,
                              env={"PATH": "/usr/bin:/bin"})
        assert proc.returncode == 0, (proc.returncode, proc.stdout, proc.stderr[-2000:])
        for line, n in zip(proc.stdout.splitlines(), names):
            _, status, t, y = line.split()
            assert status == "ok" and float(y) == expected[n][1], (n, line)


FMI3_MIXED = [f"fmi3/{n}" for n in MIXED] + [f"native/fmi3/{n}" for n in MIXED]


@pytest.mark.parametrize("names", [["fmi3/PogoStick"] * 4, FMI3_MIXED], ids=["same FMU x4", "ten FMI 3.0 FMUs"])
def test_fmi3_first_instantiations_from_pthreads_in_a_c_host_without_python(names, tmp_path):
    """FMI 3.0 co-simulation with event mode and early return, from a pthreads C host with an empty
    environment: the threads instantiate Python-hosted and native FMUs at once and each run ends
    with what the same host computes with that FMU alone (time, output, events handled)."""
    from fmpy import read_model_description

    host = compile_c_host(ROOT / "tests" / "c_host" / "fmi3_threads.c", tmp_path / "fmi3_threads")
    args = []
    for n in names:
        d = _unzipped(tmp_path, n)
        md = read_model_description(str(d / "modelDescription.xml"))
        vr = next(v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Float64")
        args.append(f"{d}:{md.coSimulation.modelIdentifier}:{md.guid}#{vr}")
    env = {"PATH": "/usr/bin:/bin"}
    alone = {}
    for a in set(args):
        proc = subprocess.run([str(host), a], capture_output=True, text=True, timeout=300, env=env)
        assert proc.returncode == 0, (a, proc.stdout, proc.stderr[-2000:])
        alone[a] = proc.stdout.split(None, 1)[1].strip()
    assert any(int(v.split()[-1]) > 0 for v in alone.values())  # events handled in Event Mode
    for _ in range(5):
        proc = subprocess.run([str(host), *args], capture_output=True, text=True, timeout=300, env=env)
        assert proc.returncode == 0, (proc.returncode, proc.stdout, proc.stderr[-2000:])
        for line, a in zip(proc.stdout.splitlines(), args):
            assert line.split(None, 1)[1].strip() == alone[a], (a, line)


# ---------------------------------------------------------------------------------------------
# 3. the standard's call sequence: refused with Error naming the function and the state
# ---------------------------------------------------------------------------------------------

def _raw(fmu, name, *args):
    """The FMU's own function, its status returned (fmpy's wrappers raise on Error)."""
    return raw_call(fmu, name, *args)


def _fmi2(name="PogoStick"):
    inst = Instance(name, "calls")
    return inst, inst.fmu


def _last(inst):
    return inst.messages[-1][2] if inst.messages else ""


def test_fmi2_calls_out_of_sequence_are_refused_and_the_instance_goes_on():
    import ctypes

    inst, fmu = _fmi2()
    try:
        F = ctypes.c_double
        # before initialization: no step, no exit, no terminate
        assert _raw(fmu, "fmi2ExitInitializationMode") == 3
        assert "fmi2ExitInitializationMode refused: not allowed in Instantiated" in _last(inst)
        assert _raw(fmu, "fmi2DoStep", F(0.0), F(1e-3), 1) == 3 and "fmi2DoStep refused" in _last(inst)
        # a bad tolerance, an unknown log category
        assert _raw(fmu, "fmi2SetupExperiment", 1, F(-1.0), F(0.0), 0, F(0.0)) == 3
        assert "tolerance = -1 violates the rule" in _last(inst)
        cats = (ctypes.c_char_p * 1)(b"logNoSuchThing")
        assert _raw(fmu, "fmi2SetDebugLogging", 1, 1, cats) == 3
        assert "'logNoSuchThing' is not a log category of this FMU" in _last(inst) and "logEvents" in _last(inst)
        # the legal sequence still works
        assert _raw(fmu, "fmi2SetupExperiment", 0, F(0.0), F(0.0), 0, F(0.0)) == 0
        assert _raw(fmu, "fmi2EnterInitializationMode") == 0
        assert _raw(fmu, "fmi2EnterInitializationMode") == 3  # a second one
        assert "not allowed in Initialization Mode" in _last(inst)
        assert _raw(fmu, "fmi2ExitInitializationMode") == 0
        assert _raw(fmu, "fmi2SetupExperiment", 0, F(0.0), F(0.0), 0, F(0.0)) == 3  # after initialization
        assert "fmi2SetupExperiment refused: not allowed in Step Complete" in _last(inst)
        assert _raw(fmu, "fmi2DoStep", F(0.0), F(1e-3), 1) == 0
        assert _raw(fmu, "fmi2Terminate") == 0
        assert _raw(fmu, "fmi2DoStep", F(1e-3), F(1e-3), 1) == 3  # after terminate
        assert "fmi2DoStep refused: not allowed in Terminated" in _last(inst)
        assert not [m for m in inst.messages if m[0] >= 4]  # nothing fatal
        assert _raw(fmu, "fmi2Reset") == 0
        inst.init().run_to(0.01, 1e-3)  # usable after every refusal
    finally:
        fmu.freeInstance()


def _fmi3_raw(name, interface="cs", event_mode=False):
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Model, FMU3Slave

    path = DIST / "fmi3" / f"{name}.fmu"
    md = read_model_description(str(path))
    messages = []
    log = lambda env, status, cat, msg: messages.append((status, msg.decode()))  # noqa: E731
    if interface == "cs":
        fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="calls3")
        fmu.instantiate(loggingOn=True, eventModeUsed=event_mode, earlyReturnAllowed=event_mode, logMessage=log)
    else:
        fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.modelExchange.modelIdentifier,
                        instanceName="calls3")
        fmu.instantiate(loggingOn=True, logMessage=log)
    return fmu, messages


def test_fmi3_calls_out_of_sequence_are_refused():
    import ctypes

    B = ctypes.c_bool
    flags = [B(), B(), B(), B(), B()]
    refs = [ctypes.byref(f) for f in flags] + [ctypes.byref(ctypes.c_double())]
    # co-simulation without event mode: no Event Mode at all
    fmu, messages = _fmi3_raw("PogoStick", "cs", event_mode=False)
    try:
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()  # -> Step Mode
        assert _raw(fmu, "fmi3UpdateDiscreteStates", *refs) == 3
        assert "fmi3UpdateDiscreteStates refused: not allowed in Step Mode" in messages[-1][1]
        assert _raw(fmu, "fmi3EnterEventMode") == 3 and "eventModeUsed = false" in messages[-1][1]
        assert _raw(fmu, "fmi3EnterStepMode") == 3 and "fmi3EnterStepMode refused: not allowed in Step Mode" in \
            messages[-1][1]
        fmu.doStep(0.0, 1e-3)  # still usable
    finally:
        fmu.terminate()
        fmu.freeInstance()
    # with event mode: Event Mode twice in a row
    fmu, messages = _fmi3_raw("PogoStick", "cs", event_mode=True)
    try:
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()  # -> Event Mode
        assert _raw(fmu, "fmi3EnterEventMode") == 3 and "not allowed in Event Mode" in messages[-1][1]
        fmu.updateDiscreteStates()
        fmu.enterStepMode()
        fmu.enterEventMode()
        assert _raw(fmu, "fmi3EnterEventMode") == 3 and "fmi3EnterEventMode refused" in messages[-1][1]
    finally:
        fmu.terminate()
        fmu.freeInstance()
    # a co-simulation function on a model-exchange instance
    fmu, messages = _fmi3_raw("PogoStick", "me")
    try:
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        assert _raw(fmu, "fmi3EnterStepMode") == 3
        assert "it is a co-simulation function, and this instance is a model-exchange instance" in messages[-1][1]
    finally:
        fmu.freeInstance()


def test_model_exchange_counts_are_checked_naming_nx_and_nz():
    import ctypes

    fmu, messages = _fmi3_raw("PogoStick", "me")
    try:
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.updateDiscreteStates()
        fmu.enterContinuousTimeMode()
        buf = (ctypes.c_double * 32)()
        for function, n, words in (("fmi3GetContinuousStates", 2, "nContinuousStates = 2, and this FMU has nx = 7"),
                                   ("fmi3GetEventIndicators", 17, "nEventIndicators = 17, and this FMU has nz = 2"),
                                   ("fmi3GetContinuousStateDerivatives", 0, "nContinuousStates = 0, and this FMU has nx = 7"),
                                   ("fmi3SetContinuousStates", 3, "nContinuousStates = 3, and this FMU has nx = 7")):
            assert _raw(fmu, function, buf, n) == 3, function
            assert f"{function} refused: {words}" in messages[-1][1], messages[-1]
            assert "internal error" not in messages[-1][1]
        assert _raw(fmu, "fmi3GetContinuousStates", buf, 7) == 0
    finally:
        fmu.freeInstance()


# ---------------------------------------------------------------------------------------------
# 5. every message names the real cause first; paths work in any locale
# ---------------------------------------------------------------------------------------------

def _host():
    from support import compile_c_host

    return compile_c_host


def _c_host_run(tmp_path, unzipdir, env=None):
    from fmpy import read_model_description

    host = _host()(ROOT / "tests" / "c_host" / "fmi2_host.c", tmp_path / "fmi2_host")
    md = read_model_description(str(Path(unzipdir) / "modelDescription.xml"))
    y = next(v.valueReference for v in md.modelVariables if v.name == "y")
    return subprocess.run([str(host), str(unzipdir), md.coSimulation.modelIdentifier, md.guid, "0.01", "1e-3", str(y), "-"],
                          capture_output=True, text=True, timeout=120, env=env or {"PATH": "/usr/bin:/bin"})


def test_a_non_ascii_folder_works_in_a_c_host_with_the_c_locale(tmp_path):
    folder = tmp_path / "Flugbahn-Mondlandefähre-ø"
    with zipfile.ZipFile(DIST / "PogoStick.fmu") as z:
        z.extractall(folder)
    proc = _c_host_run(tmp_path, folder, env={"PATH": "/usr/bin:/bin", "LANG": "C", "LC_ALL": "C"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "UnicodeEncodeError" not in proc.stderr and len(proc.stdout.splitlines()) == 11


@pytest.mark.parametrize("damage,words", [
    ("boot", "the FMU's bootstrap resources/pogofmu_boot.py cannot be run"),
    ("package", "the FMU's code is missing"),
    ("launch", "the FMU's resources folder is incomplete"),
])
def test_a_damaged_resources_folder_is_named_as_such(tmp_path, damage, words):
    import shutil

    folder = tmp_path / "fmu"
    with zipfile.ZipFile(DIST / "PogoStick.fmu") as z:
        z.extractall(folder)
    res = folder / "resources"
    if damage == "boot":
        (res / "pogofmu_boot.py").unlink()
    elif damage == "package":
        shutil.rmtree(next(p for p in res.iterdir() if p.is_dir() and p.name.startswith("_pogofmu_")))
    else:
        (res / "pogofmu_launch.txt").write_text("# empty\n")
    proc = _c_host_run(tmp_path, folder)
    assert proc.returncode != 0
    assert words in proc.stderr, proc.stderr[-2000:]
    assert "no usable CPython" not in proc.stderr and "internal error" not in proc.stderr, proc.stderr[-2000:]


def test_a_connection_without_its_connector_is_named(tmp_path):
    from pogofmu import ssp
    from test_ssp import variant

    pkg = variant(tmp_path, edit_ssd=lambda t: t.replace(
        'startElement="HopController" startConnector="F_ext"', 'startElement="HopController"', 1))
    with pytest.raises(ssp.SSPError) as exc:
        ssp.simulate(pkg, stop_time=0.01, step=1e-3)
    assert "Connection 4: no startConnector attribute" in str(exc.value) and "None" not in str(exc.value)


# ---------------------------------------------------------------------------------------------
# arguments and instances: a NULL is refused naming it; a freed instance is refused
# ---------------------------------------------------------------------------------------------

from support import BACKENDS, ERROR, STEP, RawInstance  # noqa: E402


def _fn(inst, name, restype=None):
    """The FMU's function `name` as a fresh ctypes object (fmpy's argument types left alone)."""
    fn = inst.fmu.dll[name]
    if restype is not None:
        fn.restype = restype
    return fn


@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
def test_fmi2_null_arguments_are_refused_naming_the_argument(backend):
    """A NULL instanceName, value or vr array is refused with Error (NULL for instantiate) and a
    message naming the argument; instantiate without a logger (or without callbacks) returns
    NULL; fmi2DoStep on a NULL instance is Error, never a crash."""
    import ctypes
    from pathlib import Path as P

    inst = RawInstance(backend, 2)
    try:
        c = ctypes.c_void_p(inst.fmu.component)
        guid = inst.fmu.guid.encode()
        uri = P(inst.fmu.unzipDirectory, "resources").as_uri().encode()
        instantiate = _fn(inst, "fmi2Instantiate", ctypes.c_void_p)
        assert instantiate(None, 1, guid, uri, ctypes.byref(inst._cb), 0, 1) is None
        assert "fmi2Instantiate refused" in inst.last() and "instanceName" in inst.last(), inst.last()
        assert instantiate(b"no callbacks", 1, guid, uri, None, 0, 1) is None
        no_logger = type(inst._cb)()
        no_logger.allocateMemory, no_logger.freeMemory = inst._cb.allocateMemory, inst._cb.freeMemory
        assert instantiate(b"no logger", 1, guid, uri, ctypes.byref(no_logger), 0, 1) is None
        inst.reach(STEP)
        vr = (ctypes.c_uint32 * 1)(inst.vars["y"].valueReference)
        buf = (ctypes.c_double * 1)()
        for name in ("fmi2GetReal", "fmi2SetReal"):
            assert _fn(inst, name)(c, vr, ctypes.c_size_t(1), None) == ERROR
            assert f"{name} refused" in inst.last() and "value" in inst.last() and "NULL" in inst.last(), inst.last()
            assert _fn(inst, name)(c, None, ctypes.c_size_t(1), buf) == ERROR
            assert f"{name} refused" in inst.last() and "vr" in inst.last() and "NULL" in inst.last(), inst.last()
        assert _fn(inst, "fmi2DoStep")(None, ctypes.c_double(0.0), ctypes.c_double(1e-3), 1) == ERROR
        assert inst.do_step()[0] == 0, inst.last()  # the instance goes on
    finally:
        inst.close()


@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
def test_fmi3_null_arguments_and_counts_are_refused_naming_them(backend):
    """FMI 3.0: a NULL instanceName, values or valueReferences array is refused naming the
    argument; get/set with nValueReferences = 0 and nValues != 0 is refused naming both counts;
    fmi3DoStep on a NULL instance is Error."""
    import ctypes

    inst = RawInstance(backend, 3)
    try:
        c = ctypes.c_void_p(inst.fmu.component)
        from fmpy.fmi3 import fmi3LogMessageCallback

        log = fmi3LogMessageCallback(lambda env, status, cat, msg: inst.messages.append((status, msg.decode())))
        instantiate = _fn(inst, "fmi3InstantiateCoSimulation", ctypes.c_void_p)
        resources = (os.path.join(inst.fmu.unzipDirectory, "resources") + os.path.sep).encode()
        assert instantiate(None, inst.fmu.guid.encode(), resources, 0, 1, 0, 0, None, ctypes.c_size_t(0), None, log,
                           None) is None
        assert "fmi3InstantiateCoSimulation refused" in inst.last() and "instanceName" in inst.last(), inst.last()
        inst.reach(STEP)
        vr = (ctypes.c_uint32 * 1)(inst.vars["y"].valueReference)
        buf = (ctypes.c_double * 1)()
        one, zero = ctypes.c_size_t(1), ctypes.c_size_t(0)
        for name in ("fmi3GetFloat64", "fmi3SetFloat64"):
            assert _fn(inst, name)(c, vr, one, None, one) == ERROR
            assert f"{name} refused" in inst.last() and "values" in inst.last() and "NULL" in inst.last(), inst.last()
            assert _fn(inst, name)(c, None, one, buf, one) == ERROR
            assert f"{name} refused" in inst.last() and "valueReferences" in inst.last(), inst.last()
            assert _fn(inst, name)(c, vr, zero, buf, one) == ERROR
            assert f"{name} refused" in inst.last() and "nValueReferences = 0" in inst.last() and \
                "nValues = 1" in inst.last(), inst.last()
        flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
        assert _fn(inst, "fmi3DoStep")(None, ctypes.c_double(0.0), ctypes.c_double(1e-3), ctypes.c_bool(True),
                                       *[ctypes.byref(f) for f in flags]) == ERROR
        assert inst.do_step()[0] == 0, inst.last()
    finally:
        inst.close()


@pytest.mark.parametrize("fmu", ["PogoStick", "native/PogoStick", "fmi3/PogoStick", "native/fmi3/PogoStick"])
def test_a_freed_instance_is_refused_not_freed_again(fmu):
    """fmiNFreeInstance twice, then calls on the freed instance: the second free does nothing and
    the calls return Error (a live-instance check at every entry) instead of using freed memory.
    In a process of its own: a double free would abort it."""
    fmi = 3 if "fmi3" in fmu else 2
    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "_freed_instance.py"), str(DIST / f"{fmu}.fmu"),
                           str(fmi)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    statuses = json.loads(proc.stdout.strip().splitlines()[-1])
    assert statuses and set(statuses.values()) == {ERROR}, statuses


# ---------------------------------------------------------------------------------------------
# the resource location as importers pass it; the Python an FMU needs, named
# ---------------------------------------------------------------------------------------------

# folder names a file URI has to percent-encode; importers pass them raw too ("file://" + path)
AWKWARD_FOLDERS = ["50%ab", "a%20b", "x#y ö 100%"]


@pytest.mark.parametrize("folder", AWKWARD_FOLDERS)
def test_a_raw_resource_location_of_any_folder_name_is_accepted(tmp_path, folder):
    """The C host passes "file://" + the path unencoded: a folder whose name holds '%' followed by
    hex digits (not an escape there), '#', a space or non-ASCII loads — and "a%20b" is not taken
    for a folder "a b" (none exists here)."""
    target = tmp_path / folder
    with zipfile.ZipFile(DIST / "PogoStick.fmu") as z:
        z.extractall(target)
    proc = _c_host_run(tmp_path, target)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert len(proc.stdout.splitlines()) == 11


@pytest.mark.parametrize("folder", AWKWARD_FOLDERS)
def test_an_fmi3_resource_path_is_a_path_not_a_uri(folder, tmp_path):
    """FMI 3.0 passes resourcePath as a file system path: '%' in it is a plain character."""
    target = tmp_path / folder
    with zipfile.ZipFile(DIST / "fmi3" / "PogoStick.fmu") as z:
        z.extractall(target)
    inst = RawInstance("", 3, "cs", unzip_dir=str(target))
    try:
        inst.reach(STEP)
    finally:
        inst.close()


def test_a_wrong_resource_location_names_the_argument_and_what_was_tried(tmp_path):
    import ctypes

    target = tmp_path / "fmu"
    with zipfile.ZipFile(DIST / "PogoStick.fmu") as z:
        z.extractall(target)
    inst = RawInstance("", 2, unzip_dir=str(target))
    try:
        from fmpy.fmi2 import fmi2CallbackFunctions

        location = f"file://{tmp_path}/no%20such/resources".encode()
        fn = _fn(inst, "fmi2Instantiate", ctypes.c_void_p)
        fn.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p,
                       ctypes.POINTER(fmi2CallbackFunctions), ctypes.c_int, ctypes.c_int]
        assert fn(b"wrong", 1, inst.fmu.guid.encode(), location, ctypes.byref(inst._cb), 0, 0) is None
        text = inst.last().replace("%%", "%")  # (an FMI 2.0 log message is a printf format)
        assert f"fmuResourceLocation = '{location.decode()}'" in text, text
        assert f"{tmp_path}/no such/resources/pogofmu_launch.txt" in text, text  # decoded, as a URI
        assert f"{tmp_path}/no%20such/resources/pogofmu_launch.txt" in text, text  # as given
    finally:
        inst.close()


OLD_PYTHONS = sorted(str(p) for p in (Path.home() / ".pyenv/versions").glob("3.[89].*/bin/python3"))


# not routed through support.needs_mark: no registry of the project supplies CPython 3.8/3.9 (pyenv builds
# them from python.org's sources, out of reach here); this machine's image has them, so CI runs it
@pytest.mark.skipif(not OLD_PYTHONS, reason="no CPython 3.8 or 3.9 (pyenv) on this machine")
@pytest.mark.parametrize("python", OLD_PYTHONS[:2])
def test_a_host_running_an_older_cpython_is_told_the_fmu_needs_3_10(python, tmp_path):
    """A ctypes importer under CPython 3.8/3.9: the FMU's code would run in that interpreter (one
    per process), so the message names the host's own version as the reason and what to use
    instead — not a library to choose, which cannot help in a process that runs Python already."""
    target = tmp_path / "fmu"
    with zipfile.ZipFile(DIST / "PogoStick.fmu") as z:
        z.extractall(target)
    proc = subprocess.run([python, str(ROOT / "tests" / "_ctypes_host.py"), str(target), "PogoStick"],
                          capture_output=True, text=True, timeout=60, env={"PATH": "/usr/bin:/bin"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.splitlines()
    version = subprocess.run([python, "-c", "import platform; print(platform.python_version())"],
                             capture_output=True, text=True).stdout.strip()
    assert lines[0] == "NULL", proc.stdout
    text = "\n".join(lines[1:])
    assert f"this process runs CPython {version}" in text and "the host's own interpreter" in text, text
    assert "CPython 3.10 to 3.13" in text and "native" in text, text
    assert "POGOFMU_PYTHON_LIB" not in text, text


# ---------------------------------------------------------------------------------------------
# one call's work is bounded by a parameter: max_steps_per_call
# ---------------------------------------------------------------------------------------------

def _set_reals(inst, **values):
    import ctypes

    for name, value in values.items():
        vr = (ctypes.c_uint32 * 1)(inst.vars[name].valueReference)
        if inst.vars[name].type in ("Integer", "Int32"):  # (method)
            v = (ctypes.c_int32 * 1)(value)
            status = inst.raw("fmi2SetInteger", vr, 1, v) if inst.fmi == 2 else inst.raw("fmi3SetInt32", vr, 1, v, 1)
        else:
            v = (ctypes.c_double * 1)(value)
            status = inst.raw("fmi2SetReal", vr, 1, v) if inst.fmi == 2 else inst.raw("fmi3SetFloat64", vr, 1, v, 1)
        assert status == 0, inst.last()


def _bounded_call(backend, fmi, h, **settings):
    """Initialize with `settings`, take one step of `h` s; the status, the message, the step's CPU
    seconds (of this process, which runs the FMU: not the wall time, which a loaded machine stretches)."""
    import time

    inst = RawInstance(backend, fmi)
    try:
        _set_reals(inst, **settings)
        inst.enter_initialization()
        inst.exit_initialization()
        start = time.process_time()
        status, _ = inst.do_step(h)
        return status, inst.last(), time.process_time() - start, inst
    except BaseException:
        inst.close()
        raise


@pytest.mark.parametrize("fmi", [2, 3])
def test_a_step_needing_more_than_max_steps_per_call_is_refused_at_once(fmi):
    """step_size/max_step = 1e4 internal steps at least, max_steps_per_call = 1000: refused before
    any work, naming the parameter, its value and how to raise it; the instance goes on with a
    shorter step.  The same text from both backends."""
    texts = []
    for backend in BACKENDS:
        status, text, seconds, inst = _bounded_call(backend, fmi, 100.0, max_steps_per_call=1000.0)
        try:
            assert status == ERROR and seconds < 1.0, (status, text, seconds)
            assert "max_steps_per_call = 1000" in text and "raise the parameter max_steps_per_call" in text, text
            inst.t = 0.0  # the refused step moved nothing
            assert inst.do_step(1e-2)[0] == 0, inst.last()
        finally:
            inst.close()
        texts.append(text)
    assert texts[0] == texts[1], texts


@pytest.mark.parametrize("fmi", [2, 3])
def test_a_call_that_takes_more_than_max_steps_per_call_ends_naming_it(fmi):
    """max_step = 0 (unbounded: nothing to refuse beforehand) and a stiff leg (c = 3e4, ~1e4
    internal steps per second of contact, with the explicit method 5: the default method 0 would
    go implicit there) in one step of 2 s: the call stops after 2000 internal
    steps with Error naming max_steps_per_call, where it stopped and how to go on — identically on
    both backends (the engines count the same steps); with the parameter raised the same step
    completes."""
    texts = []
    for backend in BACKENDS:
        status, text, seconds, inst = _bounded_call(backend, fmi, 2.0, c=3e4, max_step=0.0, max_steps_per_call=2000.0,
                                                    method=5)
        try:
            assert status == ERROR, (status, text)
            assert "max_steps_per_call = 2000 internal steps taken in one call" in text, text
            assert "raise the parameter max_steps_per_call" in text and "shorter communication steps" in text, text
        finally:
            inst.close()
        texts.append(text)
        status, text, _, inst = _bounded_call(backend, fmi, 2.0, c=3e4, max_step=0.0, max_steps_per_call=1e6, method=5)
        inst.close()
        assert status == 0, text
    assert texts[0] == texts[1], texts


def test_max_steps_per_call_is_a_parameter_with_a_rule():
    from support import assert_parameter_rejected

    assert_parameter_rejected("PogoStick", {"max_steps_per_call": 0.5}, "max_steps_per_call",
                              "1 <= max_steps_per_call < inf")


@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
def test_fmi2_cancel_step_is_refused_naming_the_rule(backend):
    """FMI 2.0 §4.2.2: fmi2CancelStep only stops an asynchronous fmi2DoStep that returned fmi2Pending;
    these FMUs declare canRunAsynchronuously = false and never return it, so a call is Error naming
    the rule (the instance goes on)."""
    inst = RawInstance(backend, 2)
    try:
        inst.reach(STEP)
        assert inst.raw("fmi2CancelStep") == ERROR
        text = inst.last()
        assert "fmi2CancelStep refused" in text and "fmi2Pending" in text and "max_steps_per_call" in text, text
        assert inst.do_step()[0] == 0, inst.last()
    finally:
        inst.close()
