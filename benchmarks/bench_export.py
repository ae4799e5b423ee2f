#!/usr/bin/env python3
"""Benchmark (h): ``pogofmu export`` of a user's model against pythonfmu's ``pythonfmu build``.

The bouncing ball of docs/writing-models.md (examples/ball/ball.py), exported as a user does:

* **pogofmu, four FMUs**: ``pogofmu export ball.py --out DIR`` — FMI 2.0 CS and FMI 3.0 ME + CS,
  Python-hosted and native (with the Windows DLL where mingw-w64 is installed), each validated;
* **pogofmu, one FMU**: ``--fmi 2 --backend python``, the same kind as pythonfmu's;
* **pogofmu, one FMU, cached**: the same with ``--cache DIR`` (the launcher compiled by an earlier run);
* **pythonfmu**: ``pythonfmu build -f ball_slave.py`` of the same ball written as a pythonfmu
  slave (one FMI 2.0 co-simulation FMU, no event location, no validation).

Each command runs as a whole process, ``--repeat`` rounds (default 5) in rotated order, the best
wall time of each counts (the commands run on one core at a time but for the compiler jobs).
Printed: the seconds of each and the ratios; the target: the four FMUs
in at most 10 s on this 2-core machine.
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
    return 0 if four <= 10.0 else 1


if __name__ == "__main__":
    sys.exit(main())
