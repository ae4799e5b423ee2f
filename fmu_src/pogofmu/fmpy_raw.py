"""The FMI functions of an fmpy FMU object as the bare ctypes functions, in one place.

fmpy's methods (``fmu.doStep``, ``fmu.getReal``, ...) wrap each call in argument conversion, call
logging and a status check that raises. The SSP master's hot paths (a step, a state save, the
connector reads and writes) call the functions bare, and the call-state tests call them with
arguments fmpy's wrappers would refuse. fmpy keeps them, bound with their argument and result
types, in the private dict ``_functions`` of its FMU objects; nothing else in pogofmu reads it.
``FMPY_RANGE`` is the range pyproject.toml pins fmpy to, the versions this was checked with;
tests/test_fmpy_raw.py holds the two together and checks the functions against the binary's.

Host-side code; never imported inside an FMU.
"""
from __future__ import annotations

import itertools
import threading

FMPY_RANGE = ">=0.3.20,<0.4"  # pyproject.toml's dependency on fmpy (tests/test_fmpy_raw.py compares them)


class FmpyMismatch(RuntimeError):
    """The installed fmpy does not keep its FMU objects' functions as this module expects."""


def raw_function(fmu, name: str):
    """The ctypes function ``name`` (``fmi2DoStep``, ``fmi3GetFloat64``, ...) of an instantiated or
    loaded fmpy FMU object: it returns the FMI status as an int and raises nothing."""
    functions = getattr(fmu, "_functions", None)
    if not isinstance(functions, dict):
        import fmpy

        raise FmpyMismatch(f"fmpy {fmpy.__version__}: its FMU objects keep no _functions table; pogofmu needs "
                           f"fmpy{FMPY_RANGE}")
    try:
        return functions[name]
    except KeyError:
        raise FmpyMismatch(f"fmpy's FMU object has no function {name!r} (an FMI {name[3:4]} name?)") from None


def raw_call(fmu, name: str, *args) -> int:
    """``name(fmu.component, *args)`` called bare: the FMI status."""
    return raw_function(fmu, name)(fmu.component, *args)


# ---- FMI 2.0 callbacks ----------------------------------------------------------------------------
# fmpy 0.3 formats an FMI 2.0 message (a printf format with variadic arguments, which ctypes cannot
# take) in a native proxy that has ONE target for the whole process (docs/known-issues.md). A logger
# per instance would leave that target pointing at a freed function once its instance is gone (the
# next message from any instance then kills the process), and with several instances each would
# steal the others' messages. So the target is one function that lives as long as the process and
# files each message under the instance that sent it, by the componentEnvironment each instance
# hands back with every message.
_FMI2_LOGGER = None  # the one ctypes function of _fmi2_dispatch (made on first use: fmpy is imported late)
_FMI2_SINKS = {}  # componentEnvironment -> the instance's sink
_FMI2_KEYS = itertools.count(1)  # the componentEnvironment of the next instance (next() is atomic in CPython)
# (two threads making their first instances at once must not make two loggers: the proxy could be
# left pointing at the one freed with its instance)
_FMI2_LOCK = threading.Lock()


def _fmi2_dispatch(environment, instance, status, category, message):
    sink = _FMI2_SINKS.get(environment or 0)
    if sink is not None:
        sink(int(status), category.decode(errors="replace") if category else "",
             message.decode(errors="replace") if message else "")


class Fmi2Callbacks:
    """The ``fmi2CallbackFunctions`` of one FMI 2.0 instance: its messages, formatted, go to
    ``sink(status, category, text)`` (called on the thread of the FMI call that logs). Pass
    :attr:`struct` to ``instantiate`` and keep this object as long as the instance lives; a message
    after it is gone is dropped."""

    def __init__(self, sink):
        global _FMI2_LOGGER
        import weakref
        from ctypes import byref

        from fmpy import calloc, free
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                               fmi2CallbackLoggerTYPE)
        from fmpy.logging import addLoggerProxy

        with _FMI2_LOCK:
            if _FMI2_LOGGER is None:
                _FMI2_LOGGER = fmi2CallbackLoggerTYPE(_fmi2_dispatch)
        self.key = next(_FMI2_KEYS)
        _FMI2_SINKS[self.key] = sink
        weakref.finalize(self, _FMI2_SINKS.pop, self.key, None)
        cb = self.struct = fmi2CallbackFunctions()
        cb.logger = _FMI2_LOGGER
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        cb.componentEnvironment = self.key
        # (pointing the proxy at the dispatcher again: a user's simulate_fmu(logger=...) in the same
        # process may have moved it)
        addLoggerProxy(byref(cb))
