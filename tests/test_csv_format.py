"""The master's CSV rows formatted in C (fmu_src/native/master/pg_csv.c, pogofmu/ssp/record.py):
byte for byte what Python's csv module writes for the same rows (floats as repr, integer columns
as integers), on millions of doubles; the CSVStream's rows from the C value array (bind_slots),
on the run's thread or a writer thread, the same file as the list rows of before; a failed write
the master's one-line error with the rows so far kept; and a 1-ring mirror's run the same file
with and without the C formatting."""
from __future__ import annotations

import csv
import io
import os
import subprocess
import sys

import numpy as np
import pytest

from pogofmu.ssp import record
from pogofmu.ssp.package import SSPError
from support import needs_mark, require

LIB = record.csv_library()
need_c = needs_mark(LIB is not None, "the csv module's C library (a C compiler: Debian gcc, or PyPI ziglang)")


def python_text(block, is_int):
    """What csv.writer writes for the rows as lists (the path of before)."""
    out = io.StringIO()
    w = csv.writer(out)
    ints = [j for j, f in enumerate(is_int) if f]
    for row in np.asarray(block).tolist():
        for j in ints:
            row[j] = int(row[j])
        w.writerow(row)
    return out.getvalue().encode()


def c_text(block, is_int):
    fmt = record.RowFormatter(is_int, LIB)
    pieces = list((bytes(text), end) for text, end in fmt.chunks(np.ascontiguousarray(block, dtype=np.float64)))
    ends = [end for _, end in pieces]
    assert ends == sorted(ends) and ends[-1] == len(block)  # the rows written so far, piece by piece
    text = b"".join(t for t, _ in pieces)
    assert all(text.count(b"\r\n", 0, sum(len(t) for t, _ in pieces[:i + 1])) == e for i, e in enumerate(ends))
    return text


def first_difference(a: bytes, b: bytes):
    for ra, rb in zip(a.split(b"\r\n"), b.split(b"\r\n")):
        if ra != rb:
            for fa, fb in zip(ra.split(b","), rb.split(b",")):
                if fa != fb:
                    return fa, fb
    return len(a), len(b)


def doubles(rng):
    """Over 10^6 doubles of the kinds a run writes and of the hard cases of repr."""
    n = 300_000
    bits = rng.integers(0, 2 ** 63, n, dtype=np.int64) * rng.choice([1, -1], n)
    parts = [
        bits.view(np.float64),  # random 64-bit patterns: every exponent, NaNs among them
        rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-12, 6, n) * rng.uniform(1, 10, n),  # a simulation's
        np.sin(np.arange(n) * 1e-3) / 3,
        np.arange(n) * 1e-3,  # a time grid
        rng.integers(-2 ** 53, 2 ** 53, 50_000).astype(np.float64),  # integers as floats
        rng.integers(-10 ** 6, 10 ** 6, 50_000).astype(np.float64),
        np.ldexp(1.0, np.arange(-1074, 1024)), -np.ldexp(1.0, np.arange(-1074, 1024)),  # powers of two
        np.ldexp(3.0, np.arange(-1074, 1022)),
        rng.integers(1, 2 ** 52, 50_000).view(np.float64),  # subnormals
        np.array([0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 5e-324, 2.2250738585072014e-308,
                  1.7976931348623157e308, 0.1, 0.2, 0.3, 1 / 3, 2 / 3, 1e23, 9007199254740993.0]),
    ]
    for centre in (1e16, 1e15, 1e-4, 1e-5, 1e-3, 1.0, 10.0, 1e22, 1e-300, 1e300):  # layouts' edges
        parts.append(centre * (1 + np.arange(-2000, 2000) * 2.0 ** -52))  # ulp by ulp
        parts.append(centre * (1 + rng.uniform(-1e-3, 1e-3, 5000)))
    parts.append(10.0 ** np.arange(-320, 309))
    # exact decimals half-way between two 17- or 16-digit ones (printf's ties to even)
    parts += [1 + np.arange(1, 20_000) * 2.0 ** -17, np.arange(10 ** 15, 10 ** 15 + 5000) + 0.5,
              np.arange(10 ** 14, 10 ** 14 + 5000) + 0.125, np.arange(1, 5000) * 2.0 ** -40]
    x = np.concatenate(parts)
    return x[: len(x) // 16 * 16]


@need_c
def test_c_rows_are_the_csv_modules_bytes_on_a_million_doubles():
    x = doubles(np.random.default_rng(20261204))
    assert len(x) >= 1_000_000
    block = x.reshape(-1, 16)
    got, want = c_text(block, [0] * 16), python_text(block, [0] * 16)
    assert got == want, first_difference(got, want)


@need_c
def test_c_integer_columns_are_ints():
    rng = np.random.default_rng(5)
    n = 20_000
    block = np.column_stack([
        np.arange(n) * 1e-3,
        rng.integers(-1, 2, n),  # the event column
        rng.integers(-2 ** 31, 2 ** 31, n),  # an FMI Integer
        rng.integers(-2 ** 53, 2 ** 53, n),
        np.where(rng.random(n) < 0.5, -0.0, 0.0),  # int(-0.0) is 0
        rng.choice([1e18, -1e18, 2.0 ** 63, -2.0 ** 63, 1e300, -1.5e308, 2.0 ** 64], n),  # int() of huge doubles
        rng.normal(size=n),
    ]).astype(np.float64)
    is_int = [0, 1, 1, 1, 1, 1, 0]
    got, want = c_text(block, is_int), python_text(block, is_int)
    assert got == want, first_difference(got, want)


@need_c
def test_rows_longer_than_the_text_buffer_and_a_buffer_of_a_few_rows():
    rng = np.random.default_rng(7)
    block = rng.normal(size=(3000, 731)) * 10.0 ** rng.uniform(-12, 6, (3000, 731))
    want = python_text(block, [0] * 731)
    assert c_text(block, [0] * 731) == want
    fmt = record.RowFormatter([0] * 731, LIB)
    fmt._text = np.empty(2 * LIB.pgm_csv_row_max(731, fmt.is_int.ctypes.data), dtype=np.uint8)  # two rows at most
    pieces = [(bytes(text), end) for text, end in fmt.chunks(block[:50])]
    assert len(pieces) >= 25 and b"".join(t for t, _ in pieces) == python_text(block[:50], [0] * 731)


def test_the_python_formatter_is_the_list_path():
    block = np.array([[0.0, 0, 1.5, 3], [1e-3, -1, -0.0, -7]])
    fmt = record.RowFormatter([0, 1, 0, 1], None)
    assert list(fmt.chunks(block)) == [(b"0.0,0,1.5,3\r\n0.001,-1,-0.0,-7\r\n", 2)]


# ---- CSVStream: the rows of bind_slots and of add ------------------------------------------------

NAMES = ["event", "a.x", "a.n", "b.y"]
TYPES = ["Integer", "Real", "Integer", "Real"]


def stream_rows(path, threads, native, steps=10_000, lists_every=997):
    """A run's rows into a CSVStream: from a value array (bind_slots) when ``native``, with a list
    row (a bool, and an int in a real column) now and then; returns the file's bytes."""
    rng = np.random.default_rng(3)
    values = np.zeros(6)
    slots = np.array([4, 1, 2])
    s = record.CSVStream(path, NAMES, TYPES, ["", "m", None, "s"], (0.0, steps * 1e-3), threads=threads)
    put = s.bind_slots(values, slots, [1]) if native else None
    for k in range(steps):
        t = k * 1e-3
        values[4], values[1], values[2] = rng.normal() * 10.0 ** rng.integers(-9, 9), k % 7 - 3, np.sin(t)
        if k % lists_every == 5:
            s.add([t, -1, 3, True, 0.5])
        elif put is not None:
            put(t, k % 3 - 1)
        else:
            s.add([t, k % 3 - 1, float(values[4]), int(values[1]), float(values[2])])
    s.close()
    return path.read_bytes()


@need_c
@pytest.mark.parametrize("threads", [1, 2])
def test_stream_of_slot_rows_is_the_file_of_list_rows(tmp_path, threads):
    want = stream_rows(tmp_path / "lists.csv", 1, native=False)
    assert want.startswith(b"time,event,a.x,a.n,b.y\r\n") and b",-1,3,True,0.5\r\n" in want
    got = stream_rows(tmp_path / f"slots{threads}.csv", threads, native=True)
    assert got == want
    assert not list(tmp_path.glob("*.part"))


def test_without_the_c_formatting_no_slot_rows(tmp_path, monkeypatch):
    monkeypatch.setenv("POGOFMU_SSP_NATIVE_CSV", "0")
    s = record.CSVStream(tmp_path / "r.csv", NAMES, TYPES, [None] * 4, (0.0, 1.0), threads=2)
    assert s.bind_slots(np.zeros(3), np.arange(3), []) is None  # Exchange keeps the list rows
    s.close()


class FullDisk:
    """A file whose writes fail after ``room`` bytes, as a full disk's do."""

    def __init__(self, out, room):
        self.out, self.room = out, room

    def write(self, data):
        self.room -= len(data)
        if self.room < 0:
            raise OSError(28, "No space left on device")
        return self.out.write(data)


@pytest.mark.parametrize("threads,native", [(1, True), (2, True), (1, False), (2, False)])
def test_a_failed_write_is_the_masters_error_and_the_rows_so_far_are_kept(tmp_path, threads, native):
    if native:
        require(LIB is not None, "the csv module's C library (a C compiler: Debian gcc, or PyPI ziglang)")
    s = record.CSVStream(tmp_path / "r.csv", NAMES, TYPES, [None] * 4, (0.0, 100.0), threads=threads)
    s._out = FullDisk(s._out, 3_000_000)
    values = np.zeros(6)
    put = s.bind_slots(values, np.array([4, 1, 2]), [1]) if native else None
    with pytest.raises(SSPError) as exc:
        for k in range(400_000):
            values[4] = k * 0.1
            if put:
                put(k * 1e-3, 0)
            else:
                s.add([k * 1e-3, 0, k * 0.1, 0, 0.0])
        s.close(complete=True)
    assert str(exc.value) == f"cannot write {tmp_path / 'r.csv'}: No space left on device"
    s.close(complete=False)  # what simulate() does after the error: no second error, no hang
    assert not (tmp_path / "r.csv").exists() and not (tmp_path / "r.csv.part").exists()
    text = (tmp_path / "r.incomplete.csv").read_bytes()
    assert 0 < s.rows and text.count(b"\r\n") == s.rows + 1 and text.endswith(b"\r\n")
    assert float(text.rsplit(b"\r\n", 2)[1].split(b",")[0]) == s.last_time


# ---- a run of the master: the same file as the csv module's ---------------------------------------

@pytest.fixture(scope="module")
def mirror(tmp_path_factory):
    from support import run_pogofmu

    folder = tmp_path_factory.mktemp("csv")
    proc = run_pogofmu("mirror", "--rings", "1", "--backend", "native", "--out", "m.ssp", cwd=folder,
                       timeout=600)
    assert proc.returncode == 0, proc.stderr
    return folder


def run_master(folder, name, *args, env=None):
    return subprocess.run([sys.executable, "-m", "pogofmu.ssp", "run", "m.ssp", "--step", "1e-3", "--stop-time",
                           "0.8", "--quiet", "--out", name, *args], cwd=folder, capture_output=True, text=True,
                          env={**os.environ, **(env or {})}, timeout=600)


@need_c
def test_a_runs_csv_is_the_csv_modules_file(mirror):
    """The 1-ring mirror (events, actuators on their stops): the CSV of the C formatting (one
    thread; two, with the writer thread) is byte for byte that of the csv module (list rows,
    POGOFMU_SSP_NATIVE_CSV=0) and of the whole Python master (POGOFMU_SSP_NATIVE_LEVELS=0)."""
    files = {}
    for name, threads, env in (("py", "1", {"POGOFMU_SSP_NATIVE_LEVELS": "0"}),
                               ("lists", "2", {"POGOFMU_SSP_NATIVE_CSV": "0"}),
                               ("c1", "1", None), ("c2", "2", None)):
        proc = run_master(mirror, name, "--threads", threads, env=env)
        assert proc.returncode == 0, proc.stderr
        files[name] = (mirror / name / "default.csv").read_bytes()
    assert files["py"].count(b"\r\n") > 801 and b",-1," in files["py"]  # event rows among the grid's
    assert files["c1"] == files["py"] and files["c2"] == files["py"] and files["lists"] == files["py"]


@need_c
@needs_mark(os.name == "posix", "RLIMIT_FSIZE (a POSIX system)")
def test_a_run_whose_file_cannot_grow_ends_in_one_line_with_the_rows_kept(mirror):
    """The file size limit (EFBIG, as a full disk's ENOSPC) reached on the writer thread: the
    master's one line, its rows so far in default.incomplete.csv."""
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (2_000_000, 2_000_000))

    proc = subprocess.run([sys.executable, "-m", "pogofmu.ssp", "run", "m.ssp", "--step", "1e-3", "--stop-time",
                           "3", "--quiet", "--threads", "2", "--out", "big"], cwd=mirror, capture_output=True,
                          text=True, preexec_fn=limit, timeout=600)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert lines[0] == f"error: cannot write {os.path.join('big', 'default.csv')}: File too large", proc.stderr
    assert "default.incomplete.csv" in lines[1]
    assert not (mirror / "big" / "default.csv").exists()
    assert (mirror / "big" / "default.incomplete.csv").stat().st_size > 1_000_000


@need_c
def test_with_two_threads_the_pools_workers_format_the_rows_between_their_batches(mirror):
    """``--threads 2``: the writer thread hands its blocks to the C level stepping's pool
    (pgm_pool_csv_rows, formatted by the worker between its batches); the file is byte for byte
    the one-thread run's, and no block was formatted outside the pool."""
    code = ("import sys, ctypes\n"
            "from pogofmu.ssp import cli, native_level\n"
            "calls = {'pool': 0, 'other': 0}\n"
            "orig = native_level.NativeLevels.csv_rows\n"
            "def counted(self, *args):\n"
            "    calls['pool' if self.pool else 'other'] += 1\n"
            "    return orig(self, *args)\n"
            "native_level.NativeLevels.csv_rows = counted\n"
            "cli.plot = lambda *a, **k: None\n"
            "cli.run('m.ssp', stop_time=0.8, step=1e-3, out='pooled', progress=False, threads=2)\n"
            "print(calls['pool'], calls['other'])\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=mirror, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    pooled, other = map(int, proc.stdout.split()[-2:])
    one = run_master(mirror, "one", "--threads", "1")
    assert one.returncode == 0, one.stderr
    text = (mirror / "pooled" / "default.csv").read_bytes()
    assert pooled >= 2 and other == 0  # (blocks of ~2^15 values: several for 800 rows)
    assert text == (mirror / "one" / "default.csv").read_bytes() and text.count(b"\r\n") > 801
