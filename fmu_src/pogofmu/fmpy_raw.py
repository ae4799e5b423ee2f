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
