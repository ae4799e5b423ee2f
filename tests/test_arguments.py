"""The FMI functions' arguments and instances: a NULL argument (instanceName, a value or value
reference array, the instance itself) is refused with Error — NULL for an instantiation — and a
message naming the argument; counts that do not match (nValueReferences and nValues in FMI 3.0,
nContinuousStates and nEventIndicators in model exchange) are refused naming them and the FMU's
nx and nz; a freed instance is refused, never freed again. Both backends; the instance goes on
after every refusal.

References: FMI 2.0 and FMI 3.0 (the arguments each function takes and the counts the model
description declares), and a process of its own for the freed instance (tests/_freed_instance.py:
a double free would abort it).
"""
import json
import os
import subprocess
import sys

import pytest

from pogofmu.fmpy_raw import raw_call as _raw  # the FMU's own function, its status returned
from support import BACKENDS, DIST, ERROR, ROOT, STEP, RawInstance
from support import fmi3_fmpy_instance as _fmi3_raw
from support import fmi_function as _fn


@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
def test_fmi2_null_arguments_are_refused_naming_the_argument(backend):
    """A NULL instanceName, value or vr array is refused with Error (NULL for instantiate) and a
    message naming the argument; instantiate without a logger (or without callbacks) returns
    NULL; fmi2DoStep on a NULL instance is Error, never a crash."""
    import ctypes
    from pathlib import Path as P

    inst = RawInstance(backend, 2)
    try:
        c = ctypes.c_void_p(inst.fmu.component)
        guid = inst.fmu.guid.encode()
        uri = P(inst.fmu.unzipDirectory, "resources").as_uri().encode()
        instantiate = _fn(inst, "fmi2Instantiate", ctypes.c_void_p)
        assert instantiate(None, 1, guid, uri, ctypes.byref(inst._cb), 0, 1) is None
        assert "fmi2Instantiate refused" in inst.last() and "instanceName" in inst.last(), inst.last()
        assert instantiate(b"no callbacks", 1, guid, uri, None, 0, 1) is None
        no_logger = type(inst._cb)()
        no_logger.allocateMemory, no_logger.freeMemory = inst._cb.allocateMemory, inst._cb.freeMemory
        assert instantiate(b"no logger", 1, guid, uri, ctypes.byref(no_logger), 0, 1) is None
        inst.reach(STEP)
        vr = (ctypes.c_uint32 * 1)(inst.vars["y"].valueReference)
        buf = (ctypes.c_double * 1)()
        for name in ("fmi2GetReal", "fmi2SetReal"):
            assert _fn(inst, name)(c, vr, ctypes.c_size_t(1), None) == ERROR
            assert f"{name} refused" in inst.last() and "value" in inst.last() and "NULL" in inst.last(), inst.last()
            assert _fn(inst, name)(c, None, ctypes.c_size_t(1), buf) == ERROR
            assert f"{name} refused" in inst.last() and "vr" in inst.last() and "NULL" in inst.last(), inst.last()
        assert _fn(inst, "fmi2DoStep")(None, ctypes.c_double(0.0), ctypes.c_double(1e-3), 1) == ERROR
        assert inst.do_step()[0] == 0, inst.last()  # the instance goes on
    finally:
        inst.close()


@pytest.mark.parametrize("backend", BACKENDS, ids=["python", "native"])
def test_fmi3_null_arguments_and_counts_are_refused_naming_them(backend):
    """FMI 3.0: a NULL instanceName, values or valueReferences array is refused naming the
    argument; get/set with nValueReferences = 0 and nValues != 0 is refused naming both counts;
    fmi3DoStep on a NULL instance is Error."""
    import ctypes

    inst = RawInstance(backend, 3)
    try:
        c = ctypes.c_void_p(inst.fmu.component)
        from fmpy.fmi3 import fmi3LogMessageCallback

        log = fmi3LogMessageCallback(lambda env, status, cat, msg: inst.messages.append((status, msg.decode())))
        instantiate = _fn(inst, "fmi3InstantiateCoSimulation", ctypes.c_void_p)
        resources = (os.path.join(inst.fmu.unzipDirectory, "resources") + os.path.sep).encode()
        assert instantiate(None, inst.fmu.guid.encode(), resources, 0, 1, 0, 0, None, ctypes.c_size_t(0), None, log,
                           None) is None
        assert "fmi3InstantiateCoSimulation refused" in inst.last() and "instanceName" in inst.last(), inst.last()
        inst.reach(STEP)
        vr = (ctypes.c_uint32 * 1)(inst.vars["y"].valueReference)
        buf = (ctypes.c_double * 1)()
        one, zero = ctypes.c_size_t(1), ctypes.c_size_t(0)
        for name in ("fmi3GetFloat64", "fmi3SetFloat64"):
            assert _fn(inst, name)(c, vr, one, None, one) == ERROR
            assert f"{name} refused" in inst.last() and "values" in inst.last() and "NULL" in inst.last(), inst.last()
            assert _fn(inst, name)(c, None, one, buf, one) == ERROR
            assert f"{name} refused" in inst.last() and "valueReferences" in inst.last(), inst.last()
            assert _fn(inst, name)(c, vr, zero, buf, one) == ERROR
            assert f"{name} refused" in inst.last() and "nValueReferences = 0" in inst.last() and \
                "nValues = 1" in inst.last(), inst.last()
        flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
        assert _fn(inst, "fmi3DoStep")(None, ctypes.c_double(0.0), ctypes.c_double(1e-3), ctypes.c_bool(True),
                                       *[ctypes.byref(f) for f in flags]) == ERROR
        assert inst.do_step()[0] == 0, inst.last()
    finally:
        inst.close()


@pytest.mark.parametrize("fmu", ["PogoStick", "native/PogoStick", "fmi3/PogoStick", "native/fmi3/PogoStick"])
def test_a_freed_instance_is_refused_not_freed_again(fmu):
    """fmiNFreeInstance twice, then calls on the freed instance: the second free does nothing and
    the calls return Error (a live-instance check at every entry) instead of using freed memory.
    In a process of its own: a double free would abort it."""
    fmi = 3 if "fmi3" in fmu else 2
    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "_freed_instance.py"), str(DIST / f"{fmu}.fmu"),
                           str(fmi)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    statuses = json.loads(proc.stdout.strip().splitlines()[-1])
    assert statuses and set(statuses.values()) == {ERROR}, statuses


def test_model_exchange_counts_are_checked_naming_nx_and_nz():
    import ctypes

    fmu, messages = _fmi3_raw("PogoStick", "me")
    try:
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.updateDiscreteStates()
        fmu.enterContinuousTimeMode()
        buf = (ctypes.c_double * 32)()
        for function, n, words in (("fmi3GetContinuousStates", 2, "nContinuousStates = 2, and this FMU has nx = 7"),
                                   ("fmi3GetEventIndicators", 17, "nEventIndicators = 17, and this FMU has nz = 2"),
                                   ("fmi3GetContinuousStateDerivatives", 0, "nContinuousStates = 0, and this FMU has nx = 7"),
                                   ("fmi3SetContinuousStates", 3, "nContinuousStates = 3, and this FMU has nx = 7")):
            assert _raw(fmu, function, buf, n) == 3, function
            assert f"{function} refused: {words}" in messages[-1][1], messages[-1]
            assert "internal error" not in messages[-1][1]
        assert _raw(fmu, "fmi3GetContinuousStates", buf, 7) == 0
    finally:
        fmu.freeInstance()
