"""The master's CSV rows, in-process: 500 rows of 731 columns (a 4-ring segmented mirror's, a
simulation's magnitudes) written by the list path of before (a list per row from the value array,
csv.writer: POGOFMU_SSP_NATIVE_CSV=0) and by the C formatting (CSVStream.bind_slots), on the run's
thread (--threads 1) and on the writer thread (--threads 2).

Printed per path: the time of the 500 ``row`` calls (what the run's thread spends, holding the
GIL but for the C calls), and the time to the file being closed (everything written; the
envelope of 16 plotted columns included, as in a run).

    PYTHONPATH=fmu_src python benchmarks/bench_csv_rows.py [--rows 500] [--cols 731]
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def one(path, rows, cols, threads, native):
    from pogofmu.ssp import record

    rng = np.random.default_rng(1)
    n_slots = cols - 2
    values = rng.uniform(-1, 1, 2 * n_slots) * 10.0 ** rng.uniform(-12, 6, 2 * n_slots)
    slots = np.arange(0, 2 * n_slots, 2)
    ints = list(range(0, n_slots, 40))  # a few integer columns (the actuators' modes, event counters)
    values[slots[ints]] = rng.integers(-1, 2, len(ints))
    names = ["event"] + [f"c{j}.y" for j in range(n_slots)]
    types = ["Integer"] + ["Integer" if j in ints else "Real" for j in range(n_slots)]
    s = record.CSVStream(path, names, types, [None] * len(names), (0.0, rows * 1e-3), threads=threads)
    s.plot_only(names[:: len(names) // 16][:16])  # the figure's signals only, as simulate() asks
    put = s.bind_slots(values, slots, ints) if native else None
    assert (put is not None) == native
    t0 = time.perf_counter()
    for k in range(rows):
        values[1::2] += 1e-9  # (not a recorded slot: the numbers stay those of the file compared)
        t = k * 1e-3
        if put is not None:
            put(t, 0)
        else:  # Exchange.row_values of before: a list from the slots, its integers as ints
            out = values[slots].tolist()
            for p in ints:
                out[p] = int(out[p])
            s.add([t, 0, *out])
    t_rows = time.perf_counter() - t0
    s.close()
    return t_rows, time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", type=int, default=500)
    ap.add_argument("--cols", type=int, default=731)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        files = {}
        for label, threads, native in (("old: lists + csv.writer", 1, False), ("new: C, --threads 1", 1, True),
                                       ("new: C, --threads 2", 2, True)):
            best = None
            for r in range(args.repeat):
                path = Path(tmp) / f"{threads}{native}{r}.csv"
                got = one(path, args.rows, args.cols, threads, native)
                best = got if best is None or got[1] < best[1] else best
                files[label] = path.read_bytes()
            print(f"{label:26s} rows {best[0] * 1e3:8.1f} ms ({best[0] / args.rows * 1e3:.3f} ms/row), "
                  f"closed {best[1] * 1e3:8.1f} ms")
        same = len({*files.values()}) == 1
        print(f"{args.rows} rows x {args.cols} columns, {len(next(iter(files.values()))) / 1e6:.1f} MB; "
              f"the files {'are' if same else 'are NOT'} byte-identical")


if __name__ == "__main__":
    os.environ.setdefault("POGOFMU_SSP_NATIVE_CSV", "1")
    main()
