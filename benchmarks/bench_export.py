#!/usr/bin/env python3
"""Benchmark (h): ``pogofmu export`` of a user's model against pythonfmu's ``pythonfmu build``;
benchmark (i): the native FMUs' five platforms against two.

The bouncing ball of docs/writing-models.md (examples/ball/ball.py), exported as a user does:

* **pogofmu, four FMUs**: ``pogofmu export ball.py --out DIR`` — FMI 2.0 CS and FMI 3.0 ME + CS,
  Python-hosted and native (binaries for five platforms, cross-compiled with zig), each validated;
* **pogofmu, one FMU**: ``--fmi 2 --backend python``, the same kind as pythonfmu's;
* **pogofmu, one FMU, cached**: the same with ``--cache DIR`` (the launcher compiled by an earlier run);
* **pythonfmu**: ``pythonfmu build -f ball_slave.py`` of the same ball written as a pythonfmu
  slave (one FMI 2.0 co-simulation FMU, no event location, no validation).

Each command runs as a whole process, ``--repeat`` rounds (default 5) in rotated order, the best
wall time of each counts (the commands run on one core at a time but for the compiler jobs).
Printed: the seconds of each and the ratios; the target: the four FMUs
in at most 10 s on this 2-core machine.

(i) ``pogofmu export ball.py`` (the four kinds) with the native FMUs' five platforms (the default)
against ``--platforms x86_64-linux,x86_64-windows`` (the two the native FMUs had before zig), in
the same run, the same rounds: warm — each with its own ``--cache DIR`` filled by one export
beforehand, as every export after a user's first (the engine's and adapter's objects compiled,
only the model's two files per platform to compile) — and cold (a fresh cache each time; zig's
own cache of the targets' C libraries warm in both).  The target: five / two <= 2 warm.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

PYTHONFMU_BALL = '''\
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Ball(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.h, self.v, self.g, self.e = 1.0, 0.0, 9.81, 0.8
        self.register_variable(Real("h", causality=Fmi2Causality.output))
        self.register_variable(Real("v", causality=Fmi2Causality.output))
        self.register_variable(Real("g", causality=Fmi2Causality.parameter))
        self.register_variable(Real("e", causality=Fmi2Causality.parameter))

    def do_step(self, current_time, step_size):
        self.v -= self.g * step_size
        self.h += self.v * step_size
        if self.h < 0:
            self.h, self.v = -self.h, -self.e * self.v
        return True
'''


def best_wall(commands, repeat, cwd):
    """{name: best wall seconds} of whole-process commands, in rotated rounds."""
    names = list(commands)
    best = {n: float("inf") for n in names}
    for r in range(repeat):
        for n in names[r % len(names):] + names[:r % len(names)]:
            out = Path(cwd) / f"out_{n.replace(' ', '_')}"
            shutil.rmtree(out, ignore_errors=True)
            t0 = time.perf_counter()
            proc = subprocess.run(commands[n](out), cwd=cwd, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            if proc.returncode:
                sys.exit(f"{n} failed: {proc.stderr.strip().splitlines()[-1:]}")
            best[n] = min(best[n], wall)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    pogofmu = [sys.executable, "-m", "pogofmu.cli", "export", "ball.py"]
    pythonfmu = shutil.which("pythonfmu", path=str(Path(sys.executable).parent)) or "pythonfmu"
    with tempfile.TemporaryDirectory(prefix="pogofmu-bench-export-") as tmp:
        shutil.copy2(ROOT / "examples" / "ball" / "ball.py", Path(tmp) / "ball.py")
        (Path(tmp) / "ball_slave.py").write_text(PYTHONFMU_BALL)
        commands = {
            "pogofmu, four FMUs": lambda out: pogofmu + ["--out", str(out)],
            "pogofmu, one FMU": lambda out: pogofmu + ["--out", str(out), "--fmi", "2", "--backend", "python"],
            "pogofmu, one, cached": lambda out: pogofmu + ["--out", str(out), "--fmi", "2", "--backend", "python",
                                                           "--cache", str(Path(tmp) / "cache")],
            "pythonfmu, one FMU": lambda out: [pythonfmu, "build", "-f", "ball_slave.py", "-d", str(out)],
        }
        best = best_wall(commands, args.repeat, tmp)
    print(f"(h) exporting the bouncing ball, best wall time of {args.repeat} rotated runs")
    for n, s in best.items():
        print(f"  {n:<22} {s:6.2f} s")
    four, one, peer = best["pogofmu, four FMUs"], best["pogofmu, one FMU"], best["pythonfmu, one FMU"]
    print(f"  one FMU: pogofmu / pythonfmu = {one / peer:.2f}x; four FMUs / pythonfmu's one = {four / peer:.2f}x")
    print(f"  target: four FMUs <= 10 s: {'holds' if four <= 10.0 else 'MISSED'} ({four:.2f} s)")
    ratio = platforms(args.repeat)
    return 0 if four <= 10.0 and ratio <= 2.0 else 1


TWO = "x86_64-linux,x86_64-windows"


def platforms(repeat):
    """(i): the four kinds with five platforms against two, warm and cold; returns the warm ratio."""
    pogofmu = [sys.executable, "-m", "pogofmu.cli", "export", "ball.py"]
    with tempfile.TemporaryDirectory(prefix="pogofmu-bench-platforms-") as tmp:
        shutil.copy2(ROOT / "examples" / "ball" / "ball.py", Path(tmp) / "ball.py")
        caches = {n: Path(tmp) / f"cache_{n}" for n in ("five", "two")}
        for n, extra in (("five", []), ("two", ["--platforms", TWO])):  # fill each warm cache once
            subprocess.run(pogofmu + ["--out", str(Path(tmp) / "fill"), "--cache", str(caches[n]), *extra],
                           cwd=tmp, check=True, capture_output=True)

        def fresh(out):
            cache = Path(str(out) + "_cache")
            shutil.rmtree(cache, ignore_errors=True)
            return ["--cache", str(cache)]
        commands = {
            "five, warm": lambda out: pogofmu + ["--out", str(out), "--cache", str(caches["five"])],
            "two, warm": lambda out: pogofmu + ["--out", str(out), "--cache", str(caches["two"]), "--platforms", TWO],
            "five, cold": lambda out: pogofmu + ["--out", str(out), *fresh(out)],
            "two, cold": lambda out: pogofmu + ["--out", str(out), *fresh(out), "--platforms", TWO],
        }
        best = best_wall(commands, repeat, tmp)
    print(f"(i) the four kinds, native FMUs with five platforms against two ({TWO}), best of {repeat}")
    for n, s in best.items():
        print(f"  {n:<12} {s:6.2f} s")
    warm, cold = best["five, warm"] / best["two, warm"], best["five, cold"] / best["two, cold"]
    print(f"  five / two: warm {warm:.2f}x, cold {cold:.2f}x; target warm <= 2x: {'holds' if warm <= 2.0 else 'MISSED'}")
    return warm


if __name__ == "__main__":
    sys.exit(main())
