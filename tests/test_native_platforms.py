"""The native FMUs beyond the Linux binary: Windows under wine, and the source FMU.

* Windows: ``binaries/win64/<Model>.dll`` (FMI 2.0) and ``binaries/x86_64-windows/<Model>.dll``
  (FMI 3.0), cross-compiled by the build with mingw-w64, need nothing but Windows' own
  KERNEL32 and msvcrt and export the FMI functions only (and their C stepping loop for the
  sweeps, ``pogofmu_fmi2_run_grid`` / ``pogofmu_fmi3_run_grid``); the tests' C hosts
  (tests/c_host/fmi2_host.c, fmi3_host.c), cross-compiled as well, run every default experiment
  under wine — FMI 2.0 co-simulation, FMI 3.0 co-simulation with event mode and early return, and
  FMI 3.0 model exchange — with the Linux binary's events, their times within 1e-12 s, the outputs
  within 1e-12 relative at every communication point.
* Source FMU: ``sources/`` and ``modelDescription.xml`` alone — the binaries deleted — build with
  the system compiler and nothing else (no include path outside the FMU, an empty environment),
  and with fmpy's own source-FMU build (CMake; FMI 3.0 from ``sources/buildDescription.xml``); the
  libraries built give the shipped binary's outputs (to the bit on x86_64, where the compiler has
  no fused multiply-add to contract into).

The tests that need mingw-w64, wine or CMake are skipped, naming what is missing, without them;
``.ci/run`` installs the Debian packages, and under ``CI=true`` a missing one fails the test.
"""
import os
import platform
import shutil
import subprocess
import zipfile
from pathlib import Path

import pytest

from pogofmu import build
from support import compile_c_host, fmu_path, needs
from test_portability import BARE_ENV, C_HOST_SOURCE, outputs_of, run_c_host

FMUS = build.model_names()
MINGW = shutil.which(os.environ.get("POGOFMU_MINGW") or "x86_64-w64-mingw32-gcc")
WINE = next((w for w in (shutil.which("wine64"), "/usr/lib/wine/wine64", shutil.which("wine"))
             if w and os.access(w, os.X_OK)), None)
EXACT = platform.machine() in ("x86_64", "AMD64")  # no FMA in the baseline instruction set

needs_mingw = needs(MINGW is not None, "x86_64-w64-mingw32-gcc (Debian: gcc-mingw-w64-x86-64)")
needs_wine = needs(WINE is not None, "wine64 (Debian: wine64)")


def _description(path):
    from fmpy import read_model_description

    return read_model_description(str(path))


def _extract(name, folder, keep=lambda member: True, fmi=2):
    with zipfile.ZipFile(fmu_path(f"native/{'fmi3/' if fmi == 3 else ''}{name}")) as z:
        for member in z.namelist():
            if keep(member):
                z.extract(member, folder)
    return folder


def _experiment(md):
    return float(md.defaultExperiment.stopTime), float(md.defaultExperiment.stepSize)


@pytest.fixture(scope="module")
def linux_host(tmp_path_factory):
    return compile_c_host(C_HOST_SOURCE, tmp_path_factory.mktemp("linux_host") / "fmi2_host")


@pytest.fixture(scope="module")
def linux_runs(tmp_path_factory, linux_host):
    """Each native FMU's default experiment with its shipped Linux binary: (description, rows)."""
    cache = {}

    def get(name):
        if name not in cache:
            folder = _extract(name, tmp_path_factory.mktemp(f"linux_{name}"))
            md = _description(folder)
            rc, rows, err = run_c_host(linux_host, folder, name, *_experiment(md), outputs_of(name), md=md)
            assert rc == 0, err[-2000:]
            cache[name] = (md, rows)
        return cache[name]
    return get


def _assert_same_run(got, ref, name, exact):
    assert len(got) == len(ref), f"{name}: {len(got)} rows, expected {len(ref)}"
    for a, b in zip(got, ref):
        for key, want in b.items():
            have = a[key]
            if exact or isinstance(want, int):
                assert have == want, f"{name}.{key} at t = {b['time']}: {have!r} != {want!r}"
            else:
                assert abs(have - want) <= 1e-12 * max(1.0, abs(want)), f"{name}.{key} at t = {b['time']}"


# ---- Windows --------------------------------------------------------------------------------------

@needs_mingw
@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("name", FMUS)
def test_the_windows_binary_needs_only_windows_own_libraries(name, fmi, tmp_path):
    platform_dir = "win64" if fmi == 2 else "x86_64-windows"
    folder = _extract(name, tmp_path, lambda m: m.startswith(f"binaries/{platform_dir}/"), fmi=fmi)
    dll = folder / "binaries" / platform_dir / f"{name}.dll"
    assert dll.exists(), "mingw-w64 is installed, so the build must have built the Windows binary"
    objdump = shutil.which("x86_64-w64-mingw32-objdump") or "objdump"
    text = subprocess.run([objdump, "-p", str(dll)], capture_output=True, text=True, check=True).stdout
    imported = {line.split(":", 1)[1].strip() for line in text.splitlines() if "DLL Name:" in line}
    assert imported <= {"KERNEL32.dll", "msvcrt.dll"}, imported
    table = text[text.index("[Ordinal/Name Pointer] Table"):].splitlines()[1:]
    exported = [line.split("]", 1)[1].strip() for line in table if line.strip().startswith("[")]
    extensions = {f"pogofmu_fmi{fmi}_run_grid"}  # (the sweep's C loop, pogofmu.sweep)
    assert len(exported) >= 30 and all(e.startswith(f"fmi{fmi}") or e in extensions for e in exported), exported
    assert extensions <= set(exported)


def _cross_compile(source, exe):
    subprocess.run([MINGW, "-O1", "-Wall", "-D__USE_MINGW_ANSI_STDIO=1", f"-I{build.fmi_headers()}",
                    str(source), "-o", str(exe)], check=True)
    return exe


@pytest.fixture(scope="module")
def windows_host(tmp_path_factory):
    return _cross_compile(C_HOST_SOURCE, tmp_path_factory.mktemp("windows_host") / "fmi2_host.exe")


def _wine_env(tmp_path_factory):
    base = tmp_path_factory.getbasetemp()
    return dict(BARE_ENV, WINEPREFIX=str(base / "wineprefix"), WINEDEBUG="-all", HOME=str(base))


@needs_mingw
@needs_wine
@pytest.mark.parametrize("name", FMUS)
def test_under_wine_the_windows_binary_gives_the_linux_events(name, tmp_path_factory, windows_host, linux_runs):
    """The cross-compiled host loads the DLL with LoadLibrary in wine (its own prefix, in the test's
    temporary folder) and steps the default experiment."""
    md, ref = linux_runs(name)
    folder = _extract(name, tmp_path_factory.mktemp(f"win_{name}"))
    env = _wine_env(tmp_path_factory)
    rc, rows, err = run_c_host(Path("Z:" + str(windows_host)), Path("Z:" + str(folder)), name, *_experiment(md),
                               outputs_of(name), md=md, env=env, prefix=(WINE,), timeout=600)
    assert rc == 0, err[-2000:]
    _assert_same_run(rows, ref, name, exact=False)  # n_events, s, last_event equal; t_last_event within 1e-12 s


FMI3_HOST = C_HOST_SOURCE.parent / "fmi3_host.c"


def _fmi3_lines(exe, folder, name, md, events, step, env, prefix=()):
    """The FMI 3.0 C host's output: one line per event ("event,<t>,<flag>") and the end."""
    args = [*prefix, str(exe), str(folder), name, md.guid, repr(float(md.defaultExperiment.stopTime)), repr(step),
            str(events)]
    proc = subprocess.run(args, capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return [line.split(",") for line in proc.stdout.splitlines()]


@needs_mingw
@needs_wine
@pytest.mark.parametrize("events, step", [(1, 1e-3), (2, 1e-5)], ids=["cs-event-mode", "me-euler"])
@pytest.mark.parametrize("name", ["PogoStick", "PogoStickSMA", "Penetrator"])
def test_under_wine_the_fmi3_windows_binary_gives_the_linux_events(name, events, step, tmp_path_factory):
    """FMI 3.0 under wine: co-simulation with event mode and early return (each lastSuccessfulTime
    an event time), and model exchange integrated by the host's own Euler steps (each event met)."""
    base = tmp_path_factory.mktemp(f"fmi3_{name}_{events}")
    linux = compile_c_host(FMI3_HOST, base / "fmi3_host")
    windows = _cross_compile(FMI3_HOST, base / "fmi3_host.exe")
    folder = _extract(name, base / "fmu", fmi=3)
    md = _description(folder)
    ref = _fmi3_lines(linux, folder, name, md, events, step, BARE_ENV)
    got = _fmi3_lines(Path("Z:" + str(windows)), Path("Z:" + str(folder)), name, md, events, step,
                      _wine_env(tmp_path_factory), prefix=(WINE,))
    assert len(got) == len(ref) and sum(1 for r in ref if r[0] == "event") >= 5
    for a, b in zip(got, ref):
        assert a[0] == b[0] and a[2:] == b[2:]
        assert abs(float(a[1]) - float(b[1])) <= 1e-12 * max(1.0, abs(float(b[1]))), (a, b)


# ---- the source FMU -------------------------------------------------------------------------------

def _sources_only(name, folder, fmi=2):
    return _extract(name, folder, lambda m: m == "modelDescription.xml" or m.startswith("sources/"), fmi=fmi)


@pytest.mark.parametrize("name", FMUS)
def test_the_source_fmu_builds_with_the_system_compiler_from_its_own_files(name, tmp_path, linux_host, linux_runs):
    folder = _sources_only(name, tmp_path / "fmu")
    md = _description(folder)
    units = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    assert md.buildConfigurations[0].modelIdentifier == name and units
    out = folder / "binaries" / "linux64" / f"{name}.so"
    out.parent.mkdir(parents=True)
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    proc = subprocess.run([cc, "-shared", "-fPIC", "-O2", *units, "-o", str(out), "-lm"], cwd=folder / "sources",
                          capture_output=True, text=True, env=BARE_ENV)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rc, rows, err = run_c_host(linux_host, folder, name, *_experiment(md), outputs_of(name), md=md)
    assert rc == 0, err[-2000:]
    _assert_same_run(rows, linux_runs(name)[1], name, exact=EXACT)


@needs(shutil.which("cmake") is not None, "cmake (Debian: cmake; fmpy builds source FMUs with CMake)")
@pytest.mark.parametrize("fmi", [2, 3])
def test_fmpy_builds_the_source_fmu_and_simulates_it(tmp_path, fmi):
    """fmpy.build.build_platform_binary (CMake, fmpy's own FMI headers and flags) on the sources
    alone; simulate_fmu of the result gives the Python-hosted FMU's outputs."""
    from fmpy import simulate_fmu
    from fmpy.build import build_platform_binary

    name = "PogoStickSMA"
    folder = _sources_only(name, tmp_path / "fmu", fmi=fmi)
    (tmp_path / "build").mkdir()
    build_platform_binary(folder, build_dir=tmp_path / "build")
    assert (folder / "binaries" / ("linux64" if fmi == 2 else "x86_64-linux") / f"{name}.so").exists()
    stop, step = _experiment(_description(folder))
    got = simulate_fmu(str(folder), stop_time=stop, output_interval=step)
    ref = simulate_fmu(str(fmu_path(f"{'fmi3/' if fmi == 3 else ''}{name}")), stop_time=stop, output_interval=step)
    assert got["time"][-1] == ref["time"][-1] and got["n_events"][-1] == ref["n_events"][-1] > 10
    for column in ref.dtype.names:
        if EXACT:
            assert list(got[column]) == list(ref[column]), column
        else:
            assert max(abs(a - b) for a, b in zip(got[column], ref[column])) <= 1e-10, column
