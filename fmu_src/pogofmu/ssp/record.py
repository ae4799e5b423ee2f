"""Recording a run: every connector at every communication point (and at every event), in memory
(:class:`Result`) or streamed to a CSV (:class:`CSVStream`), with the figure's min/max
:class:`Envelope` as the only thing kept of a streamed run."""
from __future__ import annotations

from operator import itemgetter
from pathlib import Path

PLOT_BINS = 2000  # time slices of a figure's min/max envelope (more than the figure's pixel columns)
CHUNK_VALUES = 1 << 20  # values per block of rows (CSV write, in-memory block): a block's memory bounded


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
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, m]):
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


class CSVStream:
    """Rows written to ``path`` while the run goes (in chunks), with the figure's :class:`Envelope`
    as the only thing kept in memory: the master's memory does not grow with the run's length.

    The file is written as ``<path>.part`` and renamed to ``path`` once the run is complete; a run
    that fails leaves its rows so far in ``<stem>.incomplete.csv`` (never a truncated ``path``).
    """

    CHUNK = 4096  # rows per write (at most; fewer for wide rows, chunk_rows)

    def __init__(self, path: Path, names, types, units, span):
        import csv

        self.path = Path(path)
        self.part = self.path.with_name(self.path.name + ".part")
        self.incomplete = self.path.with_name(f"{self.path.stem}.incomplete.csv")
        self.names = ["time"] + list(names)
        self.types = dict(zip(names, types))
        self.units = dict(zip(names, units))
        self.rows, self.last_time = 0, None
        self.span = span
        self._env = Envelope(span, len(self.names))
        self._chunk = min(self.CHUNK, chunk_rows(len(self.names)))
        self._buf = []
        self._file = self.part.open("w", newline="")
        self._csv = csv.writer(self._file)  # floats as repr (shortest round trip), integers as integers
        self._csv.writerow(self.names)

    def add(self, row):
        self._buf.append(row)
        if len(self._buf) >= self._chunk:
            self._flush()

    def plot_only(self, names):
        """The figure draws these signals only: its envelope keeps no other column (called
        before the first row)."""
        self._env = Envelope(self.span, len(self.names), keep=[self.names.index(n) for n in names])

    def _flush(self):
        if self._buf:
            self._csv.writerows(self._buf)
            self._env.add(self._buf)
            self.rows += len(self._buf)
            self.last_time = self._buf[-1][0]
            self._buf.clear()

    def close(self, complete=True):
        if self._file.closed:
            return
        try:
            self._flush()
        finally:
            self._file.close()
        if not complete and self.rows == 0:  # nothing was simulated: no file at all
            self.part.unlink(missing_ok=True)
            return
        self.part.replace(self.path if complete else self.incomplete)

    def envelope(self) -> Envelope:
        return self._env
