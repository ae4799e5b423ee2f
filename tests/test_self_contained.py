"""The repository stands on its own: a clone with nothing beside it collects the whole suite,
and no tracked file reads anything outside the checkout (.ci/run runs the whole suite in such a
clone)."""
import re
import shutil
import subprocess
import sys

import pytest

from support import ROOT

OUTSIDE = re.compile(r"\.\./shared|/work/shared|parent\s*/\s*[\"']shared[\"']|parents\[\d\]\s*/\s*[\"']shared[\"']")


def _tracked_files():
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return [ROOT / line for line in out.splitlines() if line]


@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.fail("the self-containment test needs git and a git checkout")
    dest = tmp_path_factory.mktemp("alone") / "pogofmu"
    subprocess.run(["git", "clone", "--quiet", str(ROOT), str(dest)], check=True)
    assert not (dest.parent / "shared").exists()
    return dest


def test_no_tracked_file_reads_a_path_outside_the_checkout():
    offenders = []
    for path in _tracked_files():
        if path.suffix in (".py", ".sh", ".toml", ".cfg", ".ini", ".c", ".h") or path.name == "run":
            text = path.read_text(errors="replace")
            if OUTSIDE.search(text) and path.name != "test_self_contained.py":
                offenders.append(str(path.relative_to(ROOT)))
    assert not offenders, offenders


def test_a_clone_with_nothing_beside_it_collects_every_test(clone):
    proc = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider"],
                          cwd=clone, capture_output=True, text=True, timeout=600,
                          env={"PATH": "/usr/bin:/bin", "HOME": str(clone.parent)})
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    count = re.search(r"(\d+) tests? collected", proc.stdout)
    assert count and int(count.group(1)) > 300, proc.stdout[-2000:]
    assert "FileNotFoundError" not in proc.stdout + proc.stderr
