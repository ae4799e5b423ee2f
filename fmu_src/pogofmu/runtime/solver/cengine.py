"""The engine, in C (``fmu_src/native/engine/``), for a model written in Python.

There is one engine: the C one (``pg_engine.c``: the Runge-Kutta pairs, error control, event
location, restarts, the work budget, event storms, domain conditions and every message).  The
native FMUs link it with their model's generated C.  Everything else — the Python-hosted FMUs and
the host-side tools (default experiments, studies, the dependency probes of the exporter, the
tests) — runs the same engine through this binding, with the model's Python functions (flow,
guards, activity, jumps, outputs, domain, rules, scales) called back through ctypes.  A
:class:`Simulator` is the engine for one run.

The Rosenbrock method's Jacobian (``method`` 1, and 0 while stiff) is the exact one, as in the
native FMUs: each column is the model's own flow on dual numbers (:mod:`..dual`), the same
operations as the native FMU's generated ``flow_jvp``.  A flow that does not run on dual numbers
(``math.sqrt(x)`` instead of ``fmath.sqrt(x)``, ``float(x)``) answers ``PG_NO_JVP`` once: the
engine takes the Jacobian by central differences for the rest of the run, and the run says so
(:attr:`Simulator.jacobian_by_differences`, a ``logSolver`` message).

Where the library comes from:

* inside a Python-hosted FMU, the FMU's launcher carries the engine (its ``pgb_*`` functions); the
  bootstrap names the launcher (:func:`use_library`);
* on the host, where the host-side package says (:func:`set_host_library`; ``pogofmu/__init__.py``
  gives ``pogofmu.codegen.build.host_engine_library``): an installed package's copy, compiled
  when the package was built (``pogofmu/_lib``), else compiled once per version of its sources into
  the user's cache folder (``POGOFMU_CACHE``, else the platform's cache folder).

The library is loaded with the GIL kept (``ctypes.PyDLL``): the callbacks run Python anyway, and a
run is one thread's.

Errors: the engine returns a message; a model function's own exception comes back as itself (a
:class:`ParameterError` stays one, a bug in a model stays a ``TypeError`` with its traceback), an
engine refusal becomes the :class:`ModelError` subclass its text names (event storm:
:class:`ZenoError`; leaving the domain and floating-point failures: :class:`DomainError`).
"""
from __future__ import annotations

import ctypes as C
import math
import os
import re
import struct
import threading
import weakref
from dataclasses import dataclass
from typing import List, Optional

from ..dual import Dual, value_and_tangent
from ..interface import discrete_layout  # noqa: F401 (the engine's layout of q, said once)
from ..model import FALLING, DomainError, HybridModel, ModelError, ParameterError, Params, ZenoError, reads_time
from .settings import SOLVER_PARAMETERS, check_solver_parameters, domain_slack, split_parameters

PG_OK, PG_RAISE, PG_ARITH, PG_NO_JVP = 0, 1, 2, 3
PG_ZERO_DIVISION, PG_OVERFLOW, PG_DOMAIN = 1, 2, 3
PG_MSG_MAX = 2048
_READ_HEAD = 12  # the scalars before the vectors in pgb_read
D = C.POINTER(C.c_double)


class PgMsg(C.Structure):
    _fields_ = [("text", C.c_char * PG_MSG_MAX), ("len", C.c_size_t), ("arith", C.c_int)]


MSG = C.POINTER(PgMsg)
P = C.c_void_p  # the callbacks take addresses (plain ints): a ctypes pointer object per argument costs twice as much
FN = {
    "check_settings": C.CFUNCTYPE(C.c_int, P, P),
    "check": C.CFUNCTYPE(C.c_int, P, P),
    "initial": C.CFUNCTYPE(C.c_int, P, P, P, P),
    "flow": C.CFUNCTYPE(C.c_int, C.c_double, P, P, P, P, P, P),
    "guard": C.CFUNCTYPE(C.c_int, C.c_int, C.c_double, P, P, P, P, P, P),
    "active": C.CFUNCTYPE(C.c_int, C.c_int, P, P, P),
    "jump": C.CFUNCTYPE(C.c_int, C.c_int, C.c_double, P, P, P, P, P, P, P),
    "outputs": C.CFUNCTYPE(C.c_int, C.c_double, P, P, P, P, P, P),
    "domain": C.CFUNCTYPE(C.c_int, C.c_double, P, P, P, P, P, P),
    "time_scales": C.CFUNCTYPE(C.c_int, P, P, P, P),
    "error_scales": C.CFUNCTYPE(C.c_int, P, P, P, P),
    "flow_jvp": C.CFUNCTYPE(C.c_int, C.c_double, P, P, P, P, P, P, P, P),
    "outputs_jvp": C.CFUNCTYPE(C.c_int, C.c_double, P, P, P, P, P, P, P, P),
    "time_event": C.CFUNCTYPE(C.c_int, C.c_int, P, P, P, P),
    "time_jump": C.CFUNCTYPE(C.c_int, C.c_int, C.c_double, P, P, P, P, P, P, P),
}
STRS = C.POINTER(C.c_char_p)
_FUNCTIONS = ("check_settings", "check", "initial", "flow", "guard", "active", "jump", "outputs", "domain",
              "time_scales", "error_scales", "flow_jvp", "outputs_jvp")
_BOUND = _FUNCTIONS[:12] + ("time_event", "time_jump")  # a Simulator's (outputs_jvp: NULL, never called)


class PgModel(C.Structure):
    """``PgModel`` of pg_model.h."""
    _fields_ = [("name", C.c_char_p), *((n, C.c_int) for n in ("nx", "nq", "nu", "np", "ns", "ny", "ne")),
                ("state_names", STRS), ("q_names", STRS), ("q_kinds", C.c_char_p), ("input_names", STRS),
                ("parameter_names", STRS), ("parameter_kinds", C.c_char_p), ("output_names", STRS),
                ("event_names", STRS), ("event_direction", C.POINTER(C.c_byte)),
                ("has_time_scales", C.c_int), ("has_error_scales", C.c_int),
                *((n, FN[n]) for n in _FUNCTIONS),
                ("nte", C.c_int), ("time_event_names", STRS), ("time_event", FN["time_event"]),
                ("time_jump", FN["time_jump"])]


EVENT_HOOK = C.CFUNCTYPE(None, C.c_void_p, C.c_void_p, C.c_void_p, C.c_long)  # the PgEvent by address
WARN_HOOK = C.CFUNCTYPE(None, C.c_void_p, C.c_char_p)
SWITCH_HOOK = C.CFUNCTYPE(None, C.c_char_p)  # pg_binding.c: a method switch's text

# ---- the library --------------------------------------------------------------------------------
_LIB = None
_LIB_PATH: Optional[str] = None
_LIB_LOCK = threading.Lock()

# ---- the hot functions in C (pg_binding.c's trampolines call the model through the C API) ---------
_HOT = ("flow", "guard", "active", "outputs", "domain")  # pgb_py_functions' order
_API_FUNCTIONS = ("PyFloat_FromDouble", "PyFloat_AsDouble", "PyList_New", "PyList_SetItem", "PyList_GetItem",
                  "PyTuple_New", "PyTuple_SetItem", "PyTuple_GetItem", "PyObject_CallObject", "PySequence_Size",
                  "PySequence_GetItem", "PyObject_GetItem", "PyNumber_Float", "PyObject_IsTrue", "PyErr_Occurred",
                  "PyErr_Fetch", "PyErr_NormalizeException", "PyException_SetTraceback", "PyErr_SetString",
                  "PyLong_FromVoidPtr", "PyLong_AsLong", "Py_IncRef", "Py_DecRef")


class PgbPyApi(C.Structure):
    """``PgbPyApi`` of pg_binding.c: this interpreter's C API functions, by address."""
    _fields_ = [*((n, C.c_void_p) for n in _API_FUNCTIONS), ("none", C.c_void_p), ("value_error", C.c_void_p)]


def _python_api() -> PgbPyApi:
    api = PgbPyApi()
    for name in _API_FUNCTIONS:
        setattr(api, name, C.cast(getattr(C.pythonapi, name), C.c_void_p).value)
    api.none, api.value_error = id(None), id(ValueError)  # (CPython: an object's id is its address)
    return api


def _forget_py(lib, py) -> None:
    lib.pgb_py_forget(C.byref(py))


class PgbPy(C.Structure):
    """``PgbPy`` of pg_binding.c: one run's Python objects (borrowed: the Simulator keeps them) and the
    trampolines' cache (owned by the C, dropped with pgb_py_forget)."""
    _fields_ = [("switch_text", C.c_void_p),
                *((n, C.c_void_p) for n in ("sync", "fail", "fun_for", "domain_text", "guards", "guard_times",
                                            "actives",
                                            "output_fn", "output_names", "domain", "p", "slack")),
                *((n, C.c_int) for n in ("nx", "nq", "nu", "ny", "q_ok", "u_ok")),
                ("qdict", C.c_void_p), ("uc", C.c_void_p), ("bound", C.c_void_p)]
    # then the cache's keys of q and u (sized by the engine's limits): an instance is made in a
    # buffer of pgb_py_sizeof() bytes (:func:`_new_py`)


def _new_py(lib):
    # (from_buffer keeps the buffer alive with the instance: nothing else holds it)
    return PgbPy.from_buffer((C.c_byte * lib.pgb_py_sizeof())())


def use_library(path) -> None:
    """Run the engine of the library at ``path`` (the FMU's launcher, named by its bootstrap)."""
    global _LIB_PATH, _LIB
    with _LIB_LOCK:
        if _LIB is None or _LIB_PATH != str(path):
            _LIB_PATH, _LIB = str(path), None


_HOST_LIBRARY = None  # on the host: a function giving the engine library's path (set_host_library)


def set_host_library(finder) -> None:
    """On the host, the host-side package says where the engine library is (``pogofmu/__init__.py``
    gives ``pogofmu.codegen.build.host_engine_library``): the runtime imports no host-side code."""
    global _HOST_LIBRARY
    _HOST_LIBRARY = finder


def _find_library() -> str:
    if _HOST_LIBRARY is None:
        raise ModelError("the engine library is not available: this copy of the runtime was loaded without its "
                         "FMU's launcher (run the FMU through its binary)")
    return str(_HOST_LIBRARY())


def library():
    global _LIB, _LIB_PATH
    if _LIB is not None:
        return _LIB
    with _LIB_LOCK:
        if _LIB is None:
            path = _LIB_PATH or _find_library()
            lib = C.PyDLL(path)
            lib.pgb_sizeof.restype = C.c_size_t
            lib.pgb_message.restype = C.c_char_p
            lib.pgb_message.argtypes = [C.c_void_p]
            lib.pgb_init.argtypes = [C.c_void_p, C.c_void_p, D, D, D, C.c_double, C.c_double, C.c_int, C.c_double,
                                     C.c_int, EVENT_HOOK, WARN_HOOK, C.c_void_p]
            lib.pgb_rebind.argtypes = [C.c_void_p, C.c_void_p, EVENT_HOOK, WARN_HOOK, C.c_void_p]
            lib.pgb_py_sizeof.restype = C.c_size_t
            if lib.pgb_py_sizeof() < C.sizeof(PgbPy):
                raise ModelError(f"the engine library's PgbPy has {lib.pgb_py_sizeof()} bytes, fewer than "
                                 f"{C.sizeof(PgbPy)}: another build of pg_binding.c")
            lib.pgb_py_api.argtypes = [C.c_void_p]
            lib.pgb_py_api.restype = None
            lib.pgb_py_forget.argtypes = [C.c_void_p]
            lib.pgb_py_forget.restype = None
            lib.pgb_py_functions.argtypes = [C.c_void_p]
            lib.pgb_py_functions.restype = None
            lib.pgb_py_api(C.byref(_python_api()))
            tramps = (C.c_void_p * 5)()
            lib.pgb_py_functions(tramps)
            lib.trampolines = dict(zip(_HOT, tramps))
            lib.pgb_rebind.restype = None
            # (the calls of every communication step take addresses, plain ints: cheaper to convert
            # than an array for a D)
            lib.pgb_advance.argtypes = [C.c_void_p, C.c_double, C.c_void_p]
            lib.pgb_advance_to_event.argtypes = [C.c_void_p, C.c_double, C.POINTER(C.c_int), C.c_void_p]
            lib.pgb_set_input.argtypes = [C.c_void_p, D]
            lib.pgb_set_inputs.argtypes = [C.c_void_p, D, D]
            lib.pgb_inputs_at.argtypes = [C.c_void_p, C.c_double, D]
            lib.pgb_apply_event.argtypes = [C.c_void_p, C.c_int, C.c_double, D]
            lib.pgb_restart_at.argtypes = [C.c_void_p, C.c_double, D, D]
            lib.pgb_event_due.argtypes = [C.c_void_p]
            lib.pgb_next_time_event.argtypes = [C.c_void_p]
            lib.pgb_next_time_event.restype = C.c_double
            lib.pgb_time_event_due.argtypes = [C.c_void_p, C.c_double]
            lib.pgb_me_indicators.argtypes = [C.c_void_p, C.c_double, D, D]
            lib.pgb_me_fired.argtypes = [C.c_void_p, C.c_double, D, C.POINTER(C.c_int)]
            lib.pgb_read.argtypes = [C.c_void_p, C.c_void_p]
            lib.pgb_read.restype = None
            lib.pgb_last_event.argtypes = [C.c_void_p, D, D]
            lib.pgb_last_event.restype = None
            lib.pgb_limits.argtypes = [C.POINTER(C.c_int)]
            lib.pgb_limits.restype = None
            lib.layouts = _Layouts(lib)
            _LIB_PATH, _LIB = path, lib
    return _LIB


class _Layouts:
    """PgEvent and PgScale (pg_engine.h, pg_model.h) laid out with the sizes one library was built with.

    One per loaded library (``lib.layouts``), not global: :func:`use_library` may load another
    build of the engine while runs on the previous one go on, and each must read its own sizes."""

    def __init__(self, lib):
        sizes = (C.c_int * 3)()
        lib.pgb_limits(sizes)
        max_x, self.max_scales, self.max_scale_names = sizes
        self.event = type("PgEvent", (C.Structure,), {"_fields_": [
            ("time", C.c_double), ("index", C.c_int), ("x_before", C.c_double * max_x),
            ("x_after", C.c_double * max_x)]})
        self.scale = type("PgScale", (C.Structure,), {"_fields_": [
            ("label", C.c_char_p), ("names", C.c_char_p * self.max_scale_names), ("n_names", C.c_int),
            ("value", C.c_double)]})


def layouts() -> _Layouts:
    """The :class:`_Layouts` (``event``, ``scale``, ``max_scales``, ``max_scale_names``) of the loaded library."""
    return library().layouts


# ---- a model's static description ---------------------------------------------------------------
def _strings(names):
    raw = [n.encode() for n in names]
    arr = (C.c_char_p * max(len(raw), 1))(*raw)
    return arr, raw


def _doubles(values, n=None):
    n = len(values) if n is None else n
    a = (C.c_double * max(n, 1))()
    for i, v in enumerate(values):
        a[i] = float(v)
    return a


def _number_or_nan(v) -> float:
    return float(v) if isinstance(v, (int, float)) else math.nan


class _Static:
    """The constant part of a PgModel (names, counts, directions), built once per model."""

    def __init__(self, model: HybridModel, layout):
        self.model = model
        self.layout = layout
        self.keep = []
        m = self.struct = PgModel()
        self.keep.append(model.name.encode())
        m.name = self.keep[-1]
        m.nx, m.nq, m.nu, m.np = len(model.states), len(layout), len(model.inputs), len(model.parameters)
        m.ns, m.ny, m.ne = len(SOLVER_PARAMETERS), len(model.outputs), len(model.events)
        m.nte = len(model.time_events)
        for field, names in (("state_names", [v.name for v in model.states]), ("q_names", [k for k, _ in layout]),
                             ("input_names", [v.name for v in model.inputs]),
                             ("parameter_names", [par.name for par in model.parameters]),
                             ("output_names", [v.name for v in model.outputs]),
                             ("event_names", [ev.name for ev in model.events]),
                             ("time_event_names", [ev.name for ev in model.time_events])):
            arr, raw = _strings(names)
            self.keep += [arr, raw]
            setattr(m, field, arr)
        for field, text in (("q_kinds", "".join(kind for _, kind in layout)),
                            ("parameter_kinds", "".join("i" if par.integer else "f" for par in model.parameters))):
            self.keep.append(text.encode())
            setattr(m, field, self.keep[-1])
        directions = (C.c_byte * max(len(model.events), 1))(*[-1 if ev.direction == FALLING else 1
                                                                for ev in model.events])
        self.keep.append(directions)
        m.event_direction = directions
        m.has_time_scales = int(model.time_scales is not None)
        m.has_error_scales = int(model.error_scales is not None)


_STATICS = {}


def _static(model: HybridModel, p) -> _Static:
    entry = _STATICS.get(id(model))
    if entry is None or entry.model is not model:
        entry = _STATICS[id(model)] = _Static(model, discrete_layout(model, p))
    return entry


def _write_text(msg: PgMsg, text: str) -> None:
    raw = text.encode("utf-8", "replace")[:PG_MSG_MAX - 1]
    msg.text = raw
    msg.len = len(raw)


def _q_value(kind: str, v: float):
    """An entry of q as the model's dict holds it: an entry the model started as an int (kind ``i``)
    is an int while its value is whole, and the value itself once a jump made it something else
    (``0 + 0.25`` is 0.25, in Python's arithmetic and in the native FMU's alike; until 2026-12-07 it
    was truncated back to 0 here, silently, in the Python-hosted FMUs only: a user's audit)."""
    return int(v) if kind == "i" and v.is_integer() else v


def _arith_kind(exc) -> int:
    if isinstance(exc, ZeroDivisionError):
        return PG_ZERO_DIVISION
    if isinstance(exc, OverflowError):
        return PG_OVERFLOW
    return PG_DOMAIN


# the engine's message for a function of the model that failed during the run (pg_engine.c, model_call)
_FUNCTION_FAILED = re.compile(r"the (flow|guard of event .+|jump of event .+|outputs) failed at t = ")
# the model's own code: outside this runtime's folder (host side), or in its user/ folder (in an FMU)
_RUNTIME = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _users_line(exc) -> str:
    """The text " at ball.py:12": the innermost line of the model's own code in ``exc``'s traceback (a user's
    model file or its local modules; not the runtime, nor the project's models), or ""."""
    found, tb = "", exc.__traceback__
    while tb is not None:
        path = os.path.abspath(tb.tb_frame.f_code.co_filename)
        if not path.startswith(_RUNTIME + os.sep) or path.startswith(os.path.join(_RUNTIME, "user") + os.sep):
            found = f" at {os.path.basename(path)}:{tb.tb_lineno}"
        tb = tb.tb_next
    return found


def _error_class(text: str):
    """The ModelError subclass an engine refusal belongs to (the engine's texts, pg_engine.c)."""
    if text.startswith("event storm"):
        return ZenoError
    if text.startswith(("the trajectory left", "floating-point", "the state became non-finite", "the rate d")) or \
            _FUNCTION_FAILED.match(text):
        return DomainError
    if text.startswith("cannot go back in time"):
        return ValueError
    if " violates the rule: " in text or " violate the rule: " in text:
        return ParameterError
    return ModelError


@dataclass
class EventRecord:
    """One handled event: when, which, and the state just before and after its jump."""

    time: float
    name: str
    index: int
    x_before: list
    x_after: list


class Binding:
    """One model bound to the engine: the ``PgModel`` whose functions call the model's Python code
    (the hot ones, flow, guards, activity, outputs and domain, through pg_binding.c's trampolines,
    given this object's ``PgbPy``; the cold ones through ctypes callbacks into this object), the
    caches of the discrete state's dict and the inputs' tuple, and the one place a Python exception
    becomes the engine's result (:meth:`_fail`).

    A :class:`Simulator` is one (and drives its own engine). The Python-hosted FMUs' C adapter keeps
    one per FMU instance (:mod:`..hosted`): the adapter drives the engine, and hands the binding the
    instance's parameters and settings when they change (:meth:`bind`). ``p`` and ``solver`` are
    the Python values the model's functions see."""

    def __init__(self, model: HybridModel, p=None, solver=None, u=None):
        p, s = split_parameters(model, {} if p is None else p, solver)
        self.model, self.p, self.solver = model, p, s
        self.u = tuple(float(v.start) for v in model.inputs) if u is None else tuple(float(v) for v in u)
        # the solver's messages not yet taken (logSolver): method = 0's switches, and the Jacobian
        # going to differences (a flow that does not run on dual numbers; then jacobian_by_differences)
        self.new_switches: List[str] = []
        self.jacobian_by_differences = False
        # (this run's library for good: its PgModel holds that copy's trampolines, and a process may
        # run FMUs each with its own copy of the library, use_library switching among them)
        self._lib = library()
        self._bind_model()

    def bind(self, p_addr: int, s_addr: int) -> None:
        """The model's parameters and the solver's settings from the doubles at ``p_addr`` (the
        model's parameters in order) and ``s_addr`` (SOLVER_PARAMETERS' order), as the engine has
        them: an integer parameter's value becomes an int. The trampolines' cache is dropped."""
        model = self.model
        pv = (C.c_double * max(len(model.parameters), 1)).from_address(p_addr)
        sv = (C.c_double * len(SOLVER_PARAMETERS)).from_address(s_addr)
        values = {par.name: _python_value(par, pv[i]) for i, par in enumerate(model.parameters)}
        values.update((par.name, _python_value(par, sv[i])) for i, par in enumerate(SOLVER_PARAMETERS))
        self.p, self.solver = split_parameters(model, values)
        self._slack = domain_slack(self.solver)
        self._qkey = self._qdict = self._bound = self._ukey = None
        self._fill_py()

    # ---- the callbacks ------------------------------------------------------------------------
    def _bind_model(self):
        """This binding's PgModel: the model's constant description and callbacks into this object."""
        model = self.model
        static = _static(model, self.p)
        self._static = static
        self._layout = static.layout
        self._nx, self._nq, self._nu = len(model.states), len(static.layout), len(model.inputs)
        self._X, self._Q = C.c_double * max(self._nx, 1), C.c_double * max(self._nq, 1)
        self._qbytes = 8 * self._nq
        self._qfmt = f"={self._nq}d"
        self._U, self._ubytes, self._ukey, self._uc = C.c_double * max(self._nu, 1), 8 * self._nu, None, self.u
        self._guards = [ev.guard_t for ev in model.events]
        # the guards as written, and whether each reads the time (pg_binding.c's trampoline calls them)
        self._guards_raw = [ev.guard for ev in model.events]
        self._guard_times = [reads_time(ev.guard) for ev in model.events]
        self._ne = len(model.events)
        self._slack = domain_slack(self.solver)
        self._exc = None
        self._qkey = None
        self._qdict = None
        self._bound = None
        self._qfloat = tuple(i for i, (_, kind) in enumerate(self._layout) if kind != "i")
        st = self._struct = PgModel()
        C.pointer(st)[0] = static.struct  # the constant fields
        # the cold functions through ctypes callbacks, the hot ones through pg_binding.c's trampolines
        lib = self._lib
        self._callbacks = cbs = {name: FN[name](getattr(self, "_cb_" + name)) for name in _BOUND
                                 if name not in _HOT}
        cbs.update((name, FN[name](lib.trampolines[name])) for name in _HOT)
        for name, fn in cbs.items():
            setattr(st, name, fn)
        self._on_switch = SWITCH_HOOK(self._cb_switch)
        if getattr(self, "_py", None) is None:
            self._py = _new_py(lib)
            weakref.finalize(self, _forget_py, lib, self._py)  # (the cache's references, with this binding)
        self._fill_py()
        return static

    def _fill_py(self):
        """This run's PgbPy: the objects the trampolines call (kept alive here), the cache dropped."""
        model, py = self.model, self._py
        self._forget()
        keep = self._py_keep = {
            "sync": self._tsync, "fail": self._fail, "fun_for": self._fun_for, "domain_text": self._domain_text,
            "guards": list(self._guards_raw), "guard_times": list(self._guard_times),
            "actives": [ev.active for ev in model.events],
            "output_fn": model.output_fn, "output_names": tuple(v.name for v in model.outputs),
            "domain": model.domain, "p": self.p, "slack": self._slack}
        for name, obj in keep.items():
            setattr(py, name, id(obj))
        py.switch_text = C.cast(self._on_switch, C.c_void_p).value
        py.nx, py.nq, py.nu, py.ny = self._nx, self._nq, self._nu, len(model.outputs)

    def _forget(self):
        """The trampolines' dict of q, tuple of u and bound flow dropped (changed by another route)."""
        self._lib.pgb_py_forget(C.byref(self._py))

    def _tsync(self, q, u):
        """The trampolines' ``sync``: the model's dict of q (address ``q``) and tuple of u (address
        ``u``, None: q only), as the callbacks had them."""
        return self._q(q, u), self._uc

    def _domain_text(self, text, m) -> int:
        """The trampolines' domain condition that failed: its text into the message at ``m``."""
        _write_text(PgMsg.from_address(m), str(text))
        return PG_RAISE

    def _fail(self, exc, m) -> int:
        """A Python exception inside a callback: kept, to be raised again as itself (unless the engine
        names the function of the model it came from: then the engine's message, from it). An
        exception of the model's own code carries its type, file and line into the message."""
        msg = PgMsg.from_address(m)
        where = "" if isinstance(exc, ModelError) else _users_line(exc)
        if isinstance(exc, (ArithmeticError, ValueError)) and not isinstance(exc, ModelError):
            self._exc = None
            msg.arith = _arith_kind(exc)
            detail = exc.args[-1] if exc.args and isinstance(exc.args[-1], str) else str(exc)
            _write_text(msg, f"{type(exc).__name__}: {detail}{where}" if where else detail)
            return PG_ARITH
        self._exc = exc
        _write_text(msg, str(exc) if isinstance(exc, ModelError) else f"{type(exc).__name__}: {exc}{where}")
        return PG_RAISE

    def _q(self, q, u=None):
        """The discrete state at address ``q`` as the model's dict and the inputs at address ``u`` as
        a tuple (``self._uc``), cached while they do not change.  The inputs are read from the engine:
        an input change redoes the step taken ahead with the old inputs before it binds the new."""
        key = C.string_at(q, self._qbytes) if self._nq else b""
        if u is not None and self._nu:
            ukey = C.string_at(u, self._ubytes)
            if ukey != self._ukey:
                self._ukey, self._uc, self._bound = ukey, tuple(self._U.from_address(u)[:self._nu]), None
        if key != self._qkey:
            values = self._Q.from_address(q)[:self._nq] if self._nq else []
            self._qdict = {k: _q_value(kind, v) for (k, kind), v in zip(self._layout, values)}
            self._qkey = key
            self._bound = None
        return self._qdict

    def _fun_for(self, qd):
        if self._bound is None:
            model, u, p = self.model, self._uc, self.p
            if model.bind is not None:
                self._bound = model.bind(qd, u, p)
            else:
                flow = model.flow
                self._bound = lambda t, x: flow(t, x, qd, u, p)
        return self._bound

    def _cb_check_settings(self, s, m):
        try:
            check_solver_parameters(self.solver, has_states=bool(self.model.states))
            return PG_OK
        except BaseException as exc:
            return self._fail(exc, m)

    def _cb_check(self, p, m):
        try:
            self.model.check_parameters(self.p)
            return PG_OK
        except BaseException as exc:
            return self._fail(exc, m)

    def _put_state(self, what, x_addr, q_addr, x_new, q_new):
        """Write a state the model returned (checked against the model's sizes and keys)."""
        x_new = [float(v) for v in x_new]
        if len(x_new) != self._nx:
            raise ModelError(f"{self.model.name}: {what} returned {len(x_new)} states, not {self._nx}")
        keys = [k for k, _ in self._layout]
        if list(q_new) != keys:
            raise ModelError(f"{self.model.name}: {what} returned a discrete state with keys {list(q_new)}, not {keys}")
        if self._nx:
            self._X.from_address(x_addr)[:] = x_new
        if self._nq:
            self._Q.from_address(q_addr)[:] = [float(q_new[k]) for k in keys]

    def _cb_initial(self, p, x, q, m):
        try:
            x0, q0 = self.model.initial(self.p)
            self._put_state("initial", x, q, x0, q0)
            return PG_OK
        except BaseException as exc:
            return self._fail(exc, m)

    def _cb_flow(self, t, x, q, u, p, dx, m):
        try:
            f = self._fun_for(self._q(q, u))(t, self._X.from_address(x)[:self._nx])
            if self._nx:
                self._X.from_address(dx)[:] = f
            return PG_OK
        except BaseException as exc:
            return self._fail(exc, m)

    def _cb_flow_jvp(self, t, x, q, u, p, sx, su, df, m):
        """A column of the flow's Jacobian for the engine: the model's flow on dual numbers, the states'
        tangents ``sx`` (the inputs' tangents ``su`` are the engine's zeros, NO_INPUT_MOVE: the inputs
        go in as numbers).  The engine computed the flow at this point already, so an exception here
        comes from the duals: an arithmetic one (a derivative at a singular point) or a model error
        is reported as the native FMU's generated flow_jvp reports it; any other means that the flow
        does not run on dual numbers, and the engine takes differences from now on."""
        try:
            nx, X = self._nx, self._X
            # (a state of zero tangent goes in as its number: the same values and tangents as a dual of
            # tangent 0, which the duals' arithmetic skips, at a number's cost)
            xs = [v if d == 0.0 else Dual(v, d) for v, d in zip(X.from_address(x)[:nx], X.from_address(sx)[:nx])]
            f = self._fun_for(self._q(q, u))(t, xs)
            if nx:
                X.from_address(df)[:] = [v.d if v.__class__ is Dual else value_and_tangent(v)[1] for v in f]
            return PG_OK
        except (ArithmeticError, ValueError, ModelError) as exc:
            return self._fail(exc, m)
        except Exception as exc:  # noqa: BLE001 - not dual-traceable: differences, said once
            self.new_switches.append(
                f"the Jacobian by central differences from t = {t!r} s on: {self.model.name}'s flow does not "
                f"run on dual numbers ({type(exc).__name__}: {exc})")
            return PG_NO_JVP
        except BaseException as exc:
            return self._fail(exc, m)

    def _cb_guard(self, k, t, x, q, u, p, g, m):
        try:
            C.c_double.from_address(g).value = self._guards[k](t, self._X.from_address(x)[:self._nx], self._q(q, u),
                                                               self._uc, self.p)
            return PG_OK
        except BaseException as exc:
            return self._fail(exc, m)

    def _cb_active(self, k, q, on, m):
        try:
            C.c_int.from_address(on).value = 1 if self.model.events[k].active(self._q(q)) else 0
            return PG_OK
        except BaseException as exc:
            return self._fail(exc, m)

    def _cb_jump(self, k, t, x, q, u, p, x_new, q_new, m):
        return self._jump(self.model.events[k], t, x, q, u, x_new, q_new, m)

    def _cb_time_jump(self, k, t, x, q, u, p, x_new, q_new, m):
        return self._jump(self.model.time_events[k], t, x, q, u, x_new, q_new, m)

    def _jump(self, ev, t, x, q, u, x_new, q_new, m):
        try:
            x2, q2 = ev.jump_t(t, self._X.from_address(x)[:self._nx], self._q(q, u), self._uc, self.p)
            self._put_state(f"the jump of {ev.name}", x_new, q_new, x2, q2)
            return PG_OK
        except BaseException as exc:
            return self._fail(exc, m)

    def _cb_time_event(self, k, p, at, every, m):
        try:
            ev = self.model.time_events[k]
            C.c_double.from_address(at).value = float(ev.at(self.p))
            C.c_double.from_address(every).value = float(ev.period(self.p))
            return PG_OK
        except BaseException as exc:
            return self._fail(exc, m)

    def _cb_outputs(self, t, x, q, u, p, y, m):
        try:
            out = self.model.output_fn(t, self._X.from_address(x)[:self._nx], self._q(q, u), self._uc, self.p)
            ys = (C.c_double * max(len(self.model.outputs), 1)).from_address(y)
            for i, v in enumerate(self.model.outputs):
                ys[i] = float(out[v.name])
            return PG_OK
        except BaseException as exc:
            return self._fail(exc, m)

    def _cb_domain(self, t, x, q, u, p, s, m):
        try:
            text = self.model.domain(t, self._X.from_address(x)[:self._nx], self._q(q, u), self._uc, self.p, self._slack)
            if text is None:
                return PG_OK
            _write_text(PgMsg.from_address(m), str(text))
            return PG_RAISE
        except BaseException as exc:
            return self._fail(exc, m)

    def _scales(self, fn, out, n, m):
        try:
            lay = self._lib.layouts
            rows = list(fn(self.p))[:lay.max_scales]
            table = (lay.scale * lay.max_scales).from_address(out)
            keep = self._scale_keep = []
            for i, (label, names, value) in enumerate(rows):
                sc = table[i]
                keep.append(str(label).encode())
                sc.label = keep[-1]
                names = list(names)[:lay.max_scale_names]
                for j, name in enumerate(names):
                    keep.append(str(name).encode())
                    sc.names[j] = keep[-1]
                sc.n_names = len(names)
                sc.value = float(value)
            C.c_int.from_address(n).value = len(rows)
            return PG_OK
        except BaseException as exc:
            return self._fail(exc, m)

    def _cb_time_scales(self, p, out, n, m):
        return self._scales(self.model.time_scales, out, n, m)

    def _cb_error_scales(self, p, out, n, m):
        return self._scales(self.model.error_scales, out, n, m)

    def _cb_switch(self, text):
        self.new_switches.append(text.decode("utf-8", "replace"))


def _python_value(par, v: float):
    """A parameter's value as the model sees it: an integer parameter's an int, a Real one the
    double the adapter holds (as the native FMU's generated C sees it)."""
    return int(v) if par.integer and math.isfinite(v) else v


class Simulator(Binding):
    """The engine integrating one :class:`HybridModel` from ``t0`` on.

    ``p`` holds the model's parameters (missing ones take their defaults) and may hold solver
    settings too (an FMU's parameter table holds both); ``solver`` overrides settings
    (:mod:`.settings`).  ``self.p`` is the model's own parameters, the only ones its functions see;
    ``self.solver`` the settings.

    Event bookkeeping in constant memory: ``n_events``, ``last_event`` (an :class:`EventRecord` or
    None); the full history ``events`` only with ``keep_history`` (default: the setting
    ``log_events = 1``), and then ``new_events`` collects the events a caller has not taken yet (the
    FMI adapter logs and clears them after every call).  ``new_warnings`` collects warning texts (the
    work budget) the same way.
    """

    def __init__(self, model: HybridModel, p=None, u=None, t0: float = 0.0, t_stop: float = math.inf,
                 zeno_max_events: int = 200, zeno_window: float = 1e-6, keep_history: Optional[bool] = None,
                 solver=None):
        Binding.__init__(self, model, p, solver, u)
        p, s = self.p, self.solver
        keep = bool(s.log_events) if keep_history is None else bool(keep_history)
        self._history: Optional[List[EventRecord]] = [] if keep else None
        self.new_events: List[EventRecord] = []
        self.new_warnings: List[str] = []
        lib = self._lib
        self._engine = C.create_string_buffer(lib.pgb_sizeof())
        self._attach_engine()
        # (a value that is no number goes in as NaN: the rules, called back with the Python values,
        # refuse it in the engine's order with their own words)
        svals = [_number_or_nan(s[par.name]) for par in SOLVER_PARAMETERS]
        pvals = [_number_or_nan(p[par.name]) for par in model.parameters]
        rc = lib.pgb_init(self._engine, C.byref(self._struct), _doubles(pvals),
                          _doubles(svals), _doubles(self.u, len(model.inputs)), float(t0), float(t_stop),
                          int(zeno_max_events), float(zeno_window), int(keep), self._on_event, self._on_warning,
                          C.addressof(self._py))
        self._check(rc)
        self.n_events, self.last_event = -1, None  # (the first read takes the engine's)
        self._read()

    # ---- the callbacks ------------------------------------------------------------------------
    def _attach(self):
        """This run's PgModel (the binding) and the engine's buffers."""
        static = self._bind_model()
        self._attach_engine()
        return static

    def _attach_engine(self):
        """The buffers of this run's engine calls."""
        n = _READ_HEAD + 2 * self._nx + 2 * self._nq + self._nu
        self._buf = (C.c_double * n)()
        # the buffer read in one unpack (native doubles: the bits as they are; a ctypes slice costs
        # several times as much per item), where pgb_read puts x_out, q_out, x, q and u in it (the
        # slices built once), and the addresses the calls of every step pass (the engine and the
        # buffer stay where they are for this object's life: restore copies into the same engine bytes)
        self._unpack = struct.Struct(f"{n}d").unpack_from
        a = _READ_HEAD
        b, c, d, e = a + self._nx, a + self._nx + self._nq, a + 2 * self._nx + self._nq, n - self._nu
        self._slices = (slice(a, b), slice(b, c), slice(c, d), slice(d, e), slice(e, n))
        self._eaddr, self._baddr = C.addressof(self._engine), C.addressof(self._buf)
        self._ubuf = (C.c_double * max(self._nu, 1))()
        self._zbuf = (C.c_double * max(self._ne, 1))()
        self.sloped = False  # the inputs lie on a line (set_inputs with a slope), not held
        # the discrete state of the latest read, its dict, and where a float entry's zero could be
        # -0.0 (equal to 0.0 but other bits: read anew, not served from the cache)
        self._qlast, self._qlast_dict = None, None
        self._on_event = EVENT_HOOK(self._cb_event)
        self._on_warning = WARN_HOOK(self._cb_warning)

    def _cb_event(self, ctx, engine, ev, number):
        if self._history is None:
            return
        e = self._lib.layouts.event.from_address(ev)
        record = EventRecord(e.time, self.model.all_events()[e.index].name, e.index, list(e.x_before[:self._nx]),
                             list(e.x_after[:self._nx]))
        self._history.append(record)
        self.new_events.append(record)

    def _cb_warning(self, ctx, text):
        self.new_warnings.append(text.decode("utf-8", "replace"))

    # ---- calls ----------------------------------------------------------------------------
    def _check(self, rc):
        if rc == PG_OK:
            self._exc = None
            return
        text = self._lib.pgb_message(self._engine).decode("utf-8", "replace")
        exc, self._exc = self._exc, None
        if isinstance(exc, Exception) and _FUNCTION_FAILED.match(text):
            raise DomainError(text) from exc
        if exc is not None and (not isinstance(exc, ModelError) or str(exc) == text):
            raise exc
        raise _error_class(text)(text)

    def _read(self, filled=False):
        """Take the engine's served values into this object's attributes (``filled``: the call that
        just returned wrote them into the buffer already).  Called after every communication step:
        the buffer comes in one unpack, and the discrete state's dict of the latest read is served
        again while its values are the same (as :meth:`_qdict_of` would, without the call)."""
        if not filled:
            self._lib.pgb_read(self._eaddr, self._baddr)
        v = self._unpack(self._buf)
        (self.t_out, self.t, self.h, self.max_step, n_events, n_steps, n_rejected, has_last, last_time, last_index,
         due, by_differences) = v[:_READ_HEAD]
        self.n_steps, self.n_rejected = int(n_steps), int(n_rejected)
        self._due, self.jacobian_by_differences = due != 0.0, by_differences != 0.0  # (bool(v) of a float)
        s_x_out, s_q_out, s_x, s_q, s_u = self._slices
        self.x_out = list(v[s_x_out])
        q = v[s_q_out]  # (a tuple, as _qlast)
        self.q_out = self._qlast_dict if q == self._qlast and not self._qfloat else self._qdict_of(q)
        self.x = list(v[s_x])
        q = v[s_q]
        self.q = self._qlast_dict if q == self._qlast and not self._qfloat else self._qdict_of(q)
        self.u = v[s_u]
        if n_events != self.n_events or (has_last and self.last_event is None):
            self.n_events = int(n_events)
            if has_last:
                nx = self._nx
                xb, xa = (C.c_double * max(nx, 1))(), (C.c_double * max(nx, 1))()
                self._lib.pgb_last_event(self._engine, xb, xa)
                i = int(last_index)
                self.last_event = EventRecord(last_time, self.model.all_events()[i].name, i, xb[:nx], xa[:nx])
            else:
                self.last_event = None

    def next_time_event(self) -> float:
        """The next time event's instant (``inf``: none): FMI's ``nextEventTime``."""
        return self._lib.pgb_next_time_event(self._engine)

    def time_event_due(self, t: float) -> Optional[int]:
        """The event index of the first time event due at ``t`` (its instant reached), or None."""
        i = self._lib.pgb_time_event_due(self._engine, float(t))
        return None if i < 0 else i

    def _qdict_key(self, qd):
        return struct.pack(self._qfmt, *(float(qd[k]) for k, _ in self._layout))

    def _qdict_of(self, values):
        """The discrete state ``values`` as the model's dict: the latest read's while it is the same
        (the common case: a mode changes only at events), the callbacks' if it is theirs."""
        if values == self._qlast and not (self._qfloat and any(values[i] == 0.0 for i in self._qfloat)):
            return self._qlast_dict
        key = struct.pack(self._qfmt, *values)
        if key == self._qkey:
            qd = self._qdict
        else:
            qd = {k: _q_value(kind, v) for (k, kind), v in zip(self._layout, values)}
        self._qlast, self._qlast_dict = values, qd
        return qd

    @property
    def events(self) -> List[EventRecord]:
        """The full event history (only with ``keep_history`` / ``log_events = 1``)."""
        if self._history is None:
            raise RuntimeError("the full event history is kept only with log_events = 1 (or keep_history=True); "
                               "n_events and last_event are always available")
        return self._history

    @property
    def event_due(self) -> bool:
        """A located event's jump is pending at the time served last (after :meth:`advance_to_event`)."""
        return self._due

    @property
    def fun(self):
        """The flow in the current mode and inputs, ``f(t, x)`` (FMI 3.0 model exchange's derivatives)."""
        qd = self.q
        if qd is not self._qdict or self._uc != self.u:
            self._qkey, self._qdict, self._bound = self._qdict_key(qd), qd, None
            self._ukey, self._uc = None, self.u
            self._forget()
        return self._fun_for(qd)

    def advance(self, t_target: float):
        """Integrate to ``t_target`` (handling every event on the way); return ``(x, q)`` there."""
        self._check(self._lib.pgb_advance(self._eaddr, float(t_target), self._baddr))
        self._read(True)
        return self.x_out, self.q_out

    def advance_to_event(self, t_target: float) -> bool:
        """Like :meth:`advance`, but stop at the first event on the way, *before* its jump: True when
        an event lies in ``(t_out, t_target]`` (``t_out`` is then its exact time, the jump pending
        until the next :meth:`advance`); the step sequence is that of :meth:`advance`."""
        stopped = C.c_int()
        self._check(self._lib.pgb_advance_to_event(self._eaddr, float(t_target), C.byref(stopped), self._baddr))
        self._read(True)
        return bool(stopped.value)

    def set_input(self, u):
        """Change the inputs from the latest communication time on."""
        u = tuple(float(v) for v in u)
        if u == self.u and not self.sloped:
            return
        self._bound = None
        self._forget()
        rc = self._lib.pgb_set_input(self._engine, _doubles(u, self._nu))
        self._read()  # (the engine's inputs: the new ones, or the old where it refused them)
        if self.sloped:
            self.sloped = bool(self._lib.pgb_inputs_at(self._engine, self.t_out, self._ubuf))
        self._check(rc)

    def set_inputs(self, u, du):
        """Inputs on a line from the latest communication time ``t_c`` on: ``u + du (t - t_c)``
        (FMI 2.0 input derivatives); all ``du`` zero is :meth:`set_input`, to the bit."""
        if not any(du) and not self.sloped:
            self.set_input(u)
            return
        u = tuple(float(v) for v in u)
        self._bound = None
        self._forget()
        rc = self._lib.pgb_set_inputs(self._engine, _doubles(u, self._nu), _doubles(du, self._nu))
        self._read()
        self.sloped = bool(self._lib.pgb_inputs_at(self._engine, self.t_out, self._ubuf))
        self._check(rc)

    def inputs_at(self, t: float) -> tuple:
        """The inputs the model sees at ``t`` (computed by the engine: the same bits as its own calls)."""
        self._lib.pgb_inputs_at(self._engine, float(t), self._ubuf)
        return tuple(self._ubuf[:self._nu])

    def apply_event(self, index: int, t: float, x) -> list:
        """Apply the jump of event ``index`` at time ``t`` to the state ``x`` located by someone else
        (an FMI 3.0 model-exchange importer's solver); returns the new continuous state."""
        rc = self._lib.pgb_apply_event(self._engine, int(index), float(t), _doubles(x, self._nx))
        self._forget()
        self._check(rc)
        self._read()
        return self.x

    def me_indicators(self, t: float, x) -> list:
        """Model exchange: the event indicators an importer sees at ``(t, x)`` in the current mode,
        each guard's arming updated from this observation (the engine's rule, docs/solver.md "Event
        semantics": ``pg_engine_me_indicators``)."""
        self._check(self._lib.pgb_me_indicators(self._engine, float(t), _doubles(x, self._nx), self._zbuf))
        return self._zbuf[:self._ne]

    def me_fired(self, t: float, x) -> Optional[int]:
        """Model exchange: the index of the event that fires at ``(t, x)`` (one pending at ``t``, or
        the first armed guard on its after side, in priority order), None for none."""
        index = C.c_int(-1)
        self._check(self._lib.pgb_me_fired(self._engine, float(t), _doubles(x, self._nx), C.byref(index)))
        return None if index.value < 0 else index.value

    def restart_at(self, t: float, x, u) -> None:
        """Go on from the state ``x`` at time ``t`` given from outside (an FMI 3.0 model-exchange
        importer's solver) with the inputs ``u``: the step taken ahead and any located event are
        dropped."""
        u = tuple(float(v) for v in u)
        self.u, self._bound = u, None
        self._forget()
        self._check(self._lib.pgb_restart_at(self._engine, float(t), _doubles(x, self._nx), _doubles(u, self._nu)))
        self._read()

    def domain_problem(self, t: float, x) -> Optional[str]:
        """The model's domain condition at ``(t, x)`` in the current mode: None or its text."""
        return self.model.domain(t, x, self.q, self.u, self.p, self._slack)

    # ---- snapshots ----------------------------------------------------------------------------
    def snapshot(self):
        """A copy of the whole engine state (for fmi2GetFMUstate): the engine's bytes and this
        object's lists."""
        return {"model": self.model, "p": self.p, "solver": self.solver, "u": self.u,
                "engine": self._engine.raw,
                "history": None if self._history is None else list(self._history),
                "new_events": list(self.new_events), "new_warnings": list(self.new_warnings),
                "new_switches": list(self.new_switches)}

    def restore(self, snap):
        fresh = getattr(self, "_engine", None) is None or getattr(self, "model", None) is not snap["model"]
        self.model, self.p, self.solver, self.u = snap["model"], snap["p"], snap["solver"], tuple(snap["u"])
        self._history = None if snap["history"] is None else list(snap["history"])
        self.new_events, self.new_warnings = list(snap["new_events"]), list(snap["new_warnings"])
        self.new_switches = list(snap.get("new_switches", ()))
        if fresh:
            self._lib = library()
        lib = self._lib
        if fresh:
            self._engine = C.create_string_buffer(lib.pgb_sizeof())
            self._attach()
        raw = snap["engine"]
        if len(raw) != len(self._engine.raw):
            raise ModelError(f"the engine state has {len(raw)} bytes, not {len(self._engine.raw)}: it was taken "
                             f"from another build of the engine")
        C.memmove(self._engine, raw, len(raw))
        self._qkey = self._qdict = self._bound = self._ukey = None
        self._fill_py()  # (this snapshot's p; the cache dropped)
        lib.pgb_rebind(self._engine, C.byref(self._struct), self._on_event, self._on_warning, C.addressof(self._py))
        self._qlast = self._qlast_dict = None
        self._uc = self.u
        self.n_events = -1
        self.last_event = None
        self._read()
        self.sloped = bool(lib.pgb_inputs_at(self._engine, self.t_out, self._ubuf))


def snapshot_to_data(snap: dict) -> dict:
    """Plain data (JSON-able) of a :meth:`Simulator.snapshot`."""
    return {"params": snap["p"].as_dict(), "solver": snap["solver"].as_dict(), "u": list(snap["u"]),
            "engine": snap["engine"].hex(),
            "history": None if snap["history"] is None else [_event_data(e) for e in snap["history"]],
            "new_events": [_event_data(e) for e in snap["new_events"]], "new_warnings": list(snap["new_warnings"]),
            "new_switches": list(snap["new_switches"])}


def _event_data(e: EventRecord):
    return [e.time, e.name, e.index, list(e.x_before), list(e.x_after)]


def snapshot_from_data(model: HybridModel, data: dict) -> dict:
    """The :meth:`Simulator.snapshot` that :func:`snapshot_to_data` was made from."""
    return {"model": model, "p": Params(dict(data["params"])), "solver": Params(dict(data["solver"])),
            "u": tuple(data["u"]), "engine": bytes.fromhex(data["engine"]),
            "history": None if data["history"] is None else [EventRecord(*e) for e in data["history"]],
            "new_events": [EventRecord(*e) for e in data["new_events"]], "new_warnings": list(data["new_warnings"]),
            "new_switches": list(data.get("new_switches", ()))}


__all__ = ["EventRecord", "Simulator", "discrete_layout", "library", "snapshot_from_data", "snapshot_to_data",
           "use_library"]
