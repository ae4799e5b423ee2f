"""The ``pogofmu`` command line, in the conventions of the ecosystem: --help lists the commands,
--version, no argument is usage with exit status 2, each command's usage names itself, an
unknown name lists what there is, and no error is a traceback."""
import subprocess
import sys
from pathlib import Path

import pytest

from support import DIST

POGOFMU = Path(sys.executable).with_name("pogofmu")


def pogofmu(*args, timeout=120):
    return subprocess.run([str(POGOFMU), *map(str, args)], capture_output=True, text=True, timeout=timeout)


def test_help_lists_every_command_and_version_prints_the_version():
    import pogofmu as pkg

    proc = pogofmu("--help")
    assert proc.returncode == 0
    for cmd in ("run", "ssp", "sweep", "study"):
        assert f"\n  {cmd} " in proc.stdout, proc.stdout
    assert "``" not in proc.stdout  # not a docstring
    v = pogofmu("--version")
    assert v.returncode == 0 and v.stdout.strip() == f"pogofmu {pkg.__version__}"


def test_no_argument_is_usage_and_status_2():
    proc = pogofmu()
    assert proc.returncode == 2 and proc.stderr.startswith("usage: pogofmu") and proc.stdout == ""


@pytest.mark.parametrize("args,prog", [(("ssp", "run", "--help"), "usage: pogofmu ssp run"),
                                       (("ssp", "--help"), "usage: pogofmu ssp"),
                                       (("run", "--help"), "usage: pogofmu run"),
                                       (("sweep", "--help"), "usage: pogofmu sweep"),
                                       (("study", "coupling", "--help"), "usage: pogofmu study coupling")])
def test_each_command_usage_names_itself(args, prog):
    proc = pogofmu(*args)
    assert proc.returncode == 0 and proc.stdout.startswith(prog), proc.stdout[:200]


def test_unknown_names_list_what_there_is(tmp_path):
    proc = pogofmu("nosuch")
    assert proc.returncode == 2 and "the commands are export, run, ssp, sweep, study" in proc.stderr
    run = pogofmu("run", "--dist", DIST, "--out", tmp_path / "r", "NoSuchModel")
    assert run.returncode == 1 and "no FMU named NoSuchModel" in run.stderr
    for name in ("PogoStick", "HopController", "Penetrator"):
        assert name in run.stderr
    assert "Traceback" not in run.stderr and not (tmp_path / "r").exists()
    empty = pogofmu("run", "--dist", tmp_path, "--out", tmp_path / "r2")
    assert empty.returncode == 1 and "no FMU in" in empty.stderr and "Traceback" not in empty.stderr
