"""Recording a run: every connector at every communication point (and at every event), in memory
(:class:`Result`) or streamed to a CSV (:class:`CSVStream`), with the figure's min/max
:class:`Envelope` as the only thing kept of a streamed run."""
from __future__ import annotations

from pathlib import Path

PLOT_BINS = 2000  # time slices of a figure's min/max envelope (more than the figure's pixel columns)


class Envelope:
    """Min/max envelope of every column of a run over ``bins`` equal slices of its rows.

    Drawn as a line through each slice's minimum and maximum in time order, a run of any length
    looks like the full one at the figure's resolution (every peak, every mode switch stays
    visible) from at most ``2 * bins`` points per signal; with no more rows than ``bins`` it keeps
    every row. Rows arrive in blocks of any size (:meth:`add`), so nothing else of the run is kept.
    """

    def __init__(self, n_rows: int, n_cols: int, bins: int = PLOT_BINS):
        import numpy as np

        self.n, self.bins, self.rows = n_rows, min(bins, n_rows), 0
        shape = (self.bins, n_cols)
        self.kmin, self.kmax = np.full(shape, -1, np.int64), np.full(shape, -1, np.int64)
        self.vmin, self.vmax = np.full(shape, np.inf), np.full(shape, -np.inf)
        self.tmin, self.tmax = np.zeros(shape), np.zeros(shape)

    def add(self, block):
        """Rows ``self.rows ...`` of the run: a 2-D array, column 0 the time."""
        import numpy as np

        block = np.asarray(block, dtype=np.float64)
        m = len(block)
        if m == 0:
            return
        slot = np.arange(self.rows, self.rows + m) * self.bins // self.n
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

        k = np.stack([self.kmin[:, col], self.kmax[:, col]], axis=1)
        t = np.stack([self.tmin[:, col], self.tmax[:, col]], axis=1)
        v = np.stack([self.vmin[:, col], self.vmax[:, col]], axis=1)
        order = np.argsort(k, axis=1, kind="stable")
        k, t, v = (np.take_along_axis(a, order, axis=1).ravel() for a in (k, t, v))
        keep = (k >= 0) & np.r_[True, k[1:] != k[:-1]]
        return t[keep], v[keep]


class Result:
    """Every connector at every communication point: ``res["PogoStick.y"]`` is a numpy array
    (what :func:`simulate` returns by default; the ``run`` command streams to a CSV instead)."""

    def __init__(self, names, types, units, n):
        import numpy as np

        self.names = ["time"] + list(names)
        self.types = dict(zip(names, types))
        self.units = dict(zip(names, units))
        self.data = {"time": np.empty(n)}
        for name, t in zip(names, types):
            self.data[name] = np.empty(n, dtype=np.float64 if t == "Real" else np.int64)
        self.n, self.rows = n, 0
        self._envelope = None

    def __getitem__(self, name):
        return self.data[name]

    def add(self, row):
        for name, v in zip(self.names, row):
            self.data[name][self.rows] = v
        self.rows += 1

    def close(self, complete=True):
        pass

    def envelope(self) -> Envelope:
        if self._envelope is None:
            import numpy as np

            self._envelope = Envelope(self.rows, len(self.names))
            self._envelope.add(np.column_stack([self.data[n][:self.rows] for n in self.names]))
        return self._envelope


class CSVStream:
    """Rows written to ``path`` while the run goes (in chunks), with the figure's :class:`Envelope`
    as the only thing kept in memory: the master's memory does not grow with the run's length.

    The file is written as ``<path>.part`` and renamed to ``path`` once the run is complete; a run
    that fails leaves its rows so far in ``<stem>.incomplete.csv`` (never a truncated ``path``).
    """

    CHUNK = 4096  # rows per write

    def __init__(self, path: Path, names, types, units, n_rows):
        import csv

        self.path = Path(path)
        self.part = self.path.with_name(self.path.name + ".part")
        self.incomplete = self.path.with_name(f"{self.path.stem}.incomplete.csv")
        self.names = ["time"] + list(names)
        self.types = dict(zip(names, types))
        self.units = dict(zip(names, units))
        self.n, self.rows, self.last_time = n_rows, 0, None
        self._env = Envelope(n_rows, len(self.names))
        self._buf = []
        self._file = self.part.open("w", newline="")
        self._csv = csv.writer(self._file)  # floats as repr (shortest round trip), integers as integers
        self._csv.writerow(self.names)

    def add(self, row):
        self._buf.append(row)
        if len(self._buf) >= self.CHUNK:
            self._flush()

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
        self.part.replace(self.path if complete else self.incomplete)

    def envelope(self) -> Envelope:
        return self._env
