"""The package as a user installs it: built into a wheel, installed into a folder of its own and
run from a folder outside the clone (issue 47 item 4). Every default path is the user's: ``pogofmu
run`` and the studies read ``dist/`` and write ``results/`` in the current folder, never in the
clone or beside the installed package; ``pogofmu mirror`` finds its model files in the package."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from support import DIST

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def installed(tmp_path_factory, project_wheel):
    """``(site, run)``: the wheel installed into ``site``; ``run(*args, cwd)`` runs ``python -m
    pogofmu.cli ARGS`` with it in a fresh process."""
    tmp = tmp_path_factory.mktemp("installed")
    wheel, site = project_wheel
    names = zipfile.ZipFile(wheel).namelist()
    assert "pogofmu/studies/segmented_mirror/reconstructor.py" in names, [n for n in names if "studies" in n]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "POGOFMU_DIST")}
    env.update(PYTHONPATH=str(site), POGOFMU_CACHE=str(tmp / "cache"), MPLBACKEND="Agg")

    def run(*args, cwd, timeout=900):
        return subprocess.run([sys.executable, "-m", "pogofmu.cli", *map(str, args)], cwd=cwd, env=env,
                              capture_output=True, text=True, timeout=timeout)
    probe = run("--version", cwd=tmp)
    assert probe.returncode == 0, probe.stderr
    where = subprocess.run([sys.executable, "-c", "import pogofmu; print(pogofmu.__file__)"], cwd=tmp, env=env,
                           capture_output=True, text=True)
    assert Path(where.stdout.strip()).is_relative_to(site), where  # the installed package, not the clone's
    return site, run


def _user_folder(tmp_path):
    folder = tmp_path / "user"
    folder.mkdir()
    assert not folder.resolve().is_relative_to(ROOT)
    return folder


def test_mirror_builds_from_the_installed_package(installed, tmp_path):
    site, run = installed
    folder = _user_folder(tmp_path)
    proc = run("mirror", "--rings", "1", "--backend", "native", "--out", "m.ssp", cwd=folder)
    assert proc.returncode == 0, proc.stderr[-3000:]
    names = zipfile.ZipFile(folder / "m.ssp").namelist()
    assert sum(n.endswith(".fmu") for n in names) == 3  # actuator, controller, reconstructor (one file each)
    check = run("ssp", "check", "m.ssp", cwd=folder)
    assert check.returncode == 0 and "is valid" in check.stdout, check.stderr
    assert sorted(p.name for p in folder.iterdir()) == ["m.ssp"]  # nothing else written


def test_run_reads_dist_and_writes_results_in_the_current_folder(installed, tmp_path):
    site, run = installed
    folder = _user_folder(tmp_path)
    (folder / "dist").mkdir()
    shutil.copy(DIST / "PogoStick.fmu", folder / "dist" / "PogoStick.fmu")
    clone_results = sorted((ROOT / "results").rglob("*")) if (ROOT / "results").exists() else []
    stamps = {p: p.stat().st_mtime_ns for p in clone_results}
    proc = run("run", "PogoStick", cwd=folder)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (folder / "results" / "PogoStick" / "timeseries.csv").is_file()
    assert not (site / "results").exists() and not (site / "pogofmu" / "results").exists()
    now = sorted((ROOT / "results").rglob("*")) if (ROOT / "results").exists() else []
    assert now == clone_results and all(p.stat().st_mtime_ns == stamps[p] for p in now)  # the clone untouched


def test_a_study_reads_and_writes_in_the_current_folder(installed, tmp_path):
    site, run = installed
    folder = _user_folder(tmp_path)
    (folder / "dist" / "native").mkdir(parents=True)
    shutil.copy(DIST / "native" / "SpaceHopper.ssp", folder / "dist" / "native" / "SpaceHopper.ssp")
    proc = run("study", "landing", "--samples", "2", "--stop-time", "1", "--workers", "1", "--no-progress",
               cwd=folder)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for name in ("landing.parquet", "landing.csv", "landing.png"):
        assert (folder / "results" / "landing" / name).is_file(), name
    missing = run("study", "soil", "--samples", "2", "--workers", "1", cwd=folder)
    assert missing.returncode == 2 and "dist/Penetrator.fmu" in missing.stderr, missing.stderr
