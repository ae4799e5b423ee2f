"""Session setup: build every FMU into $POGOFMU_DIST (default dist/) once, from the current sources.

The FMUs run inside this process (pythonfmu's binary borrows the host interpreter). Native
libraries loaded that way (pythonfmu, libcosim, numpy's BLAS) have been seen to corrupt the heap
during interpreter teardown, rarely ("corrupted double-linked list" after every test passed):
the session therefore ends with ``os._exit`` once pytest has reported, keeping its exit status.
Set POGOFMU_SOFT_EXIT=1 to get a normal interpreter shutdown.
"""
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

_exit_status = None


def pytest_configure(config):
    os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_sessionfinish(session, exitstatus):
    global _exit_status
    _exit_status = int(exitstatus)


def pytest_unconfigure(config):
    if _exit_status is not None and not os.environ.get("POGOFMU_SOFT_EXIT"):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_exit_status)


@pytest.fixture(scope="session", autouse=True)
def built_fmus():
    import build_fmu
    from support import DIST

    return build_fmu.main(["--dest", str(DIST)])
