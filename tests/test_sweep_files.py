"""What ``pogofmu sweep`` writes, and what it refuses before any worker starts: it writes only a
regular file it created or was told to overwrite (``--overwrite``); it never replaces a device, a
pipe, a folder or a symbolic link, and an existing table without ``--overwrite`` is left byte for
byte. Each bad input (an option's value, an output that cannot be written, a file that is not an
FMU, a number that is not finite) is one line ``error: ...`` naming it, exit status 1 or 2, no
traceback and no output file.

References: the file system itself (the kind, inode and device of what was there before, the
bytes of a table left alone) and the sweep's own table read back with pyarrow.
"""
import os
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from support import fmu_path

POGOFMU = Path(sys.executable).with_name("pogofmu")


def sweep(*args, timeout=300):
    return subprocess.run([str(POGOFMU), "sweep", *map(str, args), "--no-progress"], capture_output=True, text=True,
                          timeout=timeout)


def test_overwrite_never_replaces_a_device_a_pipe_a_folder_or_a_link(tmp_path):
    fifo = tmp_path / "pipe.parquet"
    os.mkfifo(fifo)
    link = tmp_path / "null.parquet"
    link.symlink_to("/dev/null")
    folder = tmp_path / "folder.parquet"
    folder.mkdir()
    (folder / "keep").write_text("mine")
    null_before = os.stat("/dev/null")
    for out, kind in ((fifo, "not a regular file"), (link, "a symbolic link"), (folder, "a folder")):
        proc = sweep(fmu_path("PogoStick"), "--grid", "k=90,100", "--stop-time", "0.1", "--overwrite", "--out", out)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.count("\n") == 1 and kind in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and os.readlink(link) == "/dev/null"
    assert (folder / "keep").read_text() == "mine"
    now = os.stat("/dev/null")
    assert stat.S_ISCHR(now.st_mode) and (now.st_ino, now.st_rdev) == (null_before.st_ino, null_before.st_rdev)


def test_an_existing_output_is_replaced_only_with_overwrite(tmp_path):
    """Without --overwrite an existing table is refused (one line, exit 2) and left byte for byte;
    with --overwrite the sweep replaces it by its own table."""
    import pyarrow.parquet as pq

    out = tmp_path / "table.parquet"
    out.write_bytes(b"a table from yesterday")
    proc = sweep(fmu_path("PogoStick"), "--grid", "k=90,100", "--stop-time", "0.1", "--workers", "1", "--out", out)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "exists: give --resume or --overwrite" in proc.stderr and str(out) in proc.stderr, proc.stderr
    assert out.read_bytes() == b"a table from yesterday"
    proc = sweep(fmu_path("PogoStick"), "--grid", "k=90,100", "--stop-time", "0.1", "--workers", "1", "--overwrite",
                 "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert sorted(r["k"] for r in pq.read_table(out).to_pylist()) == [90.0, 100.0]


def _not_an_fmu(tmp_path):
    bad = tmp_path / "notzip.fmu"
    bad.write_text("not a zip")
    nomd = tmp_path / "nomd.fmu"
    with zipfile.ZipFile(nomd, "w") as z:
        z.writestr("other.txt", "x")
    broken = tmp_path / "broken.fmu"
    with zipfile.ZipFile(broken, "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription")
    return bad, nomd, broken


@pytest.mark.parametrize("case", ["seed -1", "out in /proc", "out a folder", "not a zip", "zip without md",
                                  "broken md", "scheduler ::::", "workers 0", "outputs empty", "set and grid",
                                  "grid nan inf", "grid 1e400", "set inf"])
def test_each_bad_sweep_input_is_one_line_before_any_worker(case, tmp_path):
    fmu = fmu_path("PogoStick")
    bad, nomd, broken = _not_an_fmu(tmp_path)
    out = tmp_path / "r.parquet"
    args, words = {
        "seed -1": ([fmu, "--sample", "k=uniform(80,120)", "--samples", 2, "--seed", -1, "--out", out], "--seed -1"),
        "out in /proc": ([fmu, "--grid", "k=90,100", "--out", "/proc/x.parquet"], "cannot be written"),
        "out a folder": ([fmu, "--grid", "k=90,100", "--out", tmp_path], "a folder"),
        "not a zip": ([bad, "--grid", "k=90,100", "--out", out], "not an FMU (not a zip archive)"),
        "zip without md": ([nomd, "--grid", "k=90,100", "--out", out], "without modelDescription.xml"),
        "broken md": ([broken, "--grid", "k=90,100", "--out", out], "modelDescription.xml cannot be read"),
        "scheduler ::::": ([fmu, "--grid", "k=90,100", "--scheduler", "::::", "--out", out], "--scheduler '::::'"),
        "workers 0": ([fmu, "--grid", "k=90,100", "--workers", 0, "--out", out], "--workers 0: must be >= 1"),
        "outputs empty": ([fmu, "--grid", "k=90,100", "--outputs=", "--out", out], "--outputs '': names no output"),
        "set and grid": ([fmu, "--grid", "k=90,100", "--set", "k=1", "--out", out], "both swept"),
        "grid nan inf": ([fmu, "--grid", "k=nan,inf", "--out", out], "'nan' is not a finite number"),
        "grid 1e400": ([fmu, "--grid", "k=1e400", "--out", out], "'1e400' is not a finite number"),
        "set inf": ([fmu, "--grid", "k=90,100", "--set", "c=inf", "--out", out], "'inf' is not a finite number"),
    }[case]
    proc = sweep(*args, timeout=120)
    assert proc.returncode in (1, 2), proc.stderr
    assert proc.stderr.startswith("error: ") and proc.stderr.count("\n") == 1, proc.stderr
    assert words in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert not out.exists() and not Path(str(out) + ".parts").exists()
