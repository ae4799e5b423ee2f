"""The master unpacks each FMU file of a package once and its components share that copy (one
binary loaded for all its instances, as FMI allows), unless the FMU says it can be instantiated
only once per process. Shared instances must stay independent: each of two instances from one
copy, stepped in turn with different parameters, gives the bits of its own run alone."""
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from support import DIST

from pogofmu.ssp.components import _unpacked


def _comps(fmu, md, n):
    return [SimpleNamespace(name=f"P{i}", source=f"resources/{fmu.name}", model_description=md,
                            model_description_path=fmu) for i in range(n)]


def test_components_of_one_fmu_file_share_one_unpacked_copy(tmp_path):
    fmu = DIST / "native" / "PogoStick.fmu"
    md = read_model_description(str(fmu))
    assert md.coSimulation.canBeInstantiatedOnlyOncePerProcess is False
    dirs = {_unpacked(c, tmp_path / "a", extract) for c in _comps(fmu, md, 3)}
    assert len(dirs) == 1 and [str(p) for p in (tmp_path / "a" / "fmus").iterdir()] == list(dirs)


def test_an_fmu_instantiable_once_per_process_gets_a_copy_per_component(tmp_path):
    fmu = DIST / "native" / "PogoStick.fmu"
    md = read_model_description(str(fmu))
    md.coSimulation.canBeInstantiatedOnlyOncePerProcess = True
    dirs = [_unpacked(c, tmp_path, extract) for c in _comps(fmu, md, 3)]
    assert len(set(dirs)) == 3 and all(Path(d).name == f"P{i}" for i, d in enumerate(dirs))


def _instance(unzipdir, md, name, k):
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=name)
    s.instantiate()
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s.setReal([vr["k"]], [k])
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    return s, [vr["xbar"], vr["xdot"]]


def _run(slaves, steps=400, h=1e-2):
    out = [[] for _ in slaves]
    for n in range(steps):
        for i, (s, vrs) in enumerate(slaves):  # in turn: one's step between two of the other's
            s.doStep(n * h, h)
            out[i].append(s.getReal(vrs))
    for s, _ in slaves:
        s.terminate()
        s.freeInstance()  # (fmpy's freeInstance also closes its reference to the library)
    return [np.array(o) for o in out]


@pytest.mark.parametrize("backend", ["native", "python"])
def test_two_instances_from_one_copy_are_independent(tmp_path, backend):
    fmu = DIST / "native" / "PogoStick.fmu" if backend == "native" else DIST / "PogoStick.fmu"
    md = read_model_description(str(fmu))
    shared = extract(str(fmu), unzipdir=str(tmp_path / "shared"))
    both = _run([_instance(shared, md, "a", 2.0e4), _instance(shared, md, "b", 3.5e4)])
    alone = [_run([_instance(extract(str(fmu), unzipdir=str(tmp_path / f"alone{i}")), md, "x", k)])[0]
             for i, k in enumerate((2.0e4, 3.5e4))]
    assert not np.array_equal(alone[0], alone[1])  # the two runs differ: a mix-up would show
    for got, ref in zip(both, alone):
        assert np.array_equal(got.view(np.int64), ref.view(np.int64))
