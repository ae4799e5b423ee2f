"""Session setup: build every FMU into $POGOFMU_DIST (default dist/) once, from the current sources."""
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "fmu_src"))  # this checkout's code, whichever pogofmu the venv has installed


def pytest_configure(config):
    os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session", autouse=True)
def built_fmus():
    from pogofmu.build import Exporter, build_project, load_model_file
    from support import DIST, example_files

    built = build_project(DIST, ssp_dir=ROOT / "ssp", cache=ROOT / "build" / "native")
    # the example files, exported as any user's model is: the generic suites run on them too
    with Exporter(DIST / "examples", cache=ROOT / "build" / "native") as ex:
        for f in example_files():
            for source in load_model_file(f):
                built += ex.export(source)
    return built
