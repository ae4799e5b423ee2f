"""pogofmu.fmpy_raw, the one place that reads fmpy's private table of FMI functions: the installed
fmpy is in the range pyproject.toml pins and the module names, and the functions it hands out are
the FMU binary's own (the same symbol, the status returned).

References independent of the adapter: pyproject.toml, the binary's symbols through ctypes, and
fmpy's public wrappers.
"""
import ctypes
import re
import tomllib

import pytest
from fmpy import extract, instantiate_fmu, read_model_description

from pogofmu import fmpy_raw
from support import DIST, ROOT


def _pinned_range():
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    spec = [d for d in deps if re.match(r"fmpy\b", d)]
    assert len(spec) == 1, deps
    return spec[0][len("fmpy"):].replace(" ", "")


def test_the_installed_fmpy_is_in_the_range_pyproject_pins_and_the_adapter_names():
    import fmpy
    from packaging.specifiers import SpecifierSet

    assert _pinned_range() == fmpy_raw.FMPY_RANGE
    assert fmpy.__version__ in SpecifierSet(fmpy_raw.FMPY_RANGE), fmpy.__version__
    assert "0.4.0" not in SpecifierSet(fmpy_raw.FMPY_RANGE)  # the check above can fail


@pytest.fixture(params=["fmi2", "fmi3"])
def fmu(request, tmp_path):
    path = DIST / ("PogoStick.fmu" if request.param == "fmi2" else "fmi3/PogoStick.fmu")
    md = read_model_description(str(path))
    unzipped = extract(str(path), unzipdir=str(tmp_path / "fmu"))
    instance = instantiate_fmu(unzipped, md, "CoSimulation")
    yield request.param, md, instance
    instance.freeInstance()


def test_the_functions_are_the_binarys_own_and_return_the_status(fmu):
    fmi, md, instance = fmu
    getter = "fmi2GetReal" if fmi == "fmi2" else "fmi3GetFloat64"
    f = fmpy_raw.raw_function(instance, getter)
    address = ctypes.cast(getattr(instance.dll, getter), ctypes.c_void_p).value
    assert ctypes.cast(f, ctypes.c_void_p).value == address  # the same symbol of the same library
    if fmi == "fmi2":
        instance.setupExperiment(startTime=0.0)
    instance.enterInitializationMode()
    instance.exitInitializationMode()
    y = next(v for v in md.modelVariables if v.name == "y")
    vr = (ctypes.c_uint32 * 1)(y.valueReference)
    buf = (ctypes.c_double * 1)()
    args = (vr, 1, buf) if fmi == "fmi2" else (vr, 1, buf, 1)
    assert fmpy_raw.raw_call(instance, getter, *args) == 0
    public = instance.getReal([y.valueReference]) if fmi == "fmi2" else instance.getFloat64([y.valueReference])
    assert buf[0] == public[0] and buf[0] > 0


def test_a_missing_function_or_table_is_named():
    class NotAnFmpyFMU:
        component = None

    with pytest.raises(fmpy_raw.FmpyMismatch, match="no _functions table"):
        fmpy_raw.raw_function(NotAnFmpyFMU(), "fmi2DoStep")
    holder = NotAnFmpyFMU()
    holder._functions = {"fmi2DoStep": print}
    with pytest.raises(fmpy_raw.FmpyMismatch, match="no function 'fmi3DoStep'"):
        fmpy_raw.raw_function(holder, "fmi3DoStep")
