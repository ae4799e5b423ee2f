"""The FMUs as users meet them: a C importer with no Python in it, a plain fmpy script in
a virtual environment without the project, several FMUs in one process, and a clean teardown.

Every scenario runs in a fresh process, so nothing the test session imported can help an FMU.
"""
import json
import os
import shutil
import subprocess
import sys
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from pogofmu import exporter as build
from support import clean_venv as _clean_venv
from support import DIST, ROOT, compile_c_host, fmu_path, simulate

FMUS = build.model_names()
C_HOST_SOURCE = ROOT / "tests" / "c_host" / "fmi2_host.c"
CLEAN_SCRIPT = ROOT / "tests" / "_clean_venv_script.py"
TEARDOWN_PROCESSES = int(os.environ.get("POGOFMU_TEARDOWN_PROCESSES", "100"))  # per host
# a C host must bring nothing of the test's environment: only a PATH without any project venv
BARE_ENV = {"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8"}


def model_description(name):
    from fmpy import read_model_description

    return read_model_description(str(fmu_path(name)))


@pytest.fixture(scope="session")
def c_host(tmp_path_factory):
    return compile_c_host(C_HOST_SOURCE, tmp_path_factory.mktemp("c_host") / "fmi2_host")


@pytest.fixture(scope="session")
def unzipped(tmp_path_factory):
    cache = {}

    def get(name):
        if name not in cache:
            d = tmp_path_factory.mktemp(f"unzip_{name}")
            with zipfile.ZipFile(fmu_path(name)) as z:
                z.extractall(d)
            cache[name] = d
        return cache[name]

    return get


def run_c_host(c_host, unzipdir, name, stop, step, outputs, params=None, env=None, timeout=300, md=None,
               prefix=()):
    """Run the C host (under ``prefix``, e.g. wine); return (returncode, rows as dicts name -> value,
    stderr).  ``md``: the FMU's description (default: that of dist/<name>.fmu)."""
    md = md or model_description(name)
    by_name = {v.name: v for v in md.modelVariables}
    reals = [n for n in outputs if by_name[n].type == "Real"]
    ints = [n for n in outputs if by_name[n].type == "Integer"]
    args = [str(c_host), str(unzipdir), md.coSimulation.modelIdentifier, md.guid, repr(stop), repr(step),
            ",".join(str(by_name[n].valueReference) for n in reals) or "-",
            ",".join(str(by_name[n].valueReference) for n in ints) or "-"]
    args += [f"{by_name[k].valueReference}={v!r}" for k, v in (params or {}).items()]
    proc = subprocess.run([*prefix, *args], capture_output=True, text=True, env=env or BARE_ENV, timeout=timeout)
    rows = []
    for line in proc.stdout.splitlines():
        values = line.split(",")
        row = {"time": float(values[0])}
        row.update({n: float(v) for n, v in zip(reals, values[1:1 + len(reals)])})
        row.update({n: int(v) for n, v in zip(ints, values[1 + len(reals):])})
        rows.append(row)
    return proc.returncode, rows, proc.stderr


def outputs_of(name):
    return [v.name for v in model_description(name).modelVariables if v.causality == "output"]


# ---- the binary -------------------------------------------------------------------------------

@pytest.mark.parametrize("name", FMUS)
def test_binary_has_no_python_dependency(name, unzipped):
    """No libpython among the needed libraries and no undefined Py* symbol (pythonfmu's binary
    had 43): a plain dlopen(RTLD_NOW) in a C process resolves everything."""
    lib = unzipped(name) / "binaries" / "linux64" / f"{name}.so"
    needed = subprocess.run(["readelf", "-d", str(lib)], capture_output=True, text=True, check=True).stdout
    assert "libpython" not in needed
    undefined = subprocess.run(["nm", "-D", "--undefined-only", str(lib)], capture_output=True, text=True,
                               check=True).stdout.split()
    assert not [s for s in undefined if s.startswith(("Py", "_Py"))]
    with zipfile.ZipFile(fmu_path(name)) as z:
        names = z.namelist()
    # no pythonfmu Windows binary: it would need a Windows CPython no test can give it (Windows: the
    # native FMUs, tested under wine)
    assert [n for n in names if n.startswith("binaries/")] == [f"binaries/linux64/{name}.so"]


@pytest.mark.parametrize("name", FMUS)
def test_needs_no_execution_tool(name):
    md = model_description(name)
    assert md.coSimulation.needsExecutionTool is False


# ---- a C importer -----------------------------------------------------------------------------

@pytest.mark.parametrize("name", FMUS)
def test_c_host_runs_the_default_experiment_like_fmpy(name, c_host, unzipped):
    """The C host (no Python, empty environment) runs the default experiment; every output at
    every communication point equals fmpy's, bit for bit (same code, same arithmetic), so the
    event times (t_last_event) and counts are identical."""
    md = model_description(name)
    stop, step = float(md.defaultExperiment.stopTime), float(md.defaultExperiment.stepSize)
    outputs = outputs_of(name)
    rc, rows, err = run_c_host(c_host, unzipped(name), name, stop, step, outputs)
    assert rc == 0, err[-3000:]
    ref = simulate(name).res
    assert len(rows) == len(ref)
    for out in outputs:
        got = [r[out] for r in rows]
        assert got == list(ref[out]), f"{name}.{out} differs between the C host and fmpy"
    if "n_events" in outputs and name != "HopController":
        assert rows[-1]["n_events"] > 0


def _libpythons():
    """Shared CPython libraries on this machine, one per minor version >= 3.10."""
    found = {}
    patterns = ["/usr/lib/x86_64-linux-gnu/libpython3.*.so.1.0", "/usr/lib/libpython3.*.so.1.0",
                "/usr/local/lib/libpython3.*.so.1.0", str(Path.home() / ".pyenv/versions/*/lib/libpython3.*.so.1.0")]
    import glob

    for pattern in patterns:
        for lib in sorted(glob.glob(pattern)):
            minor = Path(lib).name.split(".")[1]  # libpython3.11.so.1.0 -> "11" (3.7m: "7m")
            if minor.isdigit() and int(minor) >= 10:
                minor = int(minor)
                found.setdefault(minor, lib)
    return [found[k] for k in sorted(found)]


@pytest.mark.parametrize("lib", _libpythons() or [None])
def test_c_host_with_each_cpython_gives_the_same_result(lib, c_host, unzipped):
    """One binary for CPython 3.10-3.13: each library on the machine, chosen with
    POGOFMU_PYTHON_LIB, gives outputs identical to fmpy's. A machine with no shared CPython
    library cannot run the Python-hosted FMUs in a C importer at all: that fails, not skips."""
    assert lib is not None, ("no shared CPython >= 3.10 library on this machine: the Python-hosted FMUs "
                             "need one in a C importer (a python3 built with --enable-shared, or libpython3.X)")
    outputs = ["y", "ydot", "n_events", "t_last_event"]
    rc, rows, err = run_c_host(c_host, unzipped("PogoStick"), "PogoStick", 3.0, 1e-2, outputs,
                               env=dict(BARE_ENV, POGOFMU_PYTHON_LIB=lib))
    assert rc == 0, err[-2000:]
    ref = simulate("PogoStick", stop_time=3.0, output_interval=1e-2).res
    for out in outputs:
        assert [r[out] for r in rows] == list(ref[out]), (lib, out)


def test_c_host_without_a_usable_python_is_told_what_was_tried(c_host, unzipped, tmp_path):
    """No interpreter: fmi2Instantiate returns NULL after a message naming what it looked for;
    the host goes on (exit code 3 is the host's 'instantiate returned NULL')."""
    missing = tmp_path / "libpython3.12.so.1.0"
    rc, rows, err = run_c_host(c_host, unzipped("PogoStick"), "PogoStick", 1.0, 0.1, ["y"],
                               env=dict(BARE_ENV, POGOFMU_PYTHON_LIB=str(missing)))
    assert rc == 3 and not rows, err
    assert "no usable CPython (>= 3.10)" in err and str(missing) in err and "POGOFMU_PYTHON_LIB" in err
    not_python = "libm.so.6"
    rc, _, err = run_c_host(c_host, unzipped("PogoStick"), "PogoStick", 1.0, 0.1, ["y"],
                            env=dict(BARE_ENV, POGOFMU_PYTHON_LIB=not_python))
    assert rc == 3 and "libm.so.6: lacks Py_IsInitialized" in err, err


FAKE_PYTHON = r"""/* a library that exports every symbol the launcher resolves, and says it is CPython 3.9 */
#include <stdarg.h>
#include <stddef.h>
#include <wchar.h>
#include "python_embed.h"
#define Py_GetVersion Py_GetVersion_unused /* defined below with its real signature */
#define FAKE(ret, name, args) void name(void) {}
PY_FUNCTIONS(FAKE)
#undef Py_GetVersion
#define FAKE_FLAG(name) int name;
PY_FLAGS(FAKE_FLAG)
int _Py_NoneStruct;
const char *Py_GetVersion(void) { return "3.9.18 (main, fake) [GCC]"; }
"""


def test_c_host_with_a_cpython_older_than_3_10_is_told_which_it_found(c_host, unzipped, tmp_path):
    """A CPython 3.9 (a stand-in compiled here: every symbol the launcher resolves, version
    3.9.18; and the real one too where pyenv has it): instantiation fails naming the library, its
    version and the need, before calling anything in it."""

    from pogofmu import exporter as build

    source = tmp_path / "fake_python.c"
    source.write_text(FAKE_PYTHON)
    fake = tmp_path / "libpython3.9.so.1.0"
    from pogofmu.codegen.build import c_compiler

    subprocess.run([*c_compiler(), "-shared", "-fPIC", f"-I{build.NATIVE / 'python'}", str(source), "-o", str(fake)],
                   check=True, capture_output=True)
    real = sorted((Path.home() / ".pyenv/versions").glob("3.9*/lib/libpython3.9.so.1.0"))
    for lib in [fake, *real[:1]]:
        rc, rows, err = run_c_host(c_host, unzipped("PogoStick"), "PogoStick", 1.0, 0.1, ["y"],
                                   env=dict(BARE_ENV, POGOFMU_PYTHON_LIB=str(lib)))
        assert rc == 3 and not rows, err
        assert f"{lib}: CPython 3.9" in err and "need >= 3.10" in err, err


def test_c_host_refuses_a_foreign_model_description(c_host, unzipped):
    """A GUID from another build: refused with a message, not run with the wrong variables."""
    args = [str(c_host), str(unzipped("PogoStick")), "PogoStick", "{00000000-0000-0000-0000-000000000000}",
            "1.0", "0.1", "-", "-"]
    proc = subprocess.run(args, capture_output=True, text=True, env=BARE_ENV, timeout=60)
    assert proc.returncode == 3 and "does not match this FMU's" in proc.stderr
    assert not proc.stdout


# ---- a plain fmpy script in a virtual environment without the project -------------------------

@pytest.fixture(scope="session")
def other_version_fmu(tmp_path_factory):
    """PogoStick.fmu built from a copy of the project whose version string differs."""
    copy = tmp_path_factory.mktemp("project_copy")
    shutil.copytree(ROOT / "fmu_src", copy / "fmu_src", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy2(ROOT / "build_fmu.py", copy / "build_fmu.py")
    init = copy / "fmu_src" / "pogofmu" / "runtime" / "__init__.py"
    text = init.read_text()
    version = text.split('__version__ = "')[1].split('"')[0]
    init.write_text(text.replace(f'__version__ = "{version}"', f'__version__ = "{version}+other"'))
    dest = copy / "dist"
    subprocess.run([sys.executable, str(copy / "build_fmu.py"), "--dest", str(dest), "PogoStick"], check=True,
                   capture_output=True, cwd=copy)
    return dest / "PogoStick.fmu", version


def test_plain_fmpy_venv_runs_every_fmu_in_one_process(other_version_fmu, tmp_path):
    """In a venv with only fmpy and numpy, one process: the five FMUs one after the other (and
    PogoStick again, after its first folder was deleted), then three at once stepped in turn, then
    PogoStick built from another version of the project next to the current one: every run
    reaches its stop time with the expected events, each FMU on its own bundled code."""
    python = _clean_venv()
    other, version = other_version_fmu
    expected = {}
    for name in FMUS:
        res = simulate(name).res
        expected[name] = {"stop": float(res["time"][-1]), "n_events": int(res["n_events"][-1]),
                          "t_last_event": float(res["t_last_event"][-1])}
    job = {"dist": str(DIST), "fmus": FMUS, "other": str(other), "out": str(tmp_path / "result.json")}
    proc = subprocess.run([str(python), str(CLEAN_SCRIPT), json.dumps(job)], capture_output=True, text=True,
                          timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-4000:]
    got = json.loads((tmp_path / "result.json").read_text())
    assert got["project_importable"] == [], got["project_importable"]
    for run in got["sequential"]:
        assert run["result"] == expected[run["name"]], run
    assert [r["name"] for r in got["sequential"]] == FMUS + ["PogoStick"]
    for name, result in got["simultaneous"].items():
        ref = simulate(name, stop_time=2.0, output_interval=1e-3).res
        assert result == {"n_events": int(ref["n_events"][-1]), "t_last_event": float(ref["t_last_event"][-1]),
                          "y": float(ref["y"][-1])}, name
    two = got["two_versions"]
    assert two["current"] == two["other"] == {"n_events": 19, "stop": 10.0}
    versions = two["packages"]
    assert len(versions) == 2 and sorted(versions.values()) == sorted([version, version + "+other"]), versions
    for package, folder in two["package_folders"].items():
        assert folder.endswith(f"/resources/{package}"), (package, folder)
        if versions[package] == version + "+other":  # extracted once: its code came from its own folder
            assert folder.startswith(two["unzipdirs"][1]), (package, folder)


# ---- teardown ---------------------------------------------------------------------------------

def _fmpy_process(job):
    code = ("import sys, json; from fmpy import simulate_fmu\n"
            "for path in json.loads(sys.argv[1]):\n"
            "    r = simulate_fmu(path, stop_time=0.5, output_interval=1e-2)\n"
            "    assert abs(r['time'][-1] - 0.5) < 1e-9\n"
            "try:\n"  # an instance that fails, freed afterwards (where a double release would show)
            "    simulate_fmu(json.loads(sys.argv[1])[0], stop_time=0.5, start_values={'m': -1.0})\n"
            "except Exception:\n"
            "    pass\n")
    return [sys.executable, "-c", code, json.dumps([str(fmu_path(n)) for n in FMUS])]


def _libcosim_process(job):
    payload = {"fmu": str(fmu_path("PogoStick")), "stop_time": 0.5, "step": 1e-2, "outputs": ["y"], "initial": {}}
    return [sys.executable, str(ROOT / "tests" / "_libcosim_runner.py"), json.dumps(payload)]


def test_one_hundred_processes_load_run_free_and_exit_cleanly(c_host, unzipped):
    """100 processes per host, two at a time — fmpy (all five FMUs, plus a failing instance freed afterwards),
    libcosimpy, the C host — each load, run and free FMUs and exit with status 0 (a binary that released a failed
    instance's Python slave twice corrupts the heap, which shows at process exit)."""
    assert TEARDOWN_PROCESSES >= 1, f"POGOFMU_TEARDOWN_PROCESSES = {TEARDOWN_PROCESSES}: nothing would be tested"
    d = unzipped("PogoStick")
    md = model_description("PogoStick")
    y = next(v.valueReference for v in md.modelVariables if v.name == "y")
    c_cmd = [str(c_host), str(d), "PogoStick", md.guid, "0.5", "0.01", str(y), "-"]
    kinds = [_fmpy_process, _libcosim_process, lambda job: c_cmd]

    def one(k):
        cmd = kinds[k % 3](k)
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300,
                              env=BARE_ENV if k % 3 == 2 else None)
        return k % 3, proc.returncode, proc.stderr[-1500:]

    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(one, range(3 * TEARDOWN_PROCESSES)))
    failed = [(("fmpy", "libcosimpy", "C host")[kind], rc, err) for kind, rc, err in results if rc != 0]
    assert not failed, failed[:3]
