"""The master algorithms: how the components of a system advance together in time.

* :func:`fixed_step` — Gauss–Seidel (in update order) or Jacobi with a fixed communication step
  (``--events off``: the algorithm of libcosim and fmpy's ``simulate_ssp``);
* :func:`synchronized` — the fixed grid, but every component is brought to each event's instant
  (``--events on``, the default): step, detect, locate, synchronize, iterate the event;
* :func:`model_exchange` — the strongly coupled solution (``--algorithm model-exchange``, in
  :mod:`.coupled`).

The components are :mod:`.components`; :class:`Exchange` moves the connected values between
them and writes the rows.
"""
from __future__ import annotations

import math
import time as _time
from fractions import Fraction
from operator import attrgetter
from typing import Dict, List

from .components import REAL_TYPES, StepResult
from .native_level import failed_after_step
from .package import SSPError

INPUTS = ("hold", "interpolate")  # --inputs: how a Gauss-Seidel component sees the inputs over a step
MAX_EVENT_ITERATIONS = 100  # discrete iterations at one instant before the master gives up
GRID, LEFT, RIGHT = 0, -1, 1  # the ``event`` column: output grid, left and right limit at an event
_TIME = attrgetter("t")


class Exchange:
    """The connections of a system: the latest value of every output connector, the value held on
    every input, and the rows written from them (``event`` column: 0 grid, -1 / +1 the left and
    right limits at an event instant)."""

    def __init__(self, system, instances: Dict[str, object], order: List[str], record, threads: int = 1,
                 columns=None):
        self.system = system
        self.instances = instances
        self.order = [instances[n] for n in order]
        self.record = record
        incoming = {n: [] for n in order}
        for c in system.connections:
            if c.end_element in incoming:
                incoming[c.end_element].append(c)
        self.incoming = incoming
        self.outputs = {n: [c.name for c in system.components[n].connectors.values() if c.kind != "input"]
                        for n in order}
        self.watch = {n: list(self.outputs[n]) for n in order}  # read with the outputs (see watch())
        self.value = {}  # (component, connector) -> latest output value
        self.held = {}  # (component, connector) -> value set on the input
        self.source = {(c.end_element, c.end_connector): (c.start_element, c.start_connector)
                       for c in system.connections}
        # the recorded columns (``columns``: those --record selects; default every connector), each
        # read from ``value`` by one key: an input's is its source's (None: an unconnected input)
        self.columns = columns if columns is not None else \
            [(n, c) for n in order for c in system.components[n].connectors.values()]
        self._row_keys = [self.source.get((n, c.name)) if c.kind == "input" else (n, c.name)
                          for n, c in self.columns]
        self._keyed = all(k is not None for k in self._row_keys)
        self.levels = update_levels(self.order, incoming)
        self.threads = max(1, int(threads))
        self._pool = None
        # --inputs interpolate: component -> its real input connections it takes as lines over a
        # step (Gauss-Seidel, FMUs with canInterpolateInputs); set by interpolate_inputs()
        self._lines = {}
        self._start_keys = []
        self._start = {}  # the outputs feeding them at the macro step's start t_mark
        self.t_mark = None
        self.event_sources = []  # [(t, components whose event it was)], one per event instant
        self.native = None  # the C stepping of the components it serves (.native_level)
        from .native_level import NativeLevels, library

        lib = library()
        if lib is not None:
            native = NativeLevels(lib, self, self.threads)
            if any(native.serves(inst) for inst in self.order):
                self.native, self.value, self.held = native, native.value, native.held
                self._row_arrays()
            else:
                native.close()

    def interpolate_inputs(self):
        """Gauss-Seidel with ``--inputs interpolate``: every component that can interpolate its
        inputs (FMI 2.0 canInterpolateInputs) gets each real input whose source has already
        stepped in the macro step as a line, its source's value at the step's start and the slope
        to its value at the source's time: ``u(t) = u(t_mark) + (u_src - u(t_mark)) (t - t_mark) /
        (t_src - t_mark)``. Inputs from sources that step later stay held."""
        keys = set()
        for inst in self.order:
            if not getattr(inst, "can_interpolate", False):
                continue
            lines = {c.end_connector for c in self.incoming[inst.name] if inst.type_of(c.end_connector) in REAL_TYPES}
            if lines:
                self._lines[inst.name] = lines
                keys.update((c.start_element, c.start_connector) for c in self.incoming[inst.name]
                            if c.end_connector in lines)
        self._start_keys = sorted(keys)
        if self.native is not None:  # the start values in slots of the C value array, the lines in C
            self._start = self.native.start
            self.native.lines_changed()

    def mark(self, t):
        """A macro step starts at ``t`` (every output read there): the start of the input lines."""
        if self._lines:
            self.t_mark = t
            if self.native is not None:
                self.native.mark(self._start_keys)
            else:
                v = self.value
                self._start = {k: v[k] for k in self._start_keys}

    # ---- parallel steps --------------------------------------------------------------------
    def map(self, fn, insts) -> list:
        """``[fn(inst) for inst in insts]``, on ``threads`` threads when there are several
        (``insts`` must be independent: separate instances none of which feeds another within
        the call). Every call has ended when this returns; the first failure in ``insts``'s order
        is raised. The results do not depend on the thread count: each call does what it would do
        alone, on its own instance (the FMI calls of native FMUs release the GIL)."""
        k = min(self.threads, len(insts))
        if k <= 1 or self._in_c(insts):
            return [fn(inst) for inst in insts]
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(self.threads - 1, thread_name_prefix="pogofmu-step")
        chunks = [range(i, len(insts), k) for i in range(k)]
        out = [None] * len(insts)
        failed = {}

        def run(idx):
            for i in idx:
                try:
                    out[i] = fn(insts[i])
                except BaseException as exc:  # noqa: BLE001 - raised below, in order
                    failed[i] = exc
                    return
        futures = [self._pool.submit(run, c) for c in chunks[1:]]
        try:
            run(chunks[0])
        finally:
            for f in futures:
                f.result()  # (run never raises: every call has ended here)
        if failed:
            raise failed[min(failed)]
        return out

    def _in_c(self, insts) -> bool:
        """Every one of ``insts`` is stepped by the C level call: its calls outside it (at events)
        are a few microseconds each, which Python threads would only hand the GIL around."""
        nat = self.native
        return nat is not None and all(nat.serves(inst) for inst in insts)

    def step_level(self, insts, t, h, feed, fallback, save=False, on_event=None) -> list:
        """``[fallback(inst) for inst in insts]`` (independent components, as :meth:`map`), where
        ``fallback`` does on one component: ``feed`` its inputs, save its state if ``save`` and it
        must (``must_save``), step from ``t`` by ``h``, read its outputs. The components the C code
        serves (:mod:`.native_level`) do exactly those calls there, all in one call with the GIL
        released, and give a :class:`StepResult` of the step's end, or ``on_event(inst,
        n_events before the step)`` where their event counter changed; the others run
        ``fallback``. The first failure in ``insts``'s order is raised."""
        nat = self.native
        if nat is None:
            return self.map(fallback, insts)
        batch = nat.batch(insts, feed, save)
        if batch.run is None:
            return self.map(fallback, insts)
        return self._finish(batch, insts, t, h, batch.go(t, h), fallback, on_event)

    def step_levels(self, levels, t, h, on_event):
        """A Gauss-Seidel macro step of whole ``levels`` (every component at ``t``, fed with
        lines, saved where it must, stepped by ``h`` and read) as one C call when the C code serves
        every component: the :meth:`step_level` results of the levels it ran, which end with the
        first level that has an event or a failure (the later levels are not stepped); None when
        it cannot (the caller steps level by level)."""
        nat = self.native
        macro = nat.macro(levels) if nat is not None else None
        if macro is None:
            return None
        stop, bad = macro.go(t, h)
        return [self._finish(b, level, t, h, bad if k == stop else (), None, on_event)
                for k, (b, level) in enumerate(zip(macro.batches[:stop + 1], levels))]

    def _finish(self, batch, insts, t, h, bad, fallback, on_event) -> list:
        """After a C call of ``batch``: its components' times and journals, the others stepped by
        ``fallback``, the results (see :meth:`step_level`)."""
        nat = self.native
        end = t + h
        entry = (True, t, h)
        for inst in batch.saving:  # the FMU state itself saved at t, then the step (see Component.save)
            inst.saved_in_c(entry)
        for inst in batch.fast:
            inst.t = end
        out = [StepResult(end)] * len(insts)  # (one object: nobody changes a step's result)
        errors = []
        for k, code, before in bad:
            inst = batch.fast[k]
            if code > 1:
                inst.t = end if failed_after_step(code) else t
                errors.append((batch.pos[k], nat.error(inst, code, t, h)))
            elif code == 1:
                out[batch.pos[k]] = on_event(inst, before)
            # (code -1: not run, another component failed)
        if batch.slow:
            failed = []

            def guarded(k):
                try:
                    return fallback(insts[k])
                except BaseException:
                    failed.append(k)
                    raise
            try:
                for k, r in zip(batch.slow, self.map(guarded, batch.slow)):
                    out[k] = r
            except BaseException as exc:  # noqa: BLE001 - raised below, in order
                errors.append((min(failed) if failed else -1, exc))
        if errors:
            raise min(errors, key=lambda e: e[0])[1]
        return out

    def prepare(self, levels, feed, save=False):
        """The C calls of these levels made before the run's first row (as :meth:`step_level` with
        ``feed`` and ``save`` would make them at the first step): their set-up is not a cost of the
        macro steps."""
        if self.native is not None:
            for level in levels:
                self.native.batch(level, feed, save)

    def feed_all(self, insts):
        """:meth:`feed` every one of ``insts`` (Jacobi: all inputs from the same outputs; those
        the C code serves in one call)."""
        nat = self.native
        if nat is None:
            for inst in insts:
                self.feed(inst)
            return
        batch = nat.batch(insts, None, False)
        bad = batch.go(0.0, 0.0) if batch.run is not None else ()
        for k, code, _ in bad:
            if code > 1:
                raise nat.error(batch.fast[k], code, 0.0, 0.0)
        for k in batch.slow:
            self.feed(insts[k])

    def close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        if self.native is not None:
            self.native.close()

    def takes_lines(self, inst) -> bool:
        """Whether ``inst`` takes some of its inputs as lines over a step (:meth:`interpolate_inputs`)."""
        return inst.name in self._lines

    def input_lines(self, name) -> tuple:
        """The input connectors component ``name`` takes as lines over a step (empty: none)."""
        return self._lines.get(name, ())

    def ready(self, inst) -> bool:
        """Every input of ``inst`` has a source value."""
        return all((c.start_element, c.start_connector) in self.value for c in self.incoming[inst.name])

    def feed(self, inst, only=None, continuous=False, lines=False, slopes=False) -> bool:
        """Set the inputs of ``inst`` from the latest outputs (``only``: of those components;
        ``continuous``: the real-valued inputs only, as FMI 3.0 allows in Continuous-Time Mode;
        ``lines``: a Gauss-Seidel step from the macro step's start, see :meth:`interpolate_inputs`;
        ``slopes``: the latest values, each with the slope of its line from the macro step's start,
        for a step inside the macro step); True if any value changed."""
        names, values, changed = [], [], False
        lined = self._lines.get(inst.name) if (lines and inst.t == self.t_mark) or slopes else None
        slope_names, slope_values = [], []
        for c in self.incoming[inst.name]:
            if only is not None and c.start_element not in only:
                continue
            if continuous and inst.type_of(c.end_connector) not in REAL_TYPES:
                continue
            src = (c.start_element, c.start_connector)
            v = self.value[src]
            if lined is not None and c.end_connector in lined:
                span = self.instances[c.start_element].t - self.t_mark
                if span > 0:  # the source has stepped: the line from its value at the start
                    v0 = self._start[src]
                    slope_names.append(c.end_connector)
                    slope_values.append((v - v0) / span)
                    if not slopes:
                        v = v0
            key = (c.end_element, c.end_connector)
            changed |= self.held.get(key) != v
            self.held[key] = v
            names.append(c.end_connector)
            values.append(v)
        if names:
            try:
                inst.set_values(names, values)
                if slope_names:
                    inst.set_input_slopes(slope_names, slope_values)
            except Exception as exc:  # noqa: BLE001 - fmpy raises FMICallException on an error status
                raise inst.fail(f"setting its inputs {names} at t = {inst.t!r} s", exc) from None
        return changed

    def also_read(self, inst, names):
        """Read these variables of ``inst`` with its outputs, into ``value`` (one FMI call per type)."""
        self.watch[inst.name] += [n for n in names if n not in self.watch[inst.name]]
        if self.native is not None:
            self.native.forget(inst)

    def read(self, inst) -> bool:
        """Read the output connectors of ``inst`` (and what :meth:`also_read` added); True if any
        value changed."""
        names = self.watch[inst.name]
        if not names:
            return False
        try:
            values = inst.get_values(names)
        except Exception as exc:  # noqa: BLE001
            raise inst.fail(f"reading its outputs at t = {inst.t!r} s", exc) from None
        changed = False
        for n, v in zip(names, values):
            key = (inst.name, n)
            changed |= self.value.get(key) != v
            self.value[key] = v
        return changed

    _put_row = None  # the recorder's own copy of a row from the C value array (_row_arrays)
    _row_known = False  # every recorded slot has had a value (they keep one: no slot is ever unset)

    def _all_known(self) -> bool:
        self._row_known = bool(self._np_known[self._row_slots].all())
        return self._row_known

    def row(self, t: float, kind: int = GRID):
        """One row: every output, and every input with the value it holds from here on (its
        source's latest value; an unconnected input its own)."""
        put = self._put_row
        if put is not None and type(t) is float and (self._row_known or self._all_known()):
            put(t, kind)  # no Python list: the slots copied into the recorder's block (CSVStream.bind_slots)
            return
        self.record.add(self.row_values(t, kind))

    def _row_arrays(self):
        """The recorded columns as slots of the C value array (numpy views), when all have one."""
        import numpy as np

        index = self.value.index
        self._row_slots = None
        if self._keyed and all(k in index for k in self._row_keys):
            self._row_slots = np.array([index[k] for k in self._row_keys], dtype=np.intp)
            self._row_ints = [p for p, k in enumerate(self._row_keys) if self.value.ints[index[k]]]
            self._np_values = np.ctypeslib.as_array(self.native.arr)
            self._np_known = np.ctypeslib.as_array(self.native.known)
            bind = getattr(self.record, "bind_slots", None)  # a CSVStream formatting its rows in C
            if bind is not None:
                self._put_row = bind(self._np_values, self._row_slots, self._row_ints, self.native.csv_rows)

    def row_values(self, t: float, kind: int = GRID) -> list:
        v = self.value
        if self.native is not None and self._row_slots is not None and self._np_known[self._row_slots].all():
            out = self._np_values[self._row_slots].tolist()
            for p in self._row_ints:
                out[p] = int(out[p])
            return [t, kind, *out]
        if self._keyed:
            return [t, kind, *[v[k] for k in self._row_keys]]
        out = [t, kind]
        for (name, con), key in zip(self.columns, self._row_keys):
            out.append(v[key] if key is not None else self.instances[name].get_values([con.name])[0])
        return out


def update_levels(order, incoming) -> List[list]:
    """The update order cut into levels: consecutive components none of which feeds another of
    its level (through any connection). Stepping a level's components together (in parallel)
    is Gauss–Seidel in update order: each sees the outputs of the levels before it, and of none
    of its own level, as it would one after the other."""
    levels, names = [], set()
    for inst in order:
        if names and any(c.start_element in names for c in incoming[inst.name]):
            levels.append([])
            names = set()
        if not levels:
            levels.append([])
        levels[-1].append(inst)
        names.add(inst.name)
    return levels


class Progress:
    """A line every 10 % of a long run (``--quiet``: none)."""

    def __init__(self, name, t0, t_end, on=True):
        self.name, self.t0, self.span, self.on = name, t0, t_end - t0, on
        self.next, self.wall0 = 0.1, _time.perf_counter()

    def __call__(self, t):
        if not self.on:
            return
        frac = (t - self.t0) / self.span
        if frac + 1e-12 >= self.next:
            el = _time.perf_counter() - self.wall0
            print(f"{self.name}: {100 * frac:3.0f} %  t = {t:.6g} s  ({el:.1f} s elapsed, "
                  f"~{el / max(frac, 1e-12) - el:.1f} s left)", flush=True)
            while self.next <= frac + 1e-12:
                self.next += 0.1


def _grid(t0, step):
    """``(A, P, D)``: the k-th communication point is ``(A + k P) / D`` (see :func:`grid_points`)."""
    a, b = Fraction(repr(float(t0))).as_integer_ratio()
    p, q = Fraction(repr(float(step))).as_integer_ratio()
    return a * q, p * b, b * q


def grid_points(t0, t_end, step):
    """The communication points ``t0 + k h`` after ``t0`` up to ``t_end``, each the double nearest
    the exact decimal sum of ``t0`` and ``k h`` as written (their shortest decimals, ``repr``): with
    ``h = 1e-3`` the ninth point is 0.009, where the product ``9 * 0.001`` is 0.009000000000000001.
    libcosim's points, integer nanoseconds divided by 1e9, are these whenever ``t0`` and ``h`` are
    whole nanoseconds; a component's integrator started one ulp away takes other steps, and on
    the 1-ring mirror that difference of round-off grew through the loops to 1e-2 N
    (tests/test_mirror_libcosim.py)."""
    A, P, D = _grid(t0, step)
    n = int(round((t_end - t0) / step))
    return [(A + k * P) / D for k in range(1, n + 1)]  # int / int: correctly rounded


def grid_point(t0, step, k):
    """The k-th communication point of :func:`grid_points`."""
    A, P, D = _grid(t0, step)
    return (A + k * P) / D


# =============================================================================================
# fixed step (--events off)
# =============================================================================================

def fixed_step(ex: Exchange, t0, t_end, step, jacobi=False, progress=None):
    """Every component steps from ``t_k`` to ``t_k + h``; Gauss–Seidel sets a component's inputs
    from the latest outputs just before its step (update order), Jacobi sets every input from the
    outputs at ``t_k`` (libcosim's algorithm). Events happen inside the FMUs; the master learns of
    them at the next communication point."""
    t = t0
    ex.prepare([ex.order] if jacobi else ex.levels, not jacobi)
    for T in grid_points(t0, t_end, step):
        h = T - t

        def gauss_seidel(inst):
            ex.feed(inst, lines=True)
            inst.do_step(t, h)
            ex.read(inst)

        def held(inst):  # Jacobi: the inputs were all set at t_k
            inst.do_step(t, h)
            ex.read(inst)
        if jacobi:
            ex.feed_all(ex.order)
            ex.step_level(ex.order, t, h, False, held)
        else:
            ex.mark(t)
            for level in ex.levels:
                ex.step_level(level, t, h, True, gauss_seidel)
        ex.row(T)
        t = T
        if progress:
            progress(T)
    return t


# =============================================================================================
# event-synchronized (--events on)
# =============================================================================================

class Synchronizer:
    """The fixed grid of communication points, with every component brought to each event instant.

    A macro step from ``t`` towards the next grid point ``T``:

    1. **step** each component in update order (its inputs set from the latest outputs);
    2. **detect**: an FMI 3.0 component returns early at its event (``earlyReturnAllowed``); an
       FMI 2.0 one reports it after the step (this project's FMUs count their events, any other
       FMU changes a discrete output);
    3. **locate**: an FMI 2.0 component rolls back (its state saved before the step) and is
       stepped to just before its event — the exact ``t_last_event`` of a pogofmu FMU, or the
       change of a discrete output bisected to ``tolerance``;
    4. **synchronize**: the components already stepped past that instant are restored and
       stepped to it, the later ones go no further; the macro step ends there;
    5. **iterate the event** at that instant: the left-limit row, then the components updated in
       update order — Event Mode with ``fmi3UpdateDiscreteStates`` until none asks for more and
       no connected value changes (FMI 3.0), a step across the event (FMI 2.0) — then the
       right-limit row; the macro step goes on from there.

    A component may also switch because its *inputs* cross a threshold inside the step (a
    controller's phase where the plant's velocity crosses 0): a discrete output that depends
    directly on inputs (declared dependencies) and changed over a step without an event is
    located by bisecting the whole system's step (every component restored and stepped to the
    midpoint, in update order) to ``tolerance``, and handled as an event at that instant.

    With Jacobi the components step with their inputs held from the step's start, so a switching
    output seen after the step still answers the inputs of the start: the master *probes* it —
    the switching component restored, given the inputs of the step's end and stepped again — and
    puts the component back on its Jacobi step when nothing switched. The event iteration is
    the same as Gauss–Seidel's: at one instant no time passes, and the components are updated in
    update order until the connected values settle, whatever the algorithm between the events.

    States are saved only where a later component (or the component itself, for a rollback) may
    cut the step short, and only by components that can get and set their state.
    """

    def __init__(self, ex: Exchange, tolerance: float, jacobi=False, warn=print):
        self.ex, self.tol, self.jacobi = ex, tolerance, jacobi
        order = ex.order
        for inst in order:
            inst.rollback = inst.fmi == 2 and inst.can_save and self._may_have_events(inst)
            inst.may_stop = inst.rollback or (inst.fmi == 3 and getattr(inst, "early_return", False)
                                              and self._may_have_events(inst))
            if inst.fmi == 2 and self._may_have_events(inst) and not inst.can_save:
                warn(f"warning: Component {inst.name} cannot get and set its FMU state "
                     f"(canGetAndSetFMUstate = false): it keeps the fixed communication step, and the other "
                     f"components learn of its events at the next communication point")
        for inst in order:
            inst.switches = switching_outputs(inst, ex)
            ex.also_read(inst, inst.switches)
            if inst.rollback and inst.counts_events:
                ex.also_read(inst, ["n_events", "t_last_event"])
        self.switching = [inst for inst in order if inst.switches]
        self._switch_keys = [(inst.name, n) for inst in self.switching for n in inst.switches]
        # the components stepped together with ``inst`` (its level; with Jacobi, all of them) go to
        # the step's end before any event among them is known, so a peer's event cuts them back too
        self.levels = [order] if jacobi else ex.levels
        peers = {inst.name: level for level in self.levels for inst in level}
        for i, inst in enumerate(order):
            later = any(o.may_stop for o in order[i + 1:]) or any(o.switches for o in order[i:]) \
                or any(o.may_stop for o in peers[inst.name] if o is not inst)
            inst.must_save = inst.can_save and (inst.rollback or later)
            if later and not inst.can_save:
                warn(f"warning: Component {inst.name} cannot get and set its FMU state: an event of a "
                     f"component after it in the update order is not synchronized with it (it stays at the "
                     f"end of the communication step)")
        self.next_event = {}  # component -> time event it asked for (FMI 3.0 nextEventTime)
        self.cause = ()  # the components whose event ended the latest macro step (advance)
        self.switch_now = None  # Jacobi: the switching outputs at the inputs of the latest point
        self._kept_now = False  # an event at a step's start stays in this macro step (_first_event)
        self._kept_before = False  # ... stayed in the latest macro step that advanced or kept one

    @staticmethod
    def _may_have_events(inst) -> bool:
        if inst.events is not None:  # a pogofmu FMU says which events a step can hold
            return bool(inst.events)
        return inst.fmi == 3 or bool(inst.discrete_outputs)

    # ---- one component: step, detect, locate ---------------------------------------------------
    def _counts(self, inst):
        """The event counter and the latest event time, as read with the outputs."""
        v = self.ex.value
        return int(v[(inst.name, "n_events")]), float(v[(inst.name, "t_last_event")])

    def _step(self, inst, t, T) -> StepResult:
        """Step ``inst`` from ``t`` to ``T`` (and read its outputs); an FMI 2.0 component that can
        roll back is stopped just before the first event of the step (``event_at`` tells where it
        lies)."""
        ex = self.ex
        if not inst.rollback:
            r = inst.do_step(t, T - t)
            ex.read(inst)
            return r
        if inst.counts_events:
            n0, _ = self._counts(inst)
            r = inst.do_step(t, T - t)
            ex.read(inst)
            n1, _ = self._counts(inst)
            if n1 == n0:
                return r
            return self._first_event(inst, t, n0)
        return self._bisect(inst, t, T)

    def _first_event(self, inst, t, n0) -> StepResult:
        """``inst`` (a pogofmu FMU, saved at ``t``) counted events over its step from ``t``
        (``n0`` before it): restored and stepped to just before the first of them after ``t``.

        Events at ``t`` itself belong to the step: every component was at ``t`` when it began, so
        there is no instant before them to stop at, and they are caused by what the step began
        with (a guard at zero that the flow carries across, or an input's new value: with held
        inputs a Gauss-Seidel step feeds a later component the values at the step's end). Cut
        back to ``t`` and fed the values at ``t`` instead, the component would lose the event and
        find it again at the next step: a storm without time advancing.

        Unless the macro step before ended at ``t`` with an event of ``inst`` (the limit of an
        accumulation of its events: the mirror's controller) or keeping such an event itself (two
        components switching each other back and forth at step after step): a step would hide the
        chatter in its length. Then the event is cut back to, and the run ends in its storm."""
        ex = self.ex
        _, t_c = self._counts(inst)
        if t_c <= t:  # every event of the step at its start: the step stands (see above)
            return self._keep_start_event(inst, t, StepResult(inst.t), t_c)
        while True:  # the first event of the step after its start (t_last_event is the latest)
            inst.restore()
            left = math.nextafter(t_c, -math.inf)
            if left <= t:
                return StepResult(t, event_at=t_c)
            inst.do_step(t, left - t)
            ex.read(inst)
            n, t_last = self._counts(inst)
            if n == n0:
                return StepResult(left, event_at=t_c)
            if t_last <= t:  # (the events before ``left`` all at the start)
                return self._keep_start_event(inst, t, StepResult(left, event_at=t_c), t_last)
            t_c = t_last

    def _keep_start_event(self, inst, t, kept: StepResult, t_start) -> StepResult:
        """``kept`` for ``inst``, whose step from ``t`` holds an event at ``t`` (``t_start``), unless
        the macro step before makes it a chatter (:meth:`_first_event`): then ``inst`` is restored to
        ``t`` with the event located there."""
        # (a macro step begins where the one before ended: an event instant recorded at ``t`` is
        # the one that ended it)
        last = self.ex.event_sources[-1] if self.ex.event_sources else None
        again = last is not None and last[0] == t and inst.name in last[1]
        if not self._kept_before and not again:
            self._kept_now = True
            return kept
        inst.restore()
        self.ex.read(inst)
        return StepResult(t, event_at=t_start)

    def _bisect(self, inst, t, T) -> StepResult:
        """An FMU of another tool (saved at ``t``) stepped to ``T``, stopped before the change of a
        discrete output bisected to ``tolerance``."""
        ex = self.ex
        d0 = inst.get_values(inst.discrete_outputs)
        r = inst.do_step(t, T - t)
        ex.read(inst)
        if inst.get_values(inst.discrete_outputs) == d0:
            return r
        lo, hi = t, T  # bisection: the change lies in (lo, hi]
        while hi - lo > self.tol:
            mid = 0.5 * (lo + hi)
            inst.restore()
            inst.do_step(t, mid - t)
            if inst.get_values(inst.discrete_outputs) != d0:
                hi = mid
            else:
                lo = mid
        if hi - t <= self.tol:  # the outputs changed with the inputs set at t: no event inside the step
            inst.restore()
            r = inst.do_step(t, T - t)
            ex.read(inst)
            return r
        inst.restore()
        if lo > t:
            inst.do_step(t, lo - t)
        ex.read(inst)
        return StepResult(lo, event_at=hi)

    # ---- the macro step: synchronize -----------------------------------------------------------
    def advance(self, t, T):
        """Bring every component from ``t`` to ``T``, or to the first event before it; returns
        ``(t_reached, step result of the event or None)``: the levels stepped in update order
        (:meth:`_step_level`), the earliest event among a level's components cutting the macro
        step (:meth:`_earliest`, :meth:`_back_to`), then a time event or a switch of a
        feed-through output inside the step (:meth:`_switch_event`)."""
        target, event = self._advance(t, T)
        if self._kept_now or target > t:  # (a step that stood at ``t`` leaves the mark as it was)
            self._kept_before, self._kept_now = self._kept_now, False
        return target, event

    def _advance(self, t, T):
        ex, jacobi = self.ex, self.jacobi
        switch0 = None
        if self._switch_keys:
            switch0 = self.switch_now if jacobi and self.switch_now is not None else self._switch_values()
        self.switch_now = None
        target = T
        for t_next in self.next_event.values():  # time events asked for by FMI 3.0 components
            if t < t_next < target:
                target = t_next
        if jacobi:
            ex.feed_all(ex.order)
        else:
            ex.mark(t)
        on_event = lambda inst, n0: self._first_event(inst, t, int(n0))  # noqa: E731
        ran = None  # the levels stepped by one C call (Gauss-Seidel, every component at the step's start)
        if not jacobi and max(map(_TIME, ex.order)) < target:
            ran = ex.step_levels(self.levels, t, target - t, on_event)
        event, stepped = None, []
        for k, level in enumerate(self.levels):
            # the level's components step together to ``target`` (in parallel with --threads);
            # the earliest event among them then cuts the macro step, as one after the other the
            # first would have cut the step of the next: those that went past it go back to it
            results = ran[k] if ran is not None and k < len(ran) else None
            if results is not None:  # (stepped already: all of the level was at t)
                todo = level
            else:
                todo = [inst for inst in level if inst.t < target]
                stepped += [inst for inst in level if inst.t >= target]  # ahead (they cannot roll back): they wait
                results = self._step_level(todo, t, target, on_event)
            cut, at_end = self._earliest(todo, results, target)
            if at_end is not None and event is None:
                event, self.cause = at_end[1], (at_end[0].name,)  # an event exactly at the end of the step
            stepped += todo
            if cut is not None:
                inst, event = cut
                self.cause = (inst.name,)
                target = event.t_end
                self._back_to([prev for prev in stepped if prev.t > target and prev.must_save], t, target, inst)
        if event is None and self.next_event and target in self.next_event.values():
            event = StepResult(target, event_at=target, event_mode=True)
            self.cause = tuple(inst.name for inst, t_next in self.next_event.items() if t_next == target)
        if event is None and switch0:
            target, event = self._switch_event(t, target, switch0)
        return target, event

    def _step_level(self, todo, t, goal, on_event) -> list:
        """Step the components ``todo`` of one level from ``t`` to ``goal`` (fed, saved where they
        must, read; in C where it serves them): their step results."""
        ex, jacobi = self.ex, self.jacobi

        def one(inst):
            if not jacobi:
                ex.feed(inst, lines=True)
            if inst.must_save:
                inst.save()
            if inst.rollback:
                return self._step(inst, t, goal)  # (it reads the outputs)
            r = inst.do_step(t, goal - t)
            ex.read(inst)
            return r
        return ex.step_level(todo, t, goal - t, not jacobi, one, save=True, on_event=on_event)

    @staticmethod
    def _earliest(todo, results, goal):
        """``(cut, at_end)``: the component that stopped earliest before ``goal`` (at or just before
        its event) with its result, and the first one with an event exactly at ``goal``; each
        ``(component, result)`` or None. A component asking to terminate ends the run."""
        cut = at_end = None
        pairs = zip(todo, results)
        if len(results) > 1 and results.count(results[0]) == len(results):
            pairs = ((todo[0], results[0]),)  # one result for all (a C call without events): the checks once
        for inst, r in pairs:
            if r.terminate:
                raise SSPError(f"Component {inst.name} asked to terminate the simulation at t = {r.t_end!r} s")
            if r.t_end < goal and (cut is None or r.t_end < cut[1].t_end):
                cut = (inst, r)  # it stopped at (or just before) an event: everyone goes no further
            elif r.event_at is not None and at_end is None and r.t_end == goal:
                at_end = (inst, r)
        return cut, at_end

    def _back_to(self, back, t, target, cause):
        """The components ``back`` (stepped past ``target``, saved at ``t``) restored and stepped to
        ``target``, the instant of the event of ``cause``."""
        ex, jacobi = self.ex, self.jacobi

        def redo(prev):
            prev.restore()
            if not jacobi and ex.takes_lines(prev):  # its input lines over the shorter span
                ex.feed(prev, lines=True)
            try:
                if target > t:
                    prev.do_step(t, target - t)
            except SSPError as exc:
                raise SSPError(f"{exc} (the step shortened to the event of Component {cause.name} at "
                               f"t = {target!r} s)") from None
            ex.read(prev)
        if not jacobi and any(ex.takes_lines(prev) for prev in back):
            for prev in back:  # in update order: a line's source is redone before it is fed
                redo(prev)
        else:
            ex.map(redo, back)

    def _switch_event(self, t, target, switch0):
        """``(target, event)`` after a step from ``t`` to ``target`` without an event: a
        feed-through discrete output that switched inside it is located (Jacobi: probed first)
        and is the step's event."""
        if self.jacobi:
            self.switch_now = self._probe(t, target)
            if self.switch_now == switch0:
                self._unprobe(t, target)
                return target, None
            self.switch_now = None
        if self._switch_values() != switch0:
            switched = self._switched(switch0)  # (before the bisection moves them back)
            located = self._locate_switch(t, target, switch0)
            if located is not None:
                self.cause = switched
                return located
        return target, None

    def _probed(self, t):
        """The switching components a probe from ``t`` can restore."""
        return [inst for inst in self.switching if inst.must_save and inst.saved_at == t]

    def _probe(self, t, tau):
        """Jacobi: the switching outputs at ``tau`` answering the inputs at ``tau`` — each
        switching component restored to ``t``, fed the latest outputs (those at ``tau``) and
        stepped to ``tau`` again."""
        ex = self.ex
        for inst in self._probed(t):
            inst.restore()
            ex.feed(inst)
            if tau > t:
                inst.do_step(t, tau - t)
            ex.read(inst)
        return self._switch_values()

    def _unprobe(self, t, tau):
        """Back on the Jacobi step: the probed components restored (with the inputs of ``t``
        they were saved with) and stepped to ``tau``."""
        ex = self.ex
        for inst in self._probed(t):
            inst.restore()
            if tau > t:
                inst.do_step(t, tau - t)
            ex.read(inst)

    def _switched(self, switch0):
        """The components whose switching outputs differ from ``switch0`` (a located switch's)."""
        now = self._switch_values()
        names = [key[0] for key, a, b in zip(self._switch_keys, switch0, now) if a != b]
        return tuple(dict.fromkeys(names)) or tuple(dict.fromkeys(k[0] for k in self._switch_keys))

    def _switch_values(self):
        """The latest values of every switching output (feed-through discrete outputs)."""
        v = self.ex.value
        return [v[k] for k in self._switch_keys]

    def _redo(self, t, tau):
        """Every component restored to ``t`` and stepped to ``tau`` in update order (Gauss–Seidel:
        each fed from the components before it, at ``tau``; the inputs from later ones are those
        saved at ``t``; Jacobi: every input the one saved at ``t``, then the switching outputs
        probed at ``tau``)."""
        ex, done, jacobi = self.ex, set(), self.jacobi

        def one(inst):
            if inst.must_save and inst.saved_at == t:
                inst.restore()
            if inst.t == t:
                if not jacobi:
                    ex.feed(inst, only=done, lines=True)
                if tau > t:
                    inst.do_step(t, tau - t)
                ex.read(inst)
        for level in ex.levels:
            ex.map(one, level)
            done.update(inst.name for inst in level)
        if self.jacobi:
            self._probe(t, tau)

    def _locate_switch(self, t, T, switch0):
        """Bisect the system's step for the instant a feed-through discrete output changes; None
        when it changed with the inputs at ``t`` (no switch inside the step)."""
        if not all(inst.must_save and inst.saved_at == t for inst in self.ex.order if inst.t > t):
            return None  # a component cannot go back: the switch is seen at the end of the step

        def switched():
            return self._switch_values() != switch0
        lo, hi = t, T
        while hi - lo > self.tol:
            mid = 0.5 * (lo + hi)
            self._redo(t, mid)
            if switched():
                hi = mid
            else:
                lo = mid
        if hi - t <= self.tol:  # the outputs changed with the inputs at t: go on as stepped
            self._redo(t, T)
            return None
        self._redo(t, lo)
        return lo, StepResult(lo, event_at=hi)

    # ---- at the event: iterate ----------------------------------------------------------------
    def cross(self, t, t_event):
        """FMI 2.0 rollback: every component steps across the event, from just before it to it, in
        update order; each is fed from the components that crossed before it (feed-through of the
        new mode), none from later ones — an input changed just before the event would move the
        event it is crossing. The same with Jacobi: the crossing is the event's iteration."""
        ex, done = self.ex, set()

        def one(inst):
            # (Gauss-Seidel: an input taken as a line keeps its line's slope, so that the guards of
            # the crossing see the input move as the step saw it, not held)
            ex.feed(inst, only=done, slopes=not self.jacobi)
            if inst.t < t_event:
                inst.do_step(inst.t, t_event - inst.t)
            ex.read(inst)
        for level in ex.levels:
            ex.map(one, level)
            done.update(inst.name for inst in level)

    def iterate(self, t):
        """Event Mode at ``t`` for every FMI 3.0 component that uses it: update in update order
        until no component asks for another discrete update and no connected value changes
        (superdense time); a limit ends the run naming the components and the time."""
        ex = self.ex
        em = [inst for inst in ex.order if getattr(inst, "event_mode_used", False)]
        for inst in em:
            inst.enter_event_mode()
        self.settle(t, em)
        for inst in em:
            inst.enter_step_mode()

    def settle(self, t, em):
        ex = self.ex
        for k in range(MAX_EVENT_ITERATIONS):
            busy = []
            for inst in ex.order:
                changed = ex.feed(inst) if ex.ready(inst) else False
                if inst in em:
                    need, terminate, t_next = inst.update_discrete_states()
                    if terminate:
                        raise SSPError(f"Component {inst.name} asked to terminate the simulation at t = {t!r} s")
                    if t_next is not None and t_next > t:
                        self.next_event[inst] = t_next
                    else:
                        self.next_event.pop(inst, None)
                    if need:
                        busy.append(inst.name)
                changed |= ex.read(inst)
                if changed and k > 0 and inst.name not in busy:
                    busy.append(inst.name)
            if not busy and k > 0:
                return
            if not busy and k == 0:
                continue  # one more pass: the first one may have changed inputs of earlier components
        raise SSPError(f"the discrete iteration at t = {t!r} s did not settle after {MAX_EVENT_ITERATIONS} "
                       f"iterations: {', '.join(sorted(set(busy)))} still changing (an algebraic loop through "
                       f"discrete variables, or an event that fires again at the same instant)")


def switching_outputs(inst, ex) -> List[str]:
    """The discrete outputs of ``inst`` that depend directly on a connected input (declared
    dependencies; an output without them depends on every input) and that the system declares
    as connectors of the component: a switch of an output the system does not expose (the
    mirror controllers' ``sat``, whose force is continuous at the kink) is not located."""
    from .graph import feedthrough

    fed = {c.end_connector for c in ex.incoming[inst.name]}
    if not fed:
        return []
    declared = getattr(inst.comp, "connectors", None)
    ft = feedthrough(inst.comp)
    out = []
    for name in inst.discrete_outputs:
        if declared is not None and name not in declared:
            continue
        deps = ft.get(name)
        if deps is None or deps & fed:
            out.append(name)
    return out


def synchronized(ex: Exchange, t0, t_end, step, tolerance=1e-10, jacobi=False, progress=None, warn=print):
    """The event-synchronized master (class :class:`Synchronizer`): every grid row, and at every
    event a left-limit row (``event = -1``) and a right-limit row (``event = +1``; at an event on
    a grid point the grid row is the right limit)."""
    sync = Synchronizer(ex, tolerance, jacobi, warn)
    for inst in ex.order:  # the event counters and switching outputs the synchronizer watches
        ex.read(inst)
    em = [inst for inst in ex.order if getattr(inst, "event_mode_used", False)]
    sync.settle(t0, em)  # FMI 3.0 with eventModeUsed: in Event Mode after initialization
    for inst in em:
        inst.enter_step_mode()
    ex.prepare(sync.levels, not jacobi, save=True)
    ex.row(t0)
    t = t0
    stuck = 0  # events in a row at one instant (two components switching each other back and forth)
    for T in grid_points(t0, t_end, step):
        while t < T:
            t_reached, ev = sync.advance(t, T)
            if ev is not None:
                stuck = stuck + 1 if t_reached <= t else 0
                if stuck > MAX_EVENT_ITERATIONS:
                    raise SSPError(f"event storm across the system: {stuck} events in a row at t = {t!r} s without "
                                   f"time advancing (components whose events undo each other at one instant, "
                                   f"e.g. a switch that the other component's answer switches back)")
                ex.row(t_reached, LEFT)
                if ev.event_at > t_reached:  # FMI 2.0 rollback: stopped just before the event
                    sync.cross(t_reached, ev.event_at)
                    t_reached = ev.event_at
                else:
                    sync.iterate(t_reached)
                ex.event_sources.append((t_reached, sync.cause))
                if t_reached < T:
                    ex.row(t_reached, RIGHT)
            if t_reached <= t and ev is None:
                raise SSPError(f"no component advanced from t = {t!r} s (a component returned early without an "
                               f"event)")
            t = t_reached
        ex.row(T)
        if progress:
            progress(T)
    return t
