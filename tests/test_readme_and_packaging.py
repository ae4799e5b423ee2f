"""What users read and install (issue 9 items 11 and 13): the README's commands run in the
project's venv and say what fmpy really does with a refused step; pyproject.toml's license in the
form current setuptools takes without a deprecation banner."""
import importlib.metadata
import re
import subprocess
import sys
import tomllib

from support import DIST, ROOT

README = (ROOT / "README.md").read_text()

BOTTOM_OUT = f"""
from fmpy import simulate_fmu
from fmpy.fmi1 import FMICallException
try:
    simulate_fmu({str(DIST / "PogoStickMem.fmu")!r}, stop_time=10, start_values={{"spring_law": 1, "beta": 5.0}})
except FMICallException as exc:
    print("RAISED", exc)
else:
    print("RETURNED")
"""


def test_readme_says_how_fmpy_reports_a_bottomed_out_leg():
    """Issue 9 item 11: not a quiet stop. A fresh fmpy process running the README's example
    gets FMICallException with the text the README quotes, and the README says fmi2Error."""
    proc = subprocess.run([sys.executable, "-c", BOTTOM_OUT], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    [line] = [ln for ln in proc.stdout.splitlines() if ln.startswith(("RAISED", "RETURNED"))]
    assert line == "RAISED fmi2DoStep failed with status 3 (error)."
    assert "fmi2DoStep failed with status 3 (error)" in README
    assert "quietly: check" not in README  # the old, wrong comment of the example
    mem = README[README.index("### PogoStickMem.fmu"):README.index("### PogoStickSMA.fmu")]
    assert "bottoms out at t ≈ 4.989 s and the step ends in fmi2Error" in mem
    errors = README[README.index("## Errors"):README.index("## Performance")]
    assert "FMICallException" in errors and "fmi2Fatal, message" not in errors


def test_readme_runs_the_ssp_master_with_the_venv_or_the_console_command():
    """Issue 9 item 11: every `python -m pogofmu.ssp` command the README gives is the venv's
    Python (a bare system python has no pogofmu), and the console command is named too."""
    commands = [c.lstrip("`") for c in re.findall(r"(\S*python3?) -m pogofmu\.ssp", README)]
    assert len(commands) >= 4, commands
    bare = [c for c in commands if c != ".venv/bin/python"]
    assert bare == ["python3"] and "a bare `python3 -m pogofmu.ssp` ends in" in README, commands  # the warning
    assert "pogofmu ssp run" in README and "source .venv/bin/activate" in README
    # and the venv's Python does run it
    proc = subprocess.run([str(ROOT / ".venv" / "bin" / "python"), "-m", "pogofmu.ssp", "check",
                           str(DIST / "SpaceHopper.ssp")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "is valid" in proc.stdout, proc.stderr


def test_license_is_an_spdx_expression_with_a_setuptools_that_reads_it():
    """Issue 9 item 13: `license = "MIT"` (PEP 639), not the deprecated table, with setuptools
    >= 77 required to build (older ones reject the string form), and the installed metadata
    carries it as License-Expression (what setuptools >= 77 writes for the string form)."""
    from packaging.licenses import canonicalize_license_expression
    from packaging.requirements import Requirement

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    lic = cfg["project"]["license"]
    assert isinstance(lic, str) and canonicalize_license_expression(lic) == lic == "MIT"
    [st] = [Requirement(r) for r in cfg["build-system"]["requires"] if Requirement(r).name == "setuptools"]
    assert st.specifier.contains("77.0") and not st.specifier.contains("76.1"), st
    md = importlib.metadata.metadata("pogofmu")
    assert md["License-Expression"] == "MIT" and md.get("License") is None
