"""Session setup: build every FMU into $POGOFMU_DIST (default dist/) once, from the current sources, for
the tests that use them (every module not marked ``own_fmus``)."""
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "fmu_src"))  # this checkout's code, whichever pogofmu the venv has installed


def pytest_configure(config):
    os.environ.setdefault("MPLBACKEND", "Agg")
    config.addinivalue_line("markers", "needs(available, what): a prerequisite a registry supplies (support.needs_mark)")
    config.addinivalue_line("markers", "own_fmus: the module exports the FMUs it needs itself (or needs none): "
                                       "the session's build of every project FMU is not run for it")


def pytest_runtest_setup(item):
    """The ``needs`` marks (support.needs_mark): a missing prerequisite that a registry supplies is
    skipped on a developer's machine and fails under CI=true."""
    from support import require

    for mark in item.iter_markers("needs"):
        require(*mark.args)


def pytest_collection_modifyitems(config, items):
    """Every test uses the session's build of the project's FMUs unless its module is marked
    ``own_fmus``: a run of such modules alone does not pay for the full build."""
    for item in items:
        if item.get_closest_marker("own_fmus") is None and "built_fmus" not in item.fixturenames:
            item.fixturenames.insert(0, "built_fmus")


@pytest.fixture(autouse=True)
def _cwd_kept(request):
    """The process's working folder, as it was before the test: restored after it, with a warning
    naming the test that changed it. fmpy's library loading changes the working folder and does
    not change it back when the load fails (fmpy/fmi1.py), and a later test's relative paths (a
    command's default ``dist/``) would then point elsewhere."""
    import warnings

    before = os.getcwd()
    yield
    try:
        after = os.getcwd()
    except OSError:  # (a folder since deleted)
        after = None
    if after != before:
        os.chdir(before)
        warnings.warn(f"{request.node.nodeid} left the working folder at {after} (restored to {before})")


@pytest.fixture(scope="session")
def built_fmus():
    from pogofmu.exporter import Exporter, build_project, load_model_file
    from support import DIST, example_files

    built = build_project(DIST, ssp_dir=ROOT / "ssp", cache=ROOT / "build" / "native")
    # the example files, exported as any user's model is: the generic suites run on them too
    with Exporter(DIST / "examples", cache=ROOT / "build" / "native") as ex:
        for f in example_files():
            for source in load_model_file(f):
                built += ex.export(source)
    return built


@pytest.fixture(scope="session")
def gate_fmu(tmp_path_factory):
    """tests/_sweep_gate.py built with pythonfmu, once: runs with k >= hold wait for a gate file
    (the sweep tests that interrupt a sweep at a point they control)."""
    from pythonfmu.builder import FmuBuilder

    dest = tmp_path_factory.mktemp("gate")
    return Path(FmuBuilder.build_FMU(Path(__file__).with_name("_sweep_gate.py"), dest=dest))


@pytest.fixture(scope="session")
def project_wheel(tmp_path_factory):
    """``(wheel, site)``: this checkout built by ``pip wheel`` (no dependencies) and installed
    into the folder ``site`` (``pip install --target``, no index), once a session."""
    import subprocess

    tmp = tmp_path_factory.mktemp("wheel")
    wheels = tmp / "wheels"
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(ROOT)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (wheel,) = wheels.glob("pogofmu-*.whl")
    site = tmp / "site"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-index", "--target",
                           str(site), str(wheel)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return wheel, site
