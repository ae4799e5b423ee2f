"""Concurrent first instantiation (docs/using-fmus.md, "Threads"): threads that instantiate the
same or different FMUs at once, from fmpy or from a pthreads C host without Python, all succeed —
one interpreter start per process, one import of a build's code however often it is instantiated,
from any thread — also while another thread of the process calls ``Py_GetVersion``.

References: what each FMU computes alone, one instance in this process through fmpy or the same
C host with that FMU alone; the module objects of a fresh process after its first instance. Each
scenario runs in fresh processes (tests/_threads_fmpy.py, tests/_version_race.py,
tests/_thousand_instances.py, tests/c_host/fmi2_threads.c and fmi3_threads.c), several times.
"""
import json
import subprocess
import sys
import zipfile

import pytest

from support import DIST, ROOT, Instance, compile_c_host

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
