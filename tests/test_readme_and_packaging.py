"""What users read and install: the README's commands run in the
project's venv and say what fmpy really does with a refused step; pyproject.toml's license in the
form current setuptools takes without a deprecation banner; the C layer packaged without a warning."""
import importlib.metadata
import re
import subprocess
import sys
import tomllib

from support import DIST, ROOT

README = (ROOT / "README.md").read_text()
DOCS = {p.name: p.read_text() for p in (ROOT / "docs").glob("*.md")}

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
    """Not a quiet stop. A fresh fmpy process running the README's example
    gets FMICallException with the text the README quotes, and the README says fmi2Error."""
    proc = subprocess.run([sys.executable, "-c", BOTTOM_OUT], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    [line] = [ln for ln in proc.stdout.splitlines() if ln.startswith(("RAISED", "RETURNED"))]
    assert line == "RAISED fmi2DoStep failed with status 3 (error)."
    assert "fmi2DoStep failed with status 3 (error)" in README
    assert "fmi2DoStep failed with status 3 (error)" in DOCS["using-fmus.md"]
    assert not any("quietly: check" in text for text in [README, *DOCS.values()])  # the old, wrong comment
    fmus = DOCS["fmus.md"]
    mem = fmus[fmus.index("## PogoStickMem.fmu"):fmus.index("## PogoStickSMA.fmu")]
    assert "bottoms out at t ≈ 4.989 s and the step ends in fmi2Error" in mem
    errors = DOCS["errors.md"]
    assert "FMICallException" in errors and "fmi2Fatal, message" not in errors


def test_readme_runs_the_ssp_master_with_the_venv_or_the_console_command():
    """Every `python -m pogofmu.ssp` and `pogofmu` command the README and the docs give is the
    venv's (a bare system python has no pogofmu), but for the warning that says so."""
    text = README + "\n".join(DOCS.values())
    commands = [c.lstrip("`") for c in re.findall(r"(\S*python3?) -m pogofmu\.ssp", text)]
    assert len(commands) >= 2, commands
    bare = [c for c in commands if c != ".venv/bin/python"]
    assert bare == ["python3"] and "a bare\n`python3 -m pogofmu.ssp` ends in" in README, commands  # the warning
    assert "pogofmu ssp run" in README and "source .venv/bin/activate" in README
    # and the venv's Python does run it
    proc = subprocess.run([str(ROOT / ".venv" / "bin" / "python"), "-m", "pogofmu.ssp", "check",
                           str(DIST / "SpaceHopper.ssp")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "is valid" in proc.stdout, proc.stderr


def test_license_is_an_spdx_expression_with_a_setuptools_that_reads_it():
    """`license = "MIT"` (PEP 639), not the deprecated table, with setuptools
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


def test_every_folder_of_the_c_layer_is_a_listed_package_with_its_files():
    """setuptools warns (BuildBackendWarning, on every `pip install`) for a folder under a package
    that holds importable-looking files but is not in `packages`: each folder of fmu_src/native is
    listed, and its package data takes every C, header and Python file in it (what the exporter
    compiles from an installed wheel). Checked by hand as well: `pip wheel --no-deps .` prints no
    warning of the project's and the wheel holds the same files."""
    import fnmatch

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    native = ROOT / cfg["package-dir"]["pogofmu._native"]
    for folder in [native, *sorted(p for p in native.rglob("*") if p.is_dir() and p.name != "__pycache__")]:
        files = [f.name for f in folder.iterdir() if f.suffix in (".c", ".h", ".py")]
        if not files:
            continue
        package = ".".join(["pogofmu._native", *folder.relative_to(native).parts])
        assert package in cfg["packages"], package
        patterns = cfg["package-data"].get(package, [])
        assert all(any(fnmatch.fnmatch(f, pat) for pat in patterns) for f in files), (package, files, patterns)


def test_readme_is_an_entry_and_every_page_it_names_exists():
    """The README: at most 20 000 characters, the two commands, and a link to every docs page
    (each of which exists)."""
    assert len(README) <= 20_000, len(README)
    assert "python3 tasks.py run" in README and "python3 tasks.py test" in README
    linked = set(re.findall(r"\(docs/([a-z0-9-]+\.md)\)", README))
    assert linked == set(DOCS), (linked ^ set(DOCS))
    for name, page in DOCS.items():  # links between the pages resolve too
        for target in re.findall(r"\]\(([a-z0-9-]+\.md)\)", page):
            assert target in DOCS, (name, target)
