"""Recording a run: every connector at every communication point (and at every event), in memory
(:class:`Result`) or streamed to a CSV (:class:`CSVStream`), with the figure's min/max
:class:`Envelope` as the only thing kept of a streamed run."""
from __future__ import annotations

import csv
import ctypes
import io
import os
from operator import itemgetter
from pathlib import Path

PLOT_BINS = 2000  # time slices of a figure's min/max envelope (more than the figure's pixel columns)
CHUNK_VALUES = 1 << 20  # values per block of rows (CSV write, in-memory block): a block's memory bounded
WRITER_VALUES = 1 << 15  # ... of a block handed to a writer thread (threads >= 2): formatted while the run goes on


def chunk_rows(n_cols: int) -> int:
    """Rows per block: 4096 for a narrow run, fewer for a wide one (hundreds of components),
    so that a block holds at most about CHUNK_VALUES values whatever the column count."""
    return max(16, min(4096, CHUNK_VALUES // max(n_cols, 1)))


class Envelope:
    """Min/max envelope of every column of a run over ``bins`` equal slices of its time span
    ``(t0, t1)`` (column 0 is the time).

    Drawn as a line through each slice's minimum and maximum in time order, a run of any length
    looks like the full one at the figure's resolution (every peak, every mode switch stays
    visible) from at most ``2 * bins`` points per signal; rows that fall into slices of their own
    (fewer rows than slices, evenly spread) are all kept. Rows arrive in blocks of any size
    (:meth:`add`), so nothing else of the run is kept; the number of rows need not be known (a
    run's events add rows to its grid).
    """

    def __init__(self, span, n_cols: int, bins: int = PLOT_BINS, keep=None):
        import numpy as np

        self.t0, t1 = float(span[0]), float(span[1])
        self.width = t1 - self.t0 if t1 > self.t0 else 1.0
        self.bins, self.rows = bins, 0
        # the columns kept (``keep``, column indices with 0, the time, first): 6 x bins numbers each
        self.keep = list(range(n_cols)) if keep is None else [0] + [c for c in keep if c != 0]
        self._slot = {c: i for i, c in enumerate(self.keep)}
        self._pick = None if keep is None else itemgetter(*self.keep)
        shape = (self.bins, len(self.keep))
        self.kmin, self.kmax = np.full(shape, -1, np.int64), np.full(shape, -1, np.int64)
        self.vmin, self.vmax = np.full(shape, np.inf), np.full(shape, -np.inf)
        self.tmin, self.tmax = np.zeros(shape), np.zeros(shape)

    def add(self, block):
        """Rows ``self.rows ...`` of the run: a 2-D array, column 0 the time."""
        import numpy as np

        m = len(block)
        if m == 0:
            return
        if self._pick is not None:
            block = [self._pick(r) for r in block] if not isinstance(block, np.ndarray) else block[:, self.keep]
        block = np.asarray(block, dtype=np.float64).reshape(m, len(self.keep))
        slot = np.clip(np.floor((block[:, 0] - self.t0) / self.width * self.bins), 0, self.bins - 1).astype(np.int64)
        slot = np.maximum.accumulate(slot)  # rows come in time order (equal times at event instants)
        cuts = np.flatnonzero(np.diff(slot)) + 1
        cols = np.arange(block.shape[1])
        starts, ends = np.r_[0, cuts], np.r_[cuts, m]
        one = ends - starts == 1
        if one.any():  # the slices a single row of the block falls in (fewer rows than slices): all at once
            r = starts[one]
            rows, j = block[r], slot[r]  # (each slice once: the slots of the segments differ)
            for k_, v_, t_, better in ((self.kmin, self.vmin, self.tmin, np.less),
                                       (self.kmax, self.vmax, self.tmax, np.greater)):
                new_r, new_c = np.nonzero(better(rows, v_[j]))  # NaN never wins
                k_[j[new_r], new_c] = self.rows + r[new_r]
                v_[j[new_r], new_c] = rows[new_r, new_c]
                t_[j[new_r], new_c] = rows[new_r, 0]
        for a, b in zip(starts[~one], ends[~one]):
            seg, j = block[a:b], slot[a]
            for pick, k_, v_, t_, better in ((np.argmin, self.kmin, self.vmin, self.tmin, np.less),
                                             (np.argmax, self.kmax, self.vmax, self.tmax, np.greater)):
                i = pick(seg, axis=0)
                v = seg[i, cols]
                new = better(v, v_[j])  # NaN never wins: a NaN sample leaves a gap
                k_[j, new] = self.rows + a + i[new]
                v_[j, new] = v[new]
                t_[j, new] = seg[i[new], 0]
        self.rows += m

    def series(self, col: int):
        """(time, value) of column ``col``: each slice's min and max in time order."""
        import numpy as np

        col = self._slot[col]
        k = np.stack([self.kmin[:, col], self.kmax[:, col]], axis=1)
        t = np.stack([self.tmin[:, col], self.tmax[:, col]], axis=1)
        v = np.stack([self.vmin[:, col], self.vmax[:, col]], axis=1)
        order = np.argsort(k, axis=1, kind="stable")
        k, t, v = (np.take_along_axis(a, order, axis=1).ravel() for a in (k, t, v))
        keep = (k >= 0) & np.r_[True, k[1:] != k[:-1]]
        return t[keep], v[keep]


class Result:
    """Every connector at every communication point and event: ``res["PogoStick.y"]`` is a numpy
    array (what :func:`simulate` returns by default; the ``run`` command streams to a CSV
    instead); ``res["event"]`` tells the rows apart (0 on the output grid, -1 / +1 the left and
    right limits at an event between grid points)."""

    def __init__(self, names, types, units, span):
        self.names = ["time"] + list(names)
        self.types = dict(zip(names, types))
        self.units = dict(zip(names, units))
        self.span = span
        self._chunk = chunk_rows(len(self.names))
        self._blocks = []  # full blocks of rows, float64 arrays (integers are exact in them)
        self._rows = []  # the rows since the latest block
        self._n = 0
        self._arrays = {}
        self._envelope = None
        self._keep = None

    @property
    def rows(self):
        return self._n

    def _all(self):
        import numpy as np

        if self._rows:
            self._blocks.append(np.array(self._rows, dtype=np.float64).reshape(len(self._rows), len(self.names)))
            self._rows = []
        if len(self._blocks) > 1:
            self._blocks = [np.concatenate(self._blocks)]
        return self._blocks[0] if self._blocks else np.zeros((0, len(self.names)))

    def __getitem__(self, name):
        import numpy as np

        got = self._arrays.get(name)
        if got is None or len(got) != self._n:
            col = self.names.index(name)
            integer = name != "time" and self.types.get(name) not in ("Real", "Float64", "Float32")
            got = self._arrays[name] = self._all()[:, col].astype(np.int64 if integer else np.float64)
        return got

    def add(self, row):
        self._rows.append(row)
        self._n += 1
        if len(self._rows) >= self._chunk:
            self._all()
        self._envelope = None

    def plot_only(self, names):
        """The figure draws these signals only: its envelope keeps no other column."""
        self._keep = [self.names.index(n) for n in names]

    def close(self, complete=True):
        pass

    def envelope(self) -> Envelope:
        if self._envelope is None:
            self._envelope = Envelope(self.span, len(self.names), keep=self._keep)
            if self._n:
                self._envelope.add(self._all())
        return self._envelope


_OFF = ("0", "off", "no", "false")
_CSV_LIB = None


def csv_library():
    """The C formatting of CSV rows (``fmu_src/native/master/pg_csv.c``, in the library of the C
    level stepping, :func:`.native_level.library`); None without it (no C compiler, or turned off:
    ``POGOFMU_SSP_NATIVE_CSV=0``, or ``POGOFMU_SSP_NATIVE_LEVELS=0``): the csv module then writes
    the same bytes."""
    global _CSV_LIB
    if os.environ.get("POGOFMU_SSP_NATIVE_CSV", "1").strip() in _OFF:
        return None
    if _CSV_LIB is None:
        from .native_level import library

        lib = library()
        if lib is None:
            return None
        try:
            f = lib.pgm_csv_rows
        except AttributeError:
            _CSV_LIB = False
            return None
        f.restype = ctypes.c_long
        f.argtypes = [ctypes.c_void_p, ctypes.c_long, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p,
                      ctypes.c_long, ctypes.POINTER(ctypes.c_long)]
        lib.pgm_csv_row_max.restype = ctypes.c_long
        lib.pgm_csv_row_max.argtypes = [ctypes.c_int, ctypes.c_void_p]
        _CSV_LIB = lib
    return _CSV_LIB or None


def csv_bytes(rows, encoding) -> bytes:
    """The csv module's text of ``rows`` (lists): floats as repr (shortest round trip), integers
    as integers, ``\r\n`` after each row."""
    out = io.StringIO()
    csv.writer(out).writerows(rows)
    return out.getvalue().encode(encoding)


class RowFormatter:
    """Rows of numbers (a 2-D float64 array; ``is_int[j]``: column ``j`` holds integers) as the
    bytes ``csv.writer`` writes for them as lists (floats as ``repr``, integer columns as ``int``,
    ``\\r\\n`` after each row): by the C code with the GIL released (``lib``), else by the csv
    module."""

    TEXT = 1 << 20  # bytes of text per C call (at least two rows)

    def __init__(self, is_int, lib=None, encoding="utf-8", rows=None):
        import numpy as np

        self.is_int = np.ascontiguousarray(is_int, dtype=np.uint8)
        self.ints = [j for j, f in enumerate(self.is_int) if f]
        self.lib, self.encoding = lib, encoding
        self.rows = rows or (lib.pgm_csv_rows if lib is not None else None)  # (pgm_csv_rows' arguments)
        if lib is not None:
            row_max = lib.pgm_csv_row_max(len(self.is_int), self.is_int.ctypes.data)
            self._text = np.empty(max(self.TEXT, 2 * row_max), dtype=np.uint8)
            self._done = ctypes.c_long()

    def chunks(self, block):
        """The text of ``block``'s rows, in pieces ``(text, end)``: the rows up to ``end`` (each
        text valid until the next piece is asked for)."""
        import numpy as np

        m = len(block)
        if m == 0:
            return
        if self.lib is None:
            yield self.python(block), m
            return
        block = np.ascontiguousarray(block, dtype=np.float64)
        n_cols, row_bytes = block.shape[1], block.strides[0]
        text, cap, done = self._text, len(self._text), self._done
        r = 0
        while r < m:
            n = self.rows(block.ctypes.data + r * row_bytes, m - r, n_cols, self.is_int.ctypes.data,
                                      text.ctypes.data, cap, ctypes.byref(done))
            if done.value <= 0:
                raise RuntimeError("pgm_csv_rows wrote no row")  # (the buffer holds two rows at least)
            r += done.value
            yield memoryview(text)[:n], r

    def python(self, block) -> bytes:
        """The csv module's text of ``block``'s rows (the reference the C code is held to)."""
        rows = block.tolist()
        if self.ints:
            for row in rows:
                for j in self.ints:
                    row[j] = int(row[j])
        return csv_bytes(rows, self.encoding)


class CSVStream:
    """Rows written to ``path`` while the run goes (in chunks), with the figure's :class:`Envelope`
    as the only thing kept in memory: the master's memory does not grow with the run's length.

    The file is written as ``<path>.part`` and renamed to ``path`` once the run is complete; a run
    that fails leaves its rows so far in ``<stem>.incomplete.csv`` (never a truncated ``path``).

    Rows come as lists (:meth:`add`, written by the csv module) or, from the C level stepping, as
    slots of its value array (:meth:`bind_slots`): copied into a preallocated block of the stream, no
    Python object per row, and a full block formatted by C code (:class:`RowFormatter`) with the
    GIL released — with ``threads`` >= 2 on a writer thread of the stream, overlapping the
    stepping (two blocks: one filled while the other is written), else in the calling thread.
    Both write the same bytes. A failed write ends the run with :class:`~.package.SSPError`
    ``cannot write <path>: <reason>``.
    """

    CHUNK = 4096  # rows per write (at most; fewer for wide rows, chunk_rows)

    def __init__(self, path: Path, names, types, units, span, threads: int = 1):
        self.path = Path(path)
        self.part = self.path.with_name(self.path.name + ".part")
        self.incomplete = self.path.with_name(f"{self.path.stem}.incomplete.csv")
        self.names = ["time"] + list(names)
        self.types = dict(zip(names, types))
        self.units = dict(zip(names, units))
        self.rows, self.last_time = 0, None
        self.span = span
        self.threads = max(1, int(threads))
        self._env = None  # made at the first row: plot_only() first narrows it (2000 x 6 numbers per column)
        self._chunk = min(self.CHUNK, chunk_rows(len(self.names)))
        self._buf = []  # rows given as lists, not yet written
        self._block, self._n = None, 0  # the block being filled by bind_slots()'s rows, and how many
        self._fmt = None
        self._jobs = self._free = self._writer = None
        self._error = None  # the first failed write (OSError)
        self._raised = False  # ... raised as SSPError
        self._done = False
        self._file = self.part.open("w", newline="")
        csv.writer(self._file).writerow(self.names)  # the header: the csv module, like every list row
        self._file.flush()
        self._out = self._file.buffer  # every row after it: bytes, in order

    # --- rows as lists --------------------------------------------------------------------------

    def add(self, row):
        if self._n:
            self._hand_block()
        self._buf.append(row)
        if len(self._buf) >= self._chunk:
            self._flush_list()

    def _flush_list(self):
        if not self._buf:
            return
        rows = self._buf
        self._buf = []
        data = csv_bytes(rows, self._file.encoding)
        if self._writer is not None:  # the envelope is the writer's (rows in order with the blocks)
            self._raise()
            self._jobs.put((data, len(rows), rows[-1][0], rows))
            return
        self.envelope().add(rows)
        self._write(data, len(rows), rows[-1][0])

    # --- rows as slots of the C value array -------------------------------------------------------

    def bind_slots(self, values, slots, ints, rows=None):
        """The rows of the C level stepping: ``put(t, kind)`` writes the row ``t, kind,
        values[slots]`` (``ints``: the positions in ``slots`` of integer values) into the stream's
        block; None when this stream formats no rows in C (no library). ``rows``: a function with
        ``pgm_csv_rows``'s arguments that formats them (the writer thread's: the C level stepping's
        pool, :meth:`.native_level.NativeLevels.csv_rows`)."""
        import numpy as np

        lib = csv_library()
        if lib is None or len(slots) + 2 != len(self.names):
            return None
        is_int = np.zeros(len(self.names), dtype=np.uint8)
        is_int[1] = 1  # the event column
        is_int[2 + np.asarray(list(ints), dtype=np.intp)] = 1
        self._fmt = RowFormatter(is_int, lib, self._file.encoding, rows if self.threads >= 2 else None)
        if self.threads >= 2:  # blocks of a writer thread: small, so that it formats while the run goes
            self._chunk = min(self._chunk, max(16, WRITER_VALUES // len(self.names)))
        self._block = np.empty((self._chunk, len(self.names)))
        rows = list(self._block)  # one view per row, made once
        slots = np.ascontiguousarray(slots, dtype=np.intp)
        take = values.take

        def put(t, kind):
            if self._buf:
                self._flush_list()
            row = rows[self._n]
            row[0] = t
            row[1] = kind
            take(slots, out=row[2:], mode="clip")
            self._n += 1
            if self._n == self._chunk:
                self._hand_block()

        def swap(block):  # bind_slots()'s rows go to another block from now on
            nonlocal rows
            self._block, rows = block, list(block)

        self._swap = swap
        return put

    def _hand_block(self):
        """The full (or last) block: into the envelope, and written (by the writer thread: the
        stream goes on with the other block)."""
        block, n = self._block, self._n
        self._n = 0
        if self.threads < 2:
            self.envelope().add(block[:n])
            self._write_block(block[:n])
            return
        if self._writer is None:
            self._start_writer()
        self._raise()
        self._jobs.put((block, n, float(block[n - 1, 0]), None))  # (its envelope too: the writer's)
        self._swap(self._take_free())

    def _write_block(self, block):
        if self._error is not None:
            return
        try:
            self._write_text(block)
        except OSError as exc:
            self._error = exc
        self._raise()

    def _write_text(self, block):
        """The rows of ``block`` formatted and written, counted piece by piece (a failed write
        leaves ``rows`` and ``last_time`` those of the pieces written)."""
        rows = self.rows
        for text, end in self._fmt.chunks(block):
            self._out.write(text)
            self.rows, self.last_time = rows + end, float(block[end - 1, 0])

    # --- the writer thread (threads >= 2) -------------------------------------------------------

    def _start_writer(self):
        import queue
        import threading

        import numpy as np

        self._jobs, self._free = queue.Queue(maxsize=2), queue.Queue()
        self._free.put(np.empty_like(self._block))  # the second block: filled while the first is written
        self._writer = threading.Thread(target=self._write_jobs, name="pogofmu-csv", daemon=True)
        self._writer.start()

    def _write_jobs(self):
        while True:
            job = self._jobs.get()
            if job is None:
                return
            data, n, t_last, rows = job
            try:
                self.envelope().add(data[:n] if rows is None else rows)
                if self._error is None:
                    if isinstance(data, bytes):
                        self._out.write(data)
                        self.rows += n
                        self.last_time = t_last
                    else:
                        self._write_text(data[:n])
            except BaseException as exc:  # noqa: BLE001 - handed to the run's thread (_raise)
                self._error = exc
            finally:
                if not isinstance(data, bytes):
                    self._free.put(data)  # never kept: the run's thread waits for it

    def _take_free(self):
        import queue

        while True:
            try:
                return self._free.get(timeout=1.0)
            except queue.Empty:
                if not self._writer.is_alive():
                    self._error = self._error or RuntimeError("the CSV writer thread ended")
                    self._raise()

    def _write(self, data: bytes, n, t_last):
        """Bytes of ``n`` rows, written now (no writer thread: see _flush_list)."""
        if self._error is not None:
            return
        try:
            self._out.write(data)
        except OSError as exc:
            self._error = exc
        else:
            self.rows += n
            self.last_time = t_last
        self._raise()

    def _stop_writer(self):
        if self._writer is not None:
            self._jobs.put(None)
            self._writer.join()
            self._writer = None

    def _raise(self):
        exc = self._error
        if exc is not None:
            from .package import SSPError

            self._raised = True
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise SSPError(f"cannot write {self.path}: {reason}") from None

    # ---------------------------------------------------------------------------------------------

    def plot_only(self, names):
        """The figure draws these signals only: its envelope keeps no other column (called
        before the first row)."""
        self._env = Envelope(self.span, len(self.names), keep=[self.names.index(n) for n in names])

    def close(self, complete=True):
        """Every row written, the file closed and renamed (``path`` when ``complete``, else
        ``<stem>.incomplete.csv``); a failed write raises ``SSPError`` after the rename."""
        if self._done:
            return
        self._done = True
        try:
            try:
                if self._error is None:
                    if self._n:
                        self._hand_block()
                    self._flush_list()
            finally:
                self._stop_writer()
                try:
                    self._file.close()
                except OSError as exc:  # the last buffered bytes
                    self._error = self._error or exc
                    try:
                        self._file.close()  # (a second close releases the descriptor)
                    except OSError:
                        pass
        except Exception:  # noqa: BLE001 - the rows so far are kept as incomplete, then the error goes on
            self._rename(False)
            raise
        if self._error is not None:
            self._rename(False)
            if complete or not self._raised:  # (closing after the error was raised: no second one)
                self._raise()
            return
        self._rename(complete)

    def _rename(self, complete):
        if not self.part.exists():
            return
        if not complete and self.rows == 0:  # nothing was simulated: no file at all
            self.part.unlink(missing_ok=True)
            return
        self.part.replace(self.path if complete else self.incomplete)

    def envelope(self) -> Envelope:
        if self._env is None:
            self._env = Envelope(self.span, len(self.names))
        return self._env
