"""pogofmu.fmpy_raw, the one place that reads fmpy's private table of FMI functions: the installed
fmpy is in the range pyproject.toml pins and the module names, and the functions it hands out are
the FMU binary's own (the same symbol, the status returned, nothing raised), and an error they
return is logged to the instance's own logger even after fmpy freed its FMI 2.0 proxy's target.

References independent of the adapter: pyproject.toml, the binary's symbols through ctypes, and
fmpy's public wrappers (which raise where the bare function returns a status).
"""
import ctypes
import json
import re
import subprocess
import sys
import tomllib

import pytest
from pogofmu import fmpy_raw
from support import DIST, ROOT, RawInstance


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
def fmu(request):
    # callbacks of the instance's own (RawInstance), never fmpy's FMI 2.0 defaults: their log proxy
    # may point at a logger an earlier test freed, and the unknown value reference below is logged
    inst = RawInstance("", 2 if request.param == "fmi2" else 3)
    yield request.param, inst
    inst.fmu.freeInstance()


def test_the_functions_are_the_binarys_own_and_return_the_status(fmu):
    fmi, inst = fmu
    instance = inst.fmu
    getter = "fmi2GetReal" if fmi == "fmi2" else "fmi3GetFloat64"
    f = fmpy_raw.raw_function(instance, getter)
    address = ctypes.cast(getattr(instance.dll, getter), ctypes.c_void_p).value
    assert ctypes.cast(f, ctypes.c_void_p).value == address  # the same symbol of the same library
    inst.enter_initialization()
    inst.exit_initialization()
    y = inst.vars["y"]
    vr = (ctypes.c_uint32 * 1)(y.valueReference)
    buf = (ctypes.c_double * 1)()
    args = (vr, 1, buf) if fmi == "fmi2" else (vr, 1, buf, 1)
    assert fmpy_raw.raw_call(instance, getter, *args) == 0
    public = instance.getReal([y.valueReference]) if fmi == "fmi2" else instance.getFloat64([y.valueReference])
    assert buf[0] == public[0] and buf[0] > 0
    # an unknown value reference: the bare function returns Error and the FMU logs why, where
    # fmpy's wrapper raises
    bad = (ctypes.c_uint32 * 1)(10 ** 6)
    args = (bad, 1, buf) if fmi == "fmi2" else (bad, 1, buf, 1)
    assert fmpy_raw.raw_call(instance, getter, *args) == 3
    assert inst.last() == "value reference 1000000 is not a variable of PogoStick"
    with pytest.raises(Exception):
        instance.getReal([10 ** 6]) if fmi == "fmi2" else instance.getFloat64([10 ** 6])


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("backend", ["python", "native"])
def test_an_error_logged_after_fmpy_freed_its_proxys_logger_reaches_the_instances_own(backend, fmi):
    """After simulate_fmu(..., logger=...) fmpy's FMI 2.0 log proxy points at a freed function
    (docs/known-issues.md). An instance with callbacks of its own gets the refusal of an unknown
    value reference, and the process lives; one with fmpy's default FMI 2.0 callbacks loses the
    message or dies (the native binary: SIGSEGV or SIGILL in fmpy's logging.so), which is fmpy's
    and the reason the tests never use them. FMI 3.0 gives every instance its own logger, and fmpy's
    default one prints the message. In processes of their own: the control may be killed."""
    def run(callbacks):
        proc = subprocess.run([sys.executable, str(ROOT / "tests" / "_logger_target.py"), backend, str(fmi), callbacks],
                              capture_output=True, text=True, timeout=180)
        return proc, (json.loads(proc.stdout.strip().splitlines()[-1]) if proc.returncode == 0 else None)

    text = "value reference 9999 is not a variable of PogoStick"
    proc, result = run("own")
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    assert result == {"status": 3, "messages": [text]}
    proc, result = run("default")
    if fmi == 3:
        assert proc.returncode == 0 and result["status"] == 3 and text in proc.stdout, (proc.returncode, proc.stdout)
    else:  # the control: the hazard the own callbacks avoid is there
        assert proc.returncode != 0 or text not in proc.stdout, (proc.returncode, proc.stdout)


@pytest.mark.parametrize("backend", ["python", "native"])
def test_after_a_sweep_run_fmpys_proxy_is_left_at_a_logger_that_lives(backend):
    """The sweep's runner points fmpy's FMI 2.0 proxy at one logger that lives as long as the
    process (its own per-run logger was freed with the run and a later instance on fmpy's default
    callbacks then died, as after simulate_fmu(logger=...) in the control above): the refusal of
    an unknown value reference on such an instance returns Error and the process lives."""
    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "_logger_target.py"), backend, "2", "default", "sweep"],
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    assert json.loads(proc.stdout.strip().splitlines()[-1])["status"] == 3


def test_sweep_runs_on_threads_each_get_their_own_fmi2_messages():
    """Runs of the sweep on two threads at once (a Dask worker's threads): each row's event list is
    that of the same point run alone; with fmpy's one proxy target a run's messages could land in
    the other's list."""
    import threading

    from pogofmu.sweep import Runner, Settings

    runner = Runner(str(DIST / "PogoStick.fmu"))
    settings = Settings(stop_time=3.0, events=True)
    points = [{"ydot_0": 0.3 * i} for i in range(6)]
    alone = [runner.run(p, settings)[0]["event_t"] for p in points]
    assert len({tuple(e) for e in alone}) == len(points) and all(alone)
    together = [None] * len(points)

    def work(k):
        for i in range(k, len(points), 2):
            together[i] = runner.run(points[i], settings)[0]["event_t"]
    threads = [threading.Thread(target=work, args=(k,)) for k in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert together == alone


def test_instances_alive_at_once_each_get_their_own_fmi2_messages():
    """Two FMI 2.0 instances alive at once, stepped in turn: each one's events and refusals land in
    its own list only (fmpy's proxy has one target; pogofmu.fmpy_raw.Fmi2Callbacks files a message
    by the componentEnvironment the instance hands back), the same events as an instance alone."""
    from fmpy.fmi1 import FMICallException
    from support import Instance, parse_event_log

    a = Instance("PogoStick", "a").init(log_events=1)
    b = Instance("PogoStick", "b").init(log_events=1, ydot_0=-2.0)
    for k in range(1, 201):
        a.run_to(k * 1e-2, 1e-2)
        b.run_to(k * 1e-2, 1e-2)
    alone = Instance("PogoStick", "alone").init(log_events=1)
    alone.run_to(2.0, 1e-2)
    ta, tb = ([e["time"] for e in parse_event_log(i.messages)] for i in (a, b))
    assert ta and tb and set(ta).isdisjoint(tb), (ta, tb)
    assert ta == [e["time"] for e in parse_event_log(alone.messages)]
    n_b = len(b.messages)
    with pytest.raises(FMICallException):
        a.fmu.setReal([10 ** 6], [1.0])  # an unknown value reference: refused, and the refusal logged
    assert a.messages[-1][0] >= 3 and "1000000" in a.messages[-1][2], a.messages[-1]
    assert len(b.messages) == n_b


def test_a_missing_function_or_table_is_named():
    class NotAnFmpyFMU:
        component = None

    with pytest.raises(fmpy_raw.FmpyMismatch, match="no _functions table"):
        fmpy_raw.raw_function(NotAnFmpyFMU(), "fmi2DoStep")
    holder = NotAnFmpyFMU()
    holder._functions = {"fmi2DoStep": print}
    with pytest.raises(fmpy_raw.FmpyMismatch, match="no function 'fmi3DoStep'"):
        fmpy_raw.raw_function(holder, "fmi3DoStep")
