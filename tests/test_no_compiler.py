"""Nothing but Python (issue 44 item 4): on a PATH with no cc, gcc or clang, the ziglang package's
zig compiles what the host needs.  ``pogofmu export`` of a user model builds its four FMUs, a
Python-hosted and a native FMU run in fmpy, and the host-side engine and the SSP master's C level
are compiled and run; the results are checked against the bouncing ball's closed form."""
from __future__ import annotations

import importlib.util
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from support import require

ROOT = Path(__file__).resolve().parents[1]
BALL = ROOT / "examples" / "ball" / "ball.py"
G, E = 9.81, 0.8  # the example's gravity and restitution, h(0) = 1, v(0) = 0

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="the PATH without compilers is built for Linux")


def bare_path(folder: Path) -> str:
    """A bin folder with python and the few tools a shell needs, and no C compiler."""
    folder.mkdir()
    for tool in ("sh", "env", "uname", "readelf"):
        found = shutil.which(tool)
        if found:
            (folder / tool).symlink_to(found)
    for name in ("python", "python3"):
        (folder / name).symlink_to(sys.executable)
    return str(folder)


def ball_height(t: float) -> float:
    """h(t) of the ball up to its second bounce (closed form)."""
    t1 = math.sqrt(2.0 / G)
    if t <= t1:
        return 1.0 - G * t * t / 2
    v = E * G * t1
    return v * (t - t1) - G * (t - t1) ** 2 / 2


RUN = r'''
import json, shutil, sys
from pathlib import Path
from fmpy import simulate_fmu
from pogofmu.codegen.build import c_compiler, host_engine_library, host_level_library
from pogofmu.runtime.solver.cengine import Simulator
import importlib.util

out = {"which": [shutil.which(n) for n in ("cc", "gcc", "clang")], "compiler": c_compiler()}
out["engine"] = str(host_engine_library())
out["level"] = str(host_level_library())
spec = importlib.util.spec_from_file_location("ball", sys.argv[1])
mod = importlib.util.module_from_spec(spec)
spec.loader.exec_module(mod)
model = [v for v in vars(mod).values() if type(v).__name__ == "HybridModel"][0]
sim = Simulator(model, dict(rel_tol=1e-10), keep_history=True)
sim.advance(1.2)
out["events"] = [e.time for e in sim.events]
for kind, path in (("python", sys.argv[2]), ("native", sys.argv[3])):
    res = simulate_fmu(path, stop_time=1.0, output_interval=0.05, start_values={"rel_tol": 1e-10})
    out[kind] = [[float(t), float(h)] for t, h in zip(res["time"], res["h"])]
print(json.dumps(out))
'''


def test_export_and_run_without_a_c_compiler(tmp_path):
    require(importlib.util.find_spec("ziglang") is not None, "the ziglang package (PyPI, pyproject.toml)")
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "PATH")}
    env.update(PATH=bare_path(tmp_path / "bin"), POGOFMU_CACHE=str(tmp_path / "cache"),
               PYTHONPATH=str(ROOT / "fmu_src"))
    out = tmp_path / "fmus"
    proc = subprocess.run([sys.executable, "-m", "pogofmu.cli", "export", str(BALL), "--out", str(out)],
                          env=env, capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    fmus = [out / "Ball.fmu", out / "fmi3" / "Ball.fmu", out / "native" / "Ball.fmu", out / "native" / "fmi3" / "Ball.fmu"]
    assert all(f.is_file() for f in fmus), proc.stdout
    proc = subprocess.run([sys.executable, "-c", RUN, str(BALL), str(fmus[0]), str(fmus[2])], env=env,
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["which"] == [None, None, None]
    assert Path(got["compiler"][0]).name.startswith("zig"), got["compiler"]
    for lib in (got["engine"], got["level"]):
        assert Path(lib).parent == tmp_path / "cache"
    t1 = math.sqrt(2.0 / G)
    assert got["events"][:2] == pytest.approx([t1, t1 + 2 * E * G * t1 / G], abs=1e-9)
    for kind in ("python", "native"):
        for t, h in got[kind]:
            assert h == pytest.approx(ball_height(t), abs=1e-8), (kind, t)


INSTALLED = r'''
import json, sys
from pathlib import Path
import pogofmu
from pogofmu.codegen.build import host_engine_library, host_level_library
from pogofmu.exporter.python_fmu import compile_launcher
from pogofmu.ssp import native_level
from pogofmu.runtime.solver.cengine import Simulator
from pogofmu.runtime.models import get

sim = Simulator(get("PogoStick"), {}, keep_history=True)
sim.advance(0.5)
print(json.dumps({"package": pogofmu.__file__, "engine": str(host_engine_library()),
                  "level": str(host_level_library()), "level_loaded": native_level.library() is not None,
                  "launcher2": str(compile_launcher(2, Path(sys.argv[1]))),
                  "launcher3": str(compile_launcher(3, Path(sys.argv[1])))}))
'''


def test_the_wheel_carries_the_compiled_host_libraries(tmp_path, project_wheel):
    """``pip wheel`` compiles the engine, the SSP level library and the Python-hosted FMUs' two
    launchers into pogofmu/_lib; installed (no index, no dependencies: the project's venv supplies
    them), the package uses them on a machine with no C compiler and compiles nothing into its
    cache nor into the exporter's."""
    require(importlib.util.find_spec("ziglang") is not None, "the ziglang package (PyPI, pyproject.toml)")
    wheel, site = project_wheel
    import zipfile

    names = zipfile.ZipFile(wheel).namelist()
    libs = sorted("_".join(Path(n).name.split("_")[1:-1]) for n in names if n.startswith("pogofmu/_lib/"))
    assert libs == ["engine", "launcher_fmi2", "launcher_fmi3", "level"], names
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "PATH", "PYTHONPATH")}
    env.update(PATH=bare_path(tmp_path / "bin"), POGOFMU_CACHE=str(tmp_path / "cache"), PYTHONPATH=str(site))
    proc = subprocess.run([sys.executable, "-c", INSTALLED, str(tmp_path / "exporter-cache")], env=env,
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert Path(got["package"]).is_relative_to(site)
    for key in ("engine", "level", "launcher2", "launcher3"):
        assert Path(got[key]).parent == site / "pogofmu" / "_lib", got
    assert got["level_loaded"]
    assert not (tmp_path / "cache").exists() and not (tmp_path / "exporter-cache").exists()
