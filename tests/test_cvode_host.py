"""FMI 3.0 model exchange in an importer that integrates with SUNDIALS CVODE and, like fmusim,
re-initializes it after an event only when a state changed (tests/c_host/fmi3_cvode.c, an empty
environment): every FMU with states runs to its end with the events fmpy's model exchange finds.

An event that changes the mode but no state leaves CVODE running on; an indicator of the new mode
that started at exactly 0 made it stop ("Root found at and very near t"): the FMUs report an
unarmed indicator on the side before its crossing, never 0 (docs/fmi3.md).
"""
import shutil
import subprocess
import zipfile
from pathlib import Path

import pytest

from pogofmu import exporter as build
from support import fmu_path, parse_event_log, require, ROOT

WITH_STATES = [n for n in build.model_names() if build.slave_class(n).model.states]
HEADER = Path("/usr/include/cvode/cvode.h")


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    if not HEADER.exists():
        require(False, "SUNDIALS CVODE headers (Debian: libsundials-dev)")
    exe = tmp_path_factory.mktemp("cvode_host") / "fmi3_cvode"
    cc = shutil.which("cc") or shutil.which("gcc")
    subprocess.run([cc, "-O1", "-Wall", f"-I{build.fmi_headers()}", str(ROOT / "tests" / "c_host" / "fmi3_cvode.c"),
                    "-o", str(exe), "-ldl", "-lsundials_cvode", "-lsundials_nvecserial", "-lsundials_sunlinsoldense",
                    "-lsundials_sunmatrixdense"], check=True)
    return exe


def fmpy_events(path, stop):
    from fmpy import simulate_fmu

    messages = []
    simulate_fmu(str(path), fmi_type="ModelExchange", solver="CVode", relative_tolerance=1e-8, stop_time=stop,
                 output_interval=1e-3, start_values={"log_events": 1}, debug_logging=True,
                 logger=lambda *a: messages.append((a[-3], a[-2].decode(), a[-1].decode())))
    return [e["time"] for e in parse_event_log(messages)]


@pytest.mark.parametrize("backend", ["fmi3", "native/fmi3"])
@pytest.mark.parametrize("name", WITH_STATES)
def test_a_non_restarting_cvode_importer_runs_every_fmu_to_its_end(host, name, backend, tmp_path):
    if name == "Penetrator":
        # CVODE's BDF history from the flight does not serve the stiff soil after touchdown: without a
        # restart the corrector fails at t = 0.445 s (docs/known-issues.md); the importer's shortcut
        pytest.xfail("a non-restarting BDF fails in the soil after a touchdown that changed no state")
    path = fmu_path(f"{backend}/{name}")
    with zipfile.ZipFile(path) as z:
        z.extractall(tmp_path)
        token = z.read("modelDescription.xml").decode().split('instantiationToken="')[1].split('"')[0]
    stop = 10.0
    proc = subprocess.run([str(host), str(tmp_path), name, token, repr(stop), "1e-8"], capture_output=True,
                          text=True, env={}, timeout=300)
    assert proc.returncode == 0, proc.stderr[-1500:]
    lines = proc.stdout.splitlines()
    assert lines[-1] == "end,10", lines[-3:]
    got = [float(line.split(",")[1]) for line in lines if line.startswith("event,")]
    ref = fmpy_events(path, stop)
    assert len(got) == len(ref) > 5
    # (a BDF carried across a switch of the right-hand side without a restart loses accuracy: the
    # SMA's events 4.4e-4 s from fmpy's, which restarts at every event)
    assert max(abs(a - b) for a, b in zip(got, ref)) < 2e-3
