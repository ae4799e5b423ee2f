"""The master's hot path in C: the components of one level of the update order stepped by
``fmu_src/native/master/pg_level.c`` with the GIL released, on the ``--threads`` threads.

Per component of a batch, the C code sets the inputs from slots of one flat value array, saves
the FMU state (when the Python side asks), calls ``fmi2DoStep`` and reads the outputs back into
their slots — the FMU's own functions, whose addresses fmpy holds (:mod:`pogofmu.fmpy_raw`).
It reports per component an error status, or that its event counter changed over the step;
every decision about events stays in :mod:`.algorithms`.

The connected values then live in that array: :class:`SlotValues` is the mapping
``(component, variable) -> value`` of :class:`~.algorithms.Exchange` (``value`` and ``held``)
over it, integers as ints, so the Python paths (events, initialization, other components) read
and write the same values as the C one.

Served: FMI 2.0 co-simulation FMUs of pogofmu's native backend (their calls need no GIL), whose
inputs and watched outputs are reals and integers. Every other component (FMI 3.0, another
tool's FMU, a Python-hosted FMU) keeps the Python path. An input taken as a line over the step
(Gauss-Seidel with ``--inputs interpolate``) is set in C as :meth:`~.algorithms.Exchange.feed`
sets it: the source's value at the macro step's start (a slot :meth:`NativeLevels.mark` fills)
with the slope to its value now over the time the source has stepped (a slot per source that
:meth:`Batch.go` fills), the same doubles in the same calls. ``POGOFMU_SSP_NATIVE_LEVELS=0``
turns the C path off (the tests compare the two to the bit); without a C compiler it is off.

Host-side code; never imported inside an FMU.
"""
from __future__ import annotations

import ctypes
import os
import threading
from typing import Dict, List, Optional

from .components import REAL_TYPES, Fmi2CoSimulation, _call_failed

INT_TYPES = ("Integer", "Int32", "Int16", "Int8", "UInt8", "UInt16", "UInt32", "Enumeration")  # exact in a double
FMI2_INT = ("Integer", "Enumeration")
# pg_level.c's enums (tests/test_ssp_native_layout.py compares them with the C source)
OP_FEED, OP_SAVE, OP_STEP, OP_READ = 1, 2, 4, 8  # what a component's turn in a C call does
CALL_SET_REAL, CALL_SAVE, CALL_STEP, CALL_GET_REAL, CALL_SET_INT, CALL_GET_INT, CALL_SET_DERIV = range(1, 8)
# a component's result code: 0 done, 1 done and its event counter changed, -1 not run (another
# failed); else the failed call << 8 | its FMI status (> 1)
CODE_DONE, CODE_EVENT, CODE_NOT_RUN = 0, 1, -1
CALLS = {CALL_SET_REAL: ("setting its inputs", "fmi2SetReal"), CALL_SET_INT: ("setting its inputs", "fmi2SetInteger"),
         CALL_SET_DERIV: ("setting its inputs", "fmi2SetRealInputDerivatives"),
         CALL_SAVE: ("saving its state", "fmi2GetFMUstate"), CALL_STEP: ("step", "fmi2DoStep"),
         CALL_GET_REAL: ("reading its outputs", "fmi2GetReal"), CALL_GET_INT: ("reading its outputs", "fmi2GetInteger")}


def failed_call(code: int) -> int:
    """The call (``CALL_*``) whose error a result code reports."""
    return code >> 8


def failed_after_step(code: int) -> bool:
    """Whether the error a result code reports came after the step was made (reading the outputs)."""
    return failed_call(code) in (CALL_GET_REAL, CALL_GET_INT)

_P = ctypes.c_void_p
_IP = ctypes.POINTER(ctypes.c_int)
_UP = ctypes.POINTER(ctypes.c_uint)
_DP = ctypes.POINTER(ctypes.c_double)


class PgmComp(ctypes.Structure):
    """``pgm_comp`` of pg_level.c (keep the two in step)."""

    _fields_ = [("instance", _P), ("do_step", _P), ("set_real", _P), ("get_real", _P), ("set_int", _P),
                ("get_int", _P), ("get_state", _P), ("set_deriv", _P), ("state", _P),
                ("n_in_real", ctypes.c_int), ("n_in_int", ctypes.c_int), ("n_out_real", ctypes.c_int),
                ("n_out_int", ctypes.c_int), ("int_first", ctypes.c_int),
                ("in_real_vr", _UP), ("in_real_src", _IP), ("in_real_held", _IP), ("in_real_buf", _DP),
                ("in_int_vr", _UP), ("in_int_src", _IP), ("in_int_held", _IP), ("in_int_buf", _IP),
                ("out_real_vr", _UP), ("out_real_slot", _IP), ("out_real_buf", _DP),
                ("out_int_vr", _UP), ("out_int_slot", _IP), ("out_int_buf", _IP),
                ("event_slot", ctypes.c_int),
                ("in_real_start", _IP), ("in_real_span", _IP), ("line_vr", _UP), ("line_order", _IP),
                ("line_buf", _DP)]


_LIB = None


def library():
    """The compiled pg_level.c (None when it cannot be had: no C compiler, or turned off)."""
    global _LIB
    if os.environ.get("POGOFMU_SSP_NATIVE_LEVELS", "1").strip() in ("0", "off", "no", "false"):
        return None
    if _LIB is None:
        try:
            from pogofmu.codegen.build import CompileError, host_level_library

            lib = ctypes.CDLL(str(host_level_library()))  # CDLL: every call releases the GIL
        except (ImportError, OSError, CompileError):
            _LIB = False
            return None
        lib.pgm_pool_new.restype = _P
        lib.pgm_pool_new.argtypes = [ctypes.c_int]
        lib.pgm_pool_free.restype = None
        lib.pgm_pool_free.argtypes = [_P]
        lib.pgm_run.restype = ctypes.c_int
        lib.pgm_run.argtypes = [_P, ctypes.c_int, ctypes.c_int, _P, _P, ctypes.c_double, ctypes.c_double,
                                ctypes.c_double, _P, _P, _P, _P]
        lib.pgm_pool_csv_rows.restype = ctypes.c_long
        lib.pgm_pool_csv_rows.argtypes = [_P, _P, ctypes.c_long, ctypes.c_int, _P, _P, ctypes.c_long,
                                          ctypes.POINTER(ctypes.c_long)]
        lib.pgm_run_levels.restype = ctypes.c_int
        lib.pgm_run_levels.argtypes = [_P, ctypes.c_int, ctypes.c_int, _P, _P, _P, ctypes.c_double, ctypes.c_double,
                                       ctypes.c_double, _P, _P, _P, _P, _P]
        _LIB = lib
    return _LIB or None


class SlotValues:
    """A mapping ``key -> value`` whose numeric keys live in slots of a shared double array (an
    integer slot reads back as an int); other keys (booleans, strings) in a dict."""

    __slots__ = ("index", "ints", "arr", "known", "other")

    def __init__(self, index: Dict[tuple, int], ints: bytearray, arr, known):
        self.index, self.ints, self.arr, self.known, self.other = index, ints, arr, known, {}

    def __getitem__(self, key):
        i = self.index.get(key)
        if i is None:
            return self.other[key]
        if not self.known[i]:
            raise KeyError(key)
        return int(self.arr[i]) if self.ints[i] else self.arr[i]

    def get(self, key, default=None):
        i = self.index.get(key)
        if i is None:
            return self.other.get(key, default)
        if not self.known[i]:
            return default
        return int(self.arr[i]) if self.ints[i] else self.arr[i]

    def __setitem__(self, key, value):
        i = self.index.get(key)
        if i is None:
            self.other[key] = value
        else:
            self.arr[i] = value
            self.known[i] = 1

    def __contains__(self, key):
        i = self.index.get(key)
        return key in self.other if i is None else bool(self.known[i])


def _array(ctype, values):
    return (ctype * max(len(values), 1))(*values)


def _address(fn) -> int:
    return ctypes.cast(fn, _P).value


class NativeLevels:
    """The C stepping of the components it can serve, and the flat value array of an
    :class:`~.algorithms.Exchange` (built by it when :func:`library` is available)."""

    def __init__(self, lib, ex, threads: int):
        self.lib, self.ex = lib, ex
        index, ints = {}, bytearray()

        def slot(key, type_):
            index[key] = len(ints)
            ints.append(type_ not in REAL_TYPES)
        for inst in ex.order:
            for name, var in (getattr(inst, "variables", None) or {}).items():
                if var.type in REAL_TYPES or var.type in INT_TYPES:
                    slot((inst.name, name), var.type)
        held = {}
        for c in ex.system.connections:
            end = ex.instances.get(c.end_element)
            var = (getattr(end, "variables", None) or {}).get(c.end_connector)
            if var is not None and (var.type in REAL_TYPES or var.type in INT_TYPES):
                held[(c.end_element, c.end_connector)] = len(ints)
                ints.append(var.type not in REAL_TYPES)
        # input lines (--inputs interpolate): a slot for the value at the macro step's start of
        # every real output that feeds a component able to interpolate, and one per component for
        # the time it has stepped since that start
        start, span = {}, {}
        for c in ex.system.connections:
            end = ex.instances.get(c.end_element)
            key = (c.start_element, c.start_connector)
            if getattr(end, "can_interpolate", False) and key in index and not ints[index[key]] \
                    and key not in start:
                start[key] = len(ints)
                ints.append(False)
        for inst in ex.order:
            span[inst.name] = len(ints)
            ints.append(False)
        n = max(len(ints), 1)
        self.arr = (ctypes.c_double * n)()
        self.known = (ctypes.c_ubyte * n)()
        self.value = SlotValues(index, ints, self.arr, self.known)
        self.held = SlotValues(held, ints, self.arr, self.known)
        self.start = SlotValues(start, ints, self.arr, self.known)  # Exchange._start, when it marks
        self.span = span
        self._marks = None
        self.pool = lib.pgm_pool_new(threads) if threads > 1 else None
        self.parallel = 1 if self.pool else 0
        self._pool_lock = threading.Lock()  # csv_rows (another thread) against close
        self._plans: Dict[str, Optional[tuple]] = {}
        self._batches = {}
        self._macros = {}
        self._capable = {inst.name: self._can_serve(inst) for inst in ex.order}

    def close(self):
        with self._pool_lock:
            if self.pool:
                self.lib.pgm_pool_free(self.pool)
                self.pool = None

    def mark_time(self) -> float:
        """The macro step's start of the input lines for the C calls (NaN: no lines)."""
        t_mark = self.ex.t_mark
        return t_mark if t_mark is not None else float("nan")

    def csv_rows(self, *args) -> int:
        """``pgm_csv_rows(*args)`` (pg_csv.c) for the recording's writer thread: formatted by the
        pool's workers between their batches (pgm_pool_csv_rows: the writer waits asleep, and is not
        a third thread on the cores beside the pool's), or by the calling thread when there is no
        pool (any more)."""
        with self._pool_lock:
            if self.pool:
                return self.lib.pgm_pool_csv_rows(self.pool, *args)
        return self.lib.pgm_csv_rows(*args)

    # ---- which components ----------------------------------------------------------------------
    def _can_serve(self, inst) -> bool:
        if type(inst) is not Fmi2CoSimulation or inst.events is None:  # (pogofmu.ssp.components.pogofmu_events)
            return False
        if not getattr(inst.md, "buildConfigurations", None):  # native pogofmu FMUs list their C sources
            return False
        for c in self.ex.incoming[inst.name]:
            src = self.ex.instances.get(c.start_element)
            t_in = inst.type_of(c.end_connector)
            t_src = src.type_of(c.start_connector) if src is not None and hasattr(src, "variables") else None
            if not (t_in in REAL_TYPES and t_src in REAL_TYPES or t_in in FMI2_INT and t_src in FMI2_INT):
                return False
        return True

    def serves(self, inst) -> bool:
        if not self._capable.get(inst.name):
            return False
        if getattr(inst, "rollback", False) and not inst.counts_events:
            return False  # another tool's events: bisected in Python
        return self._plan(inst) is not None

    def lines_changed(self):
        """:meth:`~.algorithms.Exchange.interpolate_inputs` chose the input lines: the plans are
        made again."""
        self._plans.clear()
        self._batches.clear()
        self._macros.clear()
        self._marks = None

    def mark(self, keys):
        """The values of ``keys`` (outputs) copied into their start slots (``self.start``)."""
        if self._marks is None:
            import numpy as np

            self._marks = (np.ctypeslib.as_array(self.arr), np.ctypeslib.as_array(self.known),
                           np.array([self.value.index[k] for k in keys], dtype=np.intp),
                           np.array([self.start.index[k] for k in keys], dtype=np.intp))
        arr, known, src, dst = self._marks
        arr[dst] = arr[src]
        known[dst] = known[src]

    def forget(self, inst):
        """The variables read with the outputs of ``inst`` changed: its plan is made again."""
        self._plans.pop(inst.name, None)
        self._batches.clear()
        self._macros.clear()

    def _plan(self, inst):
        plan = self._plans.get(inst.name, 0)
        if plan != 0:
            return plan
        ex, idx, hidx = self.ex, self.value.index, self.held.index
        ins = {"real": ([], [], []), "int": ([], [], [])}
        first = None
        lines = ex.input_lines(inst.name)
        line_start, line_span, sources = [], [], []
        for c in ex.incoming[inst.name]:
            kind = "real" if inst.type_of(c.end_connector) in REAL_TYPES else "int"
            first = first or kind
            vrs, src, held = ins[kind]
            vrs.append(inst.vr(c.end_connector))
            src.append(idx[(c.start_element, c.start_connector)])
            held.append(hidx[(c.end_element, c.end_connector)])
            if kind == "real":
                lined = c.end_connector in lines
                line_start.append(self.start.index[(c.start_element, c.start_connector)] if lined else -1)
                line_span.append(self.span[c.start_element] if lined else -1)
                if lined and c.start_element not in sources:
                    sources.append(c.start_element)
        outs = {"real": ([], []), "int": ([], [])}
        for name in ex.watch[inst.name]:
            t = inst.type_of(name)
            kind = "real" if t in REAL_TYPES else "int" if t in FMI2_INT else None
            if kind is None:
                self._plans[inst.name] = None
                return None
            outs[kind][0].append(inst.vr(name))
            outs[kind][1].append(idx[(inst.name, name)])
        fmu = inst.fmu
        from pogofmu.fmpy_raw import raw_function

        s = PgmComp()
        keep = []

        def arr(ctype, values):
            a = _array(ctype, values)
            keep.append(a)
            return ctypes.cast(a, ctypes.POINTER(ctype))
        s.instance = fmu.component
        for field, name in (("do_step", "fmi2DoStep"), ("set_real", "fmi2SetReal"), ("get_real", "fmi2GetReal"),
                            ("set_int", "fmi2SetInteger"), ("get_int", "fmi2GetInteger")):
            setattr(s, field, _address(raw_function(fmu, name)))
        if inst.can_save:
            s.get_state = _address(raw_function(fmu, "fmi2GetFMUstate"))
        (rv, rs, rh), (iv, is_, ih) = ins["real"], ins["int"]
        s.n_in_real, s.n_in_int, s.int_first = len(rv), len(iv), first == "int"
        s.in_real_vr, s.in_real_src, s.in_real_held = arr(ctypes.c_uint, rv), arr(ctypes.c_int, rs), arr(ctypes.c_int, rh)
        s.in_real_buf = arr(ctypes.c_double, [0.0] * len(rv))
        s.in_int_vr, s.in_int_src, s.in_int_held = arr(ctypes.c_uint, iv), arr(ctypes.c_int, is_), arr(ctypes.c_int, ih)
        s.in_int_buf = arr(ctypes.c_int, [0] * len(iv))
        (orv, ors), (oiv, ois) = outs["real"], outs["int"]
        s.n_out_real, s.n_out_int = len(orv), len(oiv)
        s.out_real_vr, s.out_real_slot = arr(ctypes.c_uint, orv), arr(ctypes.c_int, ors)
        s.out_real_buf = arr(ctypes.c_double, [0.0] * len(orv))
        s.out_int_vr, s.out_int_slot = arr(ctypes.c_uint, oiv), arr(ctypes.c_int, ois)
        s.out_int_buf = arr(ctypes.c_int, [0] * len(oiv))
        counts = getattr(inst, "rollback", False) and inst.counts_events and "n_events" in ex.watch[inst.name]
        s.event_slot = idx[(inst.name, "n_events")] if counts else -1
        if sources:  # inputs taken as lines over the step
            s.set_deriv = _address(raw_function(fmu, "fmi2SetRealInputDerivatives"))
            s.in_real_start, s.in_real_span = arr(ctypes.c_int, line_start), arr(ctypes.c_int, line_span)
            s.line_vr, s.line_order = arr(ctypes.c_uint, [0] * len(rv)), arr(ctypes.c_int, [1] * len(rv))
            s.line_buf = arr(ctypes.c_double, [0.0] * len(rv))
        names = [c.end_connector for c in ex.incoming[inst.name]]
        plan = self._plans[inst.name] = (s, keep, names, sources)
        return plan

    # ---- running a batch --------------------------------------------------------------------------
    def batch(self, insts, feed, save) -> "Batch":
        """The C call for ``insts`` (cached): ``feed`` None: set the inputs only; else step and
        read, setting the inputs first if ``feed``, saving first those that must if ``save``."""
        key = (tuple(insts), feed, save)
        b = self._batches.get(key)
        if b is None:
            b = self._batches[key] = Batch(self, insts, feed, save)
        return b

    def macro(self, levels) -> Optional["Macro"]:
        """The one C call of a Gauss-Seidel macro step over ``levels`` (cached), or None when a
        component of them is not served (see :meth:`~.algorithms.Exchange.step_levels`)."""
        key = tuple(map(tuple, levels))
        m = self._macros.get(key, 0)
        if m == 0:
            batches = [self.batch(level, True, True) for level in levels]
            m = Macro(self, batches) if all(b.run is not None and not b.slow for b in batches) else None
            self._macros[key] = m
        return m

    def error(self, inst, code, t, h):
        """The master's error for a failed call of ``inst`` in C (as the Python path words it)."""
        what, function = CALLS[failed_call(code)]
        exc = _call_failed(function, code & 0xFF)
        if what == "step":
            what = f"fmi2DoStep from t = {t:.10g} s (step {h:g} s)"
        elif what == "setting its inputs":
            what = f"setting its inputs {self._plan(inst)[2]} at t = {inst.t!r} s"
        elif what == "reading its outputs":
            what = f"reading its outputs at t = {inst.t!r} s"
        return inst.fail(what, exc)


class Batch:
    """One C call over the served components of a list (``pos``: their places in it, ``fast``
    them, ``saving`` those saved before their step, ``slow``: the places of the others)."""

    def __init__(self, nat: NativeLevels, insts, feed, save):
        self.nat, self.pos, self.fast, self.saving, self.slow = nat, [], [], [], []
        ops = []
        base = OP_FEED if feed is None else (OP_FEED if feed else 0) | OP_STEP | OP_READ
        for k, inst in enumerate(insts):
            saving = feed is not None and save and inst.must_save
            # served: a component that keeps a journal of its calls for a restore is saved here
            # (only the components that must save keep one: Component.save)
            if nat.serves(inst) and (saving or not inst.journaling):
                self.pos.append(k)
                self.fast.append(inst)
                ops.append(base | OP_SAVE if saving else base)
                if saving:
                    self.saving.append(inst)
                    nat._plan(inst)[0].state = inst.state_address()  # (the C code saves into it)
            else:
                self.slow.append(k)
        n = len(self.fast)
        self.run = None
        # the sources of the served components' input lines: (component, its span slot)
        names = dict.fromkeys(src for inst in self.fast for src in nat._plan(inst)[3]) if feed else {}
        self.sources = [(nat.ex.instances[name], nat.span[name]) for name in names]
        if n:
            self.args = (nat.pool, nat.parallel if feed is not None else 0, n,
                         (ctypes.POINTER(PgmComp) * n)(*[ctypes.pointer(nat._plan(i)[0]) for i in self.fast]),
                         (ctypes.c_ubyte * n)(*ops))
            self.before, self.result = (ctypes.c_double * n)(), (ctypes.c_int * n)()
            self.run = nat.lib.pgm_run

    def go(self, t, h):
        """Run it: ``[(index in fast, code, event counter before)]`` of the components whose code
        is not 0 (1: the event counter changed; -1: not run, another failed; else the failed
        call << 8 | its status)."""
        pool, parallel, n, comps, ops = self.args
        nat = self.nat
        t_mark = nat.ex.t_mark
        if self.sources and t == t_mark:  # lines: the time each source has stepped since the start
            arr = nat.arr
            for src, slot in self.sources:
                arr[slot] = src.t - t_mark
        if not self.run(pool, parallel, n, comps, ops, t, h, nat.mark_time(), nat.arr, nat.known, self.before,
                        self.result):
            return ()
        return self.bad()

    def bad(self):
        """After its C call: ``[(index in fast, code, event counter before)]`` of the components
        whose code is not 0 (see :meth:`go`)."""
        result, before = self.result, self.before
        return [(i, result[i], before[i]) for i in range(len(self.fast)) if result[i] != 0]


class Macro:
    """The levels of a Gauss-Seidel macro step in one C call (pgm_run_levels): the :class:`Batch`
    of each level, run one after the other with the GIL released."""

    def __init__(self, nat: NativeLevels, batches):
        self.nat, self.batches = nat, batches
        n = len(batches)

        def pointers(arrays):
            return (_P * n)(*[ctypes.addressof(a) for a in arrays])
        # each component's span slot: the time it has stepped, read by the input lines of later levels
        spans = [(ctypes.c_int * len(b.fast))(*[nat.span[inst.name] for inst in b.fast]) for b in batches]
        self._keep = spans
        self.args = (n, (ctypes.c_int * n)(*[len(b.fast) for b in batches]), pointers([b.args[3] for b in batches]),
                     pointers([b.args[4] for b in batches]))
        self.tail = (pointers([b.before for b in batches]), pointers([b.result for b in batches]), pointers(spans))
        self.run = nat.lib.pgm_run_levels

    def go(self, t, h):
        """Run it: ``(stop, bad)``: the index of the level it stopped after (the number of levels
        when every result was 0) and that level's components whose code is not 0 (as
        :meth:`Batch.go`)."""
        nat = self.nat
        stop = self.run(nat.pool, nat.parallel, *self.args, t, h, nat.mark_time(), nat.arr, nat.known, *self.tail)
        return stop, (self.batches[stop].bad() if stop < len(self.batches) else ())
