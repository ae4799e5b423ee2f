#!/usr/bin/env python3
"""Benchmark (b): each case's FMU through ``fmpy.simulate_fmu`` against the FMI floor.

The FMI floor of a case is **its own FMU with the model's work taken out**: the same build (the
project's launcher, the same variables, the same output buffers, the same FMI traffic), whose
slave's ``do_step`` returns at once (:func:`floor_of` rewrites the slave module inside a copy of
the built ``.fmu``; the outputs stay those of the start).  It measures what fmpy and the
project's launcher cost per communication step before any model code runs.  The FMUs are built
into a temporary folder (``pogofmu.exporter.build_project(tmp, names)``, never into dist/), then run
alternately through ``fmpy.simulate_fmu`` with fmpy's defaults (validation, extraction to a
temporary folder), ``stop_time`` = the case's, ``output_interval = 1e-3``; the best CPU time
(``time.process_time``) of ``--repeat`` runs of each counts (the median is printed too).  The FMU
runs with the case's parameters and its own solver defaults (method 0, rel_tol 1e-6, max_step 0.01).

Two like-for-like peers, both judged against the target:

* ``FMU/floor-io``: the FMU and its floor, every output recorded at every communication point (as
  fmpy does by default): the ratio is what the model's own work adds;
* ``1-out/floor``: the FMU and its floor with fmpy recording one output (``output=[...]``).

``FMU/floor`` (every output of the FMU against the one-output floor) is printed for information:
it mostly measures fmpy recording every output instead of one.  ``native/floor-io``: the case's
native FMU (``dist/native/``, no Python) the same way, every output recorded, against the same
floor; its table must equal the Python-hosted FMU's to the bit (else the benchmark stops).

A third peer, the C importer: the tests' C host ``tests/c_host/fmi2_host.c``, compiled
here with the system compiler and ``-DRECORD_IN_MEMORY``, loads the FMU's binary with ``dlopen(RTLD_LOCAL)`` in a process with no Python (the
launcher brings its own interpreter) and records every output at every point in memory, as
fmpy does.  Its CPU time (``getrusage`` of the child) is compared with fmpy's *per communication
step*: the fixed costs of each (fmpy reading and extracting the FMU; the C host starting an
interpreter) are measured by a run of one step and subtracted, ``(T(stop) - T(one step)) / n``.

Targets, judged and printed for every case (the ``met`` column):

* the FMU through fmpy within 1.2x the do-nothing FMU with the same outputs
  (``FMU/floor-io``), and the C host at least 3x faster per step than fmpy (``fmpy/C``);
* ``1-out/floor`` at most 3x.

Exit status 1 if one is missed (on any case).

    python benchmarks/bench_fmu.py [--repeat 7] [--case PogoStick ...]
"""
from __future__ import annotations

import argparse
import gc
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from cases import all_cases  # noqa: E402

OUTPUT_INTERVAL = 1e-3
FLOOR_TARGET = 3.0  # 1-out/floor
FLOOR_IO_TARGET = 1.2  # FMU/floor-io
C_HOST_TARGET = 3.0  # fmpy per step / C host per step


def quiet():
    import contextlib
    import io

    return contextlib.redirect_stdout(io.StringIO())


FLOOR_STEP = """

    def do_step(self, current_time, step_size):  # the FMI floor (bench_fmu.py): no model work
        return True
"""


def callgrind_instructions(cmd, env=None) -> int:
    """The instructions a whole process executes, valgrind's callgrind count (repeatable whatever
    the machine's load): benchmarks (f) and (g) count with it."""
    import re
    import subprocess

    proc = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", *map(str, cmd)],
                          capture_output=True, text=True, env=env)
    found = re.search(r"Collected : (\d+)", proc.stderr)
    if proc.returncode or not found:
        raise SystemExit(f"callgrind run of {Path(str(cmd[0])).name} failed ({proc.returncode}): "
                         f"{proc.stderr[-2000:]}")
    return int(found.group(1))


def build(dest: Path, names):
    """Build the cases' FMUs (FMI 2.0) into ``dest``; return {name: path}."""
    from pogofmu.exporter import build_project

    with quiet():
        built = build_project(dest, sorted(set(names)), cache=ROOT / "build" / "native")
    fmus = {Path(p).stem: Path(p) for p in built if Path(p).parent == dest}  # FMI 2.0 (FMI 3.0: dest/fmi3/)
    fmus.update({f"native/{Path(p).stem}": Path(p) for p in built if Path(p).parent == dest / "native"})
    return fmus


def floor_of(fmu: Path, dest: Path) -> Path:
    """A copy of ``fmu`` whose slave does nothing in ``do_step`` (the class is the last thing in
    its slave module): the same launcher, variables, start values, buffers and token, no model
    work.  Its Python package is renamed (``<package>_floor``, in every path and text of
    resources/), since a process imports each package once by name and would otherwise run the
    floor with the FMU's code, or the FMU with the floor's."""
    import zipfile

    out = dest / "floor" / fmu.name
    out.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        launch = src.read("resources/pogofmu_launch.txt").decode()
        package = next(line.split("=", 1)[1] for line in launch.splitlines() if line.startswith("package="))
        renamed = f"{package}_floor"
        slave = f"resources/{package}_slave.py"
        for item in src.infolist():
            data = src.read(item)
            if item.filename == slave:
                data = data.rstrip(b"\n") + FLOOR_STEP.encode()
            if item.filename.startswith("resources/") and item.filename.endswith((".py", ".txt")):
                data = data.replace(package.encode(), renamed.encode())
            info = zipfile.ZipInfo(item.filename.replace(package, renamed), item.date_time)
            info.compress_type, info.external_attr = item.compress_type, item.external_attr
            dst.writestr(info, data)
    return out


def simulate(fmu: Path, stop_time, start_values, output=None):
    from fmpy import simulate_fmu

    gc.collect()
    t0 = time.process_time()  # CPU time of this process: less disturbed by other load than wall time
    res = simulate_fmu(str(fmu), stop_time=stop_time, output_interval=OUTPUT_INTERVAL,
                       start_values=start_values, output=output)
    dt = time.process_time() - t0
    if abs(res["time"][-1] - stop_time) > 1e-9:  # a refused step ends simulate_fmu quietly
        raise SystemExit(f"{fmu.name}: the run stopped at t = {res['time'][-1]} < {stop_time}")
    return dt, res


def compile_c_host(dest: Path) -> Path:
    import shutil
    import subprocess

    from pogofmu.exporter import fmi_headers

    exe = dest / "fmi2_record"
    cc = shutil.which("cc") or shutil.which("gcc")
    subprocess.run([cc, "-O2", "-DRECORD_IN_MEMORY", f"-I{fmi_headers()}",
                    str(ROOT / "tests" / "c_host" / "fmi2_host.c"), "-o", str(exe), "-ldl"], check=True)
    return exe


class CHost:
    """One FMU run by the C importer in a fresh process with a bare environment."""

    def __init__(self, exe: Path, fmu: Path, dest: Path):
        import zipfile

        from fmpy import read_model_description

        self.exe, self.dir = exe, dest / f"unzip_{fmu.stem}"
        with zipfile.ZipFile(fmu) as z:
            z.extractall(self.dir)
        md = read_model_description(str(fmu))
        outs = [v for v in md.modelVariables if v.causality == "output"]
        vrs = lambda kind: ",".join(str(v.valueReference) for v in outs if v.type == kind) or "-"  # noqa: E731
        self.args = [md.coSimulation.modelIdentifier, md.guid]
        self.reals, self.ints = vrs("Real"), vrs("Integer")

    def run(self, stop_time) -> float:
        import resource
        import subprocess

        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        proc = subprocess.run([str(self.exe), str(self.dir), *self.args, repr(stop_time), repr(OUTPUT_INTERVAL),
                               self.reals, self.ints], capture_output=True, text=True,
                              env={"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8"})
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if proc.returncode:
            raise SystemExit(f"C host failed ({proc.returncode}): {proc.stderr[-2000:]}")
        return (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=7, help="timed runs of each FMU (best counts)")
    ap.add_argument("--case", action="append", help="run only this case (name or FMU; repeatable)")
    args = ap.parse_args(argv)
    cases = all_cases(args.case)

    with tempfile.TemporaryDirectory(prefix="pogofmu-bench-") as tmp:
        fmus = build(Path(tmp), [c.fmu for c in cases])
        c_exe = compile_c_host(Path(tmp))
        print(f"(b) FMU through fmpy.simulate_fmu vs the FMI floor (the same FMU through the project's "
              f"launcher, its do_step emptied): output_interval {OUTPUT_INTERVAL:g}; best of {args.repeat} "
              f"rotating runs (median in brackets).\n    like for like (the targets): FMU vs floor-io, "
              f"every output recorded from each;\n    1-out vs floor, one output recorded from "
              f"each. FMU/floor (all outputs vs one) for information only")
        print("    C host: the same FMU in a C importer (no Python in the process); per-step CPU time "
              "of fmpy and of the C host, fixed costs subtracted")
        head = (f"{'case':<14} {'steps':>6} {'outputs':>7} {'FMU s':>15} {'floor-io s':>15} "
                f"{'FMU/floor-io':>12} {'floor s':>15} {'1-out/floor':>11} {'C host s':>8} "
                f"{'fmpy us/st':>10} {'C us/st':>7} {'fmpy/C':>6}  {'met':>4} {'FMU/floor':>9} {'events':>6} "
                f"{'native s':>8} {'native/floor-io':>15}")
        print(head)
        print("-" * len(head))
        missed = []
        for case in cases:
            n_steps = round(case.stop_time / OUTPUT_INTERVAL)
            floor = floor_of(fmus[case.fmu], Path(tmp))
            from fmpy import read_model_description

            first = next(v.name for v in read_model_description(str(fmus[case.fmu])).modelVariables
                         if v.causality == "output")
            runs = {"fmu": (fmus[case.fmu], dict(case.params), None), "floor": (floor, {}, [first]),
                    "io": (floor, {}, None), "one": (fmus[case.fmu], dict(case.params), [first]),
                    "native": (fmus[f"native/{case.fmu}"], dict(case.params), None)}
            times = {key: [] for key in runs}
            results = {}
            # the C host runs the default experiment (it sets no parameters)
            host = None if case.params else CHost(c_exe, fmus[case.fmu], Path(tmp))
            if host is not None:  # the C host's run, and both fixed costs (one step)
                runs.update(c=None, c1=None, fmu1=(fmus[case.fmu], dict(case.params), None))
                times.update(c=[], c1=[], fmu1=[])
            short = OUTPUT_INTERVAL  # the one-step runs
            for key, run in runs.items():  # untimed warm-up: imports, caches
                if run is not None:
                    simulate(run[0], short if key == "fmu1" else case.stop_time, run[1], run[2])
            keys = list(runs)
            for i in range(args.repeat):
                for key in keys[i % len(keys):] + keys[:i % len(keys)]:  # rotate the order
                    if key in ("c", "c1"):
                        times[key].append(host.run(case.stop_time if key == "c" else short))
                        continue
                    fmu, start, output = runs[key]
                    dt, results[key] = simulate(fmu, short if key == "fmu1" else case.stop_time, start, output)
                    times[key].append(dt)
            best = {key: min(v) for key, v in times.items()}
            med = {key: statistics.median(v) for key, v in times.items()}
            res = results["fmu"]
            ratio_io = best["fmu"] / best["io"]
            ratio_one = best["one"] / best["floor"]
            if host is not None:
                per_fmpy = (best["fmu"] - best["fmu1"]) / (n_steps - 1)
                per_c = (best["c"] - best["c1"]) / (n_steps - 1)
                ratio_c = per_fmpy / per_c
                c_cols = f"{best['c']:>8.3f} {per_fmpy * 1e6:>10.2f} {per_c * 1e6:>7.2f} {ratio_c:>5.2f}x"
            else:
                ratio_c, c_cols = math.inf, f"{'-':>8} {'-':>10} {'-':>7} {'-':>6}"
            checks = {f"FMU/floor-io {ratio_io:.2f}x > {FLOOR_IO_TARGET:g}x": ratio_io <= FLOOR_IO_TARGET,
                      f"1-out/floor {ratio_one:.2f}x > {FLOOR_TARGET:g}x": ratio_one <= FLOOR_TARGET}
            if host is not None:  # (a case with parameters has no C-host run: the C host sets none)
                checks[f"fmpy/C host {ratio_c:.2f}x < {C_HOST_TARGET:g}x"] = ratio_c >= C_HOST_TARGET
            ok = all(checks.values())
            n_out = len(res.dtype.names) - 1
            n_events = int(res["n_events"][-1]) if "n_events" in res.dtype.names else -1
            print(f"{case.name:<14} {n_steps:>6} {n_out:>7} "
                  f"{best['fmu']:>6.3f} ({med['fmu']:.3f}) {best['io']:>6.3f} ({med['io']:.3f}) "
                  f"{ratio_io:>11.2f}x {best['floor']:>6.3f} ({med['floor']:.3f}) {ratio_one:>10.2f}x {c_cols}  "
                  f"{'yes' if ok else 'NO':>4} {best['fmu'] / best['floor']:>8.2f}x {n_events:>6} "
                  f"{best['native']:>8.3f} {best['native'] / best['io']:>14.2f}x", flush=True)
            if results["native"]["time"][-1] != res["time"][-1] or not all(
                    np.array_equal(results["native"][k], res[k]) for k in res.dtype.names):
                raise SystemExit(f"{case.name}: the native FMU's table differs from the Python-hosted FMU's")
            if not ok:
                missed.append(f"{case.name}: " + ", ".join(k for k, v in checks.items() if not v))
    if missed:
        print("target MISSED: " + "; ".join(missed))
        return 1
    print(f"targets hold on every case: FMU/floor-io <= {FLOOR_IO_TARGET:g}x, 1-out/floor <= {FLOOR_TARGET:g}x, "
          f"fmpy/C host >= {C_HOST_TARGET:g}x per step")
    return 0


if __name__ == "__main__":
    sys.exit(main())
