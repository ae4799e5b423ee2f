#!/usr/bin/env python3
"""The project's two commands (and a few more), runnable on a machine with nothing but Python.

    python3 tasks.py run     # build + validate every FMU, simulate default experiments -> results/
                             # (the native FMUs' -> results/native/), export examples/ -> dist/examples/
                             # (pogofmu export) and run them -> results/examples/,
                             # run the SpaceHopper SSP on the Moon
    python3 tasks.py test    # the test suite (what CI runs)
    python3 tasks.py build   # the venv and dist/ only (build_fmu.py), nothing run
    python3 tasks.py bench   # the benchmarks (benchmarks/)

``run`` forwards to the ``pogofmu`` command of the venv (``pogofmu run``, ``pogofmu ssp run``).

The first call creates ``.venv/`` beside this file and installs the project with its test
dependencies into it (again whenever pyproject.toml changes); every command then runs inside it.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
PY = VENV / ("Scripts/python.exe" if os.name == "nt" else "bin/python")
STAMP = VENV / ".pogofmu-installed"


def ensure_venv():
    want = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    if PY.exists() and STAMP.exists() and STAMP.read_text() == want:
        return
    if not PY.exists():
        print(f"creating virtual environment {VENV}", flush=True)
        venv.EnvBuilder(with_pip=True).create(VENV)
    print("installing pogofmu and its dependencies into .venv", flush=True)
    subprocess.check_call([str(PY), "-m", "pip", "install", "--quiet", "--upgrade", "pip"])
    subprocess.check_call([str(PY), "-m", "pip", "install", "--quiet", "-e", f"{ROOT}[test]"])
    # the wheels of fmpy and numpy at the installed versions, with their dependencies: the tests'
    # fmpy-only venv installs from them (--no-index), so no test reaches a package index
    pins = subprocess.check_output([str(PY), "-c", "import fmpy, numpy; print(f'fmpy=={fmpy.__version__} "
                                    "numpy=={numpy.__version__}')"], text=True).split()
    subprocess.check_call([str(PY), "-m", "pip", "download", "--quiet", "-d", str(VENV / "wheels"), *pins])
    STAMP.write_text(want)


def in_venv() -> bool:
    return Path(sys.prefix).resolve() == VENV.resolve()


def main(argv):
    if not argv or argv[0] not in ("run", "test", "bench", "build"):
        print(__doc__)
        return 2
    if not in_venv():
        ensure_venv()
        return subprocess.call([str(PY), str(ROOT / "tasks.py"), *argv], cwd=ROOT)
    cmd, rest = argv[0], argv[1:]
    os.environ.setdefault("MPLBACKEND", "Agg")
    if cmd == "build":
        return subprocess.call([sys.executable, str(ROOT / "build_fmu.py"), *rest], cwd=ROOT)
    if cmd == "run":
        rc = subprocess.call([sys.executable, str(ROOT / "build_fmu.py")], cwd=ROOT)
        if rc:
            return rc
        rc = subprocess.call([sys.executable, "-m", "pogofmu.cli", "run", *rest], cwd=ROOT)
        if rc:
            return rc
        if (ROOT / "dist" / "native").is_dir():  # the native FMUs (no Python inside): the same experiments
            rc = subprocess.call([sys.executable, "-m", "pogofmu.cli", "run", "--dist", str(ROOT / "dist" / "native"),
                                  "--out", str(ROOT / "results" / "native"), *rest], cwd=ROOT)
            if rc:
                return rc
        # the user's side: the model files of examples/, exported by `pogofmu export` as a user does,
        # and their default experiments
        examples = sorted(str(p) for p in (ROOT / "examples").glob("*/*.py"))
        if examples:
            rc = subprocess.call([sys.executable, "-m", "pogofmu.cli", "export", *examples,
                                  "--out", str(ROOT / "dist" / "examples")], cwd=ROOT)
            if rc:
                return rc
            rc = subprocess.call([sys.executable, "-m", "pogofmu.cli", "run", "--dist", str(ROOT / "dist" / "examples"),
                                  "--out", str(ROOT / "results" / "examples")], cwd=ROOT)
            if rc:
                return rc
        # the system-level example: the SpaceHopper on the Moon, run by the project's SSP master
        # (with the native FMUs where they were built: the same results, faster)
        native_ssp = ROOT / "dist" / "native" / "SpaceHopper.ssp"
        ssp = native_ssp if native_ssp.exists() else ROOT / "dist" / "SpaceHopper.ssp"
        for body in ("moon",):
            rc |= subprocess.call([sys.executable, "-m", "pogofmu.cli", "ssp", "run", str(ssp),
                                   "--parameters", body, "--stop-time", "30", "--step", "1e-3",
                                   "--out", str(ROOT / "results" / f"SpaceHopper-{body}")], cwd=ROOT)
        # the 1-ring segmented mirror phasing through a gust: pistons.png and piston_map.png
        rc |= subprocess.call([sys.executable, "-m", "pogofmu.studies.mirror", "demo", str(ROOT / "results" / "Mirror_R1")],
                              cwd=ROOT)
        return rc
    if cmd == "test":
        rc = subprocess.call([sys.executable, "-m", "pytest", *rest], cwd=ROOT)
        return 0 if rc == 5 and os.environ.get("POGOFMU_ALLOW_EMPTY") else rc
    if cmd == "bench":
        rc = subprocess.call([sys.executable, str(ROOT / "build_fmu.py")], cwd=ROOT)
        for script in sorted((ROOT / "benchmarks").glob("bench_*.py")):
            rc |= subprocess.call([sys.executable, str(script), *rest], cwd=ROOT)
        return rc
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
