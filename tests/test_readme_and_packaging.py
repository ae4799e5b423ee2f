"""What users read and install: the README's commands run in the
project's venv and say what fmpy really does with a refused step; pyproject.toml's license in the
form current setuptools takes without a deprecation banner; the C layer packaged file for file, and
an editable install without a warning."""
import importlib.metadata
import importlib.util
import re
import subprocess
import sys
import tomllib

from support import DIST, ROOT, require

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


def _c_layer_files():
    """The C layer as an installed package carries it: every file of fmu_src/native (its C files and
    headers, the Python-hosted FMUs' boot module, the vendored FMI headers' README)."""
    native = ROOT / "fmu_src" / "native"
    files = [f for f in native.rglob("*") if f.is_file() and "__pycache__" not in f.parts and f.suffix != ".pyc"]
    return native, sorted(f.relative_to(native).as_posix() for f in files)


def _native_in_wheel(names):
    prefix = "pogofmu/_native/"
    return sorted(n[len(prefix):] for n in names if n.startswith(prefix))


def test_the_wheel_carries_the_c_layer_file_for_file(project_wheel):
    """setup.py copies fmu_src/native into the package as pogofmu/_native (the exporter compiles an
    installed package's FMUs from it): the wheel holds every file of it, and nothing else there."""
    import zipfile

    wheel, site = project_wheel
    native, files = _c_layer_files()
    assert _native_in_wheel(zipfile.ZipFile(wheel).namelist()) == files
    assert (site / "pogofmu" / "_native" / "pg_backend.h").read_bytes() == (native / "pg_backend.h").read_bytes()


def test_a_wheel_built_from_the_source_distribution_carries_the_c_layer(tmp_path):
    """What a package index gets: ``python -m build`` makes the sdist and builds the wheel from it
    (not from the checkout). MANIFEST.in carries the C layer and the mirror's model files into the
    sdist, so that wheel holds them as the checkout's does (setup.py refuses to build without them)."""
    import shutil
    import tarfile
    import zipfile

    require(importlib.util.find_spec("build") is not None, "the build package (the test extra)")
    # a copy of the checkout without what earlier builds left (setuptools puts every file an old
    # egg-info's SOURCES.txt lists into the sdist, whatever MANIFEST.in says)
    tree = tmp_path / "tree"
    shutil.copytree(ROOT, tree, ignore=shutil.ignore_patterns(".venv", ".git", "dist", "build", "results",
                                                               "*.egg-info", "__pycache__", ".pytest_cache"))
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "build", "-o", str(out), str(tree)],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    (sdist,) = out.glob("pogofmu-*.tar.gz")
    (wheel,) = out.glob("pogofmu-*.whl")
    native, files = _c_layer_files()
    top = sdist.name[:-len(".tar.gz")]
    with tarfile.open(sdist) as tar:
        members = set(tar.getnames())
    assert {f"{top}/fmu_src/native/{f}" for f in files} <= members
    names = zipfile.ZipFile(wheel).namelist()
    assert _native_in_wheel(names) == files
    mirror = sorted(f.name for f in (ROOT / "examples" / "segmented_mirror").glob("*.py"))
    assert sorted(n.rsplit("/", 1)[1] for n in names if n.startswith("pogofmu/studies/segmented_mirror/")) == mirror


def test_pip_install_editable_prints_no_warning_of_the_project(tmp_path):
    """`pip install -e` (what python3 tasks.py does) prints no setuptools warning: with a second
    package-dir mapping (the C layer as pogofmu._native) setuptools installed a meta path finder and
    printed "BuildBackendWarning: Editable installation" at every install. The install here goes to a
    prefix of its own (no dependencies) and leaves the running venv's install as it was."""
    # --ignore-installed: without it pip uninstalls the running venv's own pogofmu first
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "-e", str(ROOT),
                           "--prefix", str(tmp_path / "prefix"), "--ignore-installed"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    # (pip's own notes about this machine's index configuration are not the project's)
    ours = [line for line in (proc.stdout + proc.stderr).splitlines()
            if "warning" in line.lower() and "WARNING: Location" not in line]
    assert not ours, ours
    (pth,) = (tmp_path / "prefix").rglob("__editable__.pogofmu-*.pth")
    assert pth.read_text().split() == [str(ROOT / "fmu_src")]
    assert importlib.metadata.distribution("pogofmu") is not None  # (still installed here)


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
