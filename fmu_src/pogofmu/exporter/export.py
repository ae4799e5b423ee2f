"""``pogofmu export``: any model — a user's file or the project's own — to its FMUs, one build path.

    pogofmu export ball.py --out dist            # all four kinds, laid out as the project's dist/:
        dist/Ball.fmu               FMI 2.0 co-simulation, Python-hosted
        dist/fmi3/Ball.fmu          FMI 3.0 model exchange + co-simulation (event mode), Python-hosted
        dist/native/Ball.fmu        FMI 2.0, native (C generated from the model; no Python at run time)
        dist/native/fmi3/Ball.fmu   FMI 3.0, native (with sources/)
    pogofmu export ball.py --check               # every check, nothing built

The native FMUs carry binaries for x86_64-linux, aarch64-linux, x86_64-windows, x86_64-darwin and
aarch64-darwin (cross-compiled with zig; ``--platforms`` chooses a subset) and their C sources.

Every FMU is validated (fmpy's validation) as it is written.  A model the native generator cannot
follow still gets its Python-hosted FMUs; the refusal names the file, the line, the construct
and the rewrite, and the exit status is 1.  Exit status 2: a mistake in the model file or the
command line; 1: the machine failed the export (a file that cannot be written: disk full, no
permission, ...; no C compiler) — one line, no traceback, naming what failed.  No temporary file
and no half-written FMU stays behind, whatever ends the export (Ctrl-C included): each FMU is
written beside its name and takes it only once complete and validated.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import List, Optional, Sequence

from .errors import BuildError, ModelFileError, OutputError
from .source import ModelSource, describe_exception, load_model_file, user_frame

KINDS = (("python", 2), ("python", 3), ("native", 2), ("native", 3))


class NativeRefusal(BuildError):
    """The native generator cannot follow the model (the Python-hosted FMUs are still written)."""


def engine_limits() -> dict:
    """The engine's fixed sizes (``#define PG_MAX_*`` of its headers, read from them)."""
    import re

    from pogofmu.codegen.build import NATIVE

    out = {}
    for header in ("engine/pg_engine.h", "engine/pg_pairs.h"):
        for name, value in re.findall(r"#define PG_MAX_(\w+) (\d+)\b", (NATIVE / header).read_text()):
            out[name] = int(value)
    return out


def engine_size_check(source: ModelSource) -> None:
    """A model larger than the engine's fixed sizes is refused for every backend (both run the C
    engine), naming the count, the limit and its constant."""
    from pogofmu.codegen.cmodel import SIZES, model_sizes

    model, limits = source.model, engine_limits()
    counts = model_sizes(model)
    for key, what in SIZES:
        n = counts[key]
        if n > limits[key]:
            raise ModelFileError(f"{source.where()}: {model.name} has {n} {what}; the engine takes at most "
                                 f"{limits[key]} (PG_MAX_{key} in fmu_src/native/engine)")


def native_check(source: ModelSource) -> None:
    """Trace the model as the native generator does; a construct it cannot follow is a
    :class:`NativeRefusal` naming it and what to do."""
    from pogofmu.codegen.cmodel import generate
    from pogofmu.codegen.trace import TraceError

    try:
        generate(source.model)
    except TraceError as exc:
        raise NativeRefusal(f"no native FMU of {source.model.name}: {exc}") from None


class Exporter:
    """Builds the FMUs of models into ``out``; ``cache``: where compiled launchers are kept (a
    temporary folder of this exporter by default)."""

    def __init__(self, out: Path, fmi: Sequence[int] = (2, 3), backends: Sequence[str] = ("python", "native"),
                 cache: Optional[Path] = None, log=print, token_seed: str = "", platforms: Optional[Sequence[str]] = None):
        self.out = Path(out)
        self.kinds = [(b, v) for b, v in KINDS if b in backends and v in fmi]
        self.log = log
        self.token_seed = token_seed
        self._tmp = None
        if cache is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="pogofmu_cache_")
            cache = Path(self._tmp.name)
        self.cache = Path(cache)
        self.refusals: List[str] = []
        # the native FMUs' platforms (FMI 3.0 tuples), the same for every FMU of this export;
        # recorded in pogofmu-build.json
        from pogofmu.codegen.build import parse_platforms

        self.platforms = parse_platforms(platforms or "all")
        # the native FMUs' model-independent objects (engine, adapter, entry files: every file but the
        # model's own two), per platform: kept in the given cache, else in the user's cache folder
        # (keyed by compiler, flags and contents), so that five platforms cost a model's two files each
        from pogofmu.codegen.build import cache_dir

        self.objects = (cache_dir() if self._tmp is not None else self.cache) / "objects"
        self._launchers = {}  # FMI version -> the launcher's compilation (model-independent)
        self._pool = None

    def _start_launchers(self):
        """Start compiling the launchers of every Python-hosted kind, in the background, while the
        first model is checked and its native FMUs compile (only an export needs them, not --check)."""
        if self._launchers or not any(b == "python" for b, _ in self.kinds):
            return
        from concurrent.futures import ThreadPoolExecutor

        from .python_fmu import compile_launcher

        self._pool = ThreadPoolExecutor(max_workers=2)
        for _, version in self.kinds:
            if version not in self._launchers:
                self._launchers[version] = self._pool.submit(compile_launcher, version, self.cache)

    def launcher(self, version: int):
        return self._launchers[version].result()

    def close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def check(self, source: ModelSource) -> Optional[str]:
        """Every check of ``source`` (a mistake raises :class:`ModelFileError`); returns the native
        refusal, if any."""
        from .checks import check_model

        check_model(source)
        engine_size_check(source)
        if any(b == "native" for b, _ in self.kinds):
            try:
                native_check(source)
            except NativeRefusal as exc:
                return str(exc)
        return None

    def export(self, source: ModelSource) -> List[Path]:
        """Check and build the FMUs of one model; returns their paths."""
        from .native_fmu import build_native_fmu
        from .python_fmu import build_python_fmu

        self._start_launchers()
        refusal = self.check(source)
        if refusal:
            self.refusals.append(refusal)
        built = []
        for backend, version in self.kinds:
            if backend == "native":
                if refusal:
                    continue
                from .native_fmu import zig_available

                if not zig_available():
                    self.refusals.append(f"no native FMU of {source.model.name}: no ziglang (pip install ziglang)")
                    continue
            try:
                if backend == "python":
                    fmu = build_python_fmu(source, self.out, version, self.launcher(version), self.token_seed)
                else:
                    fmu = build_native_fmu(source, self.out, version, objects=self.objects, platforms=self.platforms)
            except (BuildError, ModelFileError):
                raise
            except OSError as exc:
                if user_frame(exc.__traceback__, source.user_files()) is None:  # the machine's, not the model's
                    raise OutputError(f"cannot build the FMI {version}.0 {backend} FMU of {source.model.name}: "
                                      f"{exc.filename + ': ' if exc.filename else ''}{exc.strerror or exc}") from None
                raise ModelFileError(describe_exception(exc, source.user_files(), source.where())) from None
            except Exception as exc:  # noqa: BLE001 - a model that fails while building: one line naming its line
                raise ModelFileError(describe_exception(exc, source.user_files(), source.where())) from None
            self.log(f"built and validated {_shown(fmu)}")
            self._record(fmu)
            built.append(fmu)
        return built

    RECORD = "pogofmu-build.json"

    def _record(self, fmu: Path):
        """``<out>/pogofmu-build.json``: what each FMU of the folder carries (its binaries' platforms),
        as the build made it, for whoever checks the folder later (the tests do)."""
        import json
        import zipfile

        from .package import output_file

        with zipfile.ZipFile(fmu) as z:
            platforms = sorted({n.split("/")[1] for n in z.namelist() if n.startswith("binaries/") and n.count("/") == 2})
        path = self.out / self.RECORD
        try:
            record = json.loads(path.read_text()) if path.exists() else {}
        except ValueError:
            record = {}
        record[fmu.relative_to(self.out).as_posix()] = {"binaries": platforms, "platforms": list(self.platforms)}
        with output_file(path) as tmp:
            tmp.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")


def _shown(path: Path) -> str:
    try:
        rel = os.path.relpath(path)
    except ValueError:
        return str(path)
    return str(path) if rel.startswith("..") else rel


def export_files(files: Sequence[str], out: Path, names: Sequence[str] = (), requires: Sequence[str] = (),
                 fmi: Sequence[int] = (2, 3), backends: Sequence[str] = ("python", "native"),
                 log=print, cache: Optional[Path] = None, platforms: Optional[Sequence[str]] = None) -> List[Path]:
    """Export every model of ``files`` (``names``: only those) into ``out``; raises the first mistake.
    Returns the FMUs written (native refusals are in the exception :class:`NativeRefusal` raised
    after everything else is written)."""
    sources = []
    for f in files:
        sources += load_model_file(f, names=names, requires=requires)
    seen = {}
    for s in sources:
        if s.model.name in seen and seen[s.model.name] is not s.model:
            raise ModelFileError(f"{s.where()}: two models named {s.model.name!r} ({seen[s.model.name]} too): "
                                 f"an FMU is named after its model")
        seen[s.model.name] = s.where()
    built = []
    with Exporter(out, fmi, backends, cache=cache, log=log, platforms=platforms) as ex:
        for s in sources:
            built += ex.export(s)
        if ex.refusals:
            raise NativeRefusal("; ".join(ex.refusals))
    return built


def one_line(text) -> str:
    return " | ".join(line.strip() for line in str(text).strip().splitlines() if line.strip())


def main(argv=None, prog="pogofmu export") -> int:
    ap = argparse.ArgumentParser(prog=prog, description="export hybrid models written in Python as FMUs: FMI 2.0 "
                                 "co-simulation and FMI 3.0 model exchange + co-simulation, Python-hosted and "
                                 "native (docs/writing-models.md)",
                                 epilog="exit status: 0 every FMU written; 2 a mistake in a model file or the command "
                                 "line; 1 the machine failed the export (a file that cannot be written: disk full, no "
                                 "permission; no C compiler) or the native generator refused a model (its "
                                 "Python-hosted FMUs are written). A failed export leaves no temporary or "
                                 "half-written file.")
    ap.add_argument("files", nargs="+", metavar="FILE.py", help="model files (each defines MODEL, or HybridModels)")
    ap.add_argument("--out", help="output folder (laid out as dist/: <Model>.fmu, fmi3/, native/, native/fmi3/)")
    ap.add_argument("--model", action="append", default=[], metavar="NAME",
                    help="export only this model of the files (repeatable; default: MODEL, else every HybridModel)")
    ap.add_argument("--fmi", choices=("2", "3"), action="append", help="FMI version (default both; repeatable)")
    ap.add_argument("--backend", choices=("python", "native"), action="append",
                    help="python: the model's Python code behind the launcher; native: C generated from it "
                         "(default both; repeatable)")
    ap.add_argument("--requires", action="append", default=[], metavar="MODULE",
                    help="allow the model to import this third-party module (recorded in the FMU's documentation; "
                         "the target's Python must have it; no native FMU can call it)")
    ap.add_argument("--platforms", metavar="LIST", default="all",
                    help="the native FMUs' binaries: comma-separated FMI 3.0 platform tuples of x86_64-linux, "
                         "aarch64-linux, x86_64-windows, x86_64-darwin, aarch64-darwin (default: all)")
    ap.add_argument("--check", action="store_true", help="run every check, build nothing")
    ap.add_argument("--cache", metavar="DIR", help="keep the compiled launchers and C objects in DIR for the next "
                    "export (default: a temporary folder, removed afterwards)")
    args = ap.parse_args(argv)
    if not args.check and not args.out:
        print(f"{prog}: --out DIR is required (or --check)", file=sys.stderr)
        return 2
    fmi = tuple(int(v) for v in (args.fmi or ("2", "3")))
    from pogofmu.codegen.build import parse_platforms

    try:
        platforms = parse_platforms(args.platforms)
    except ValueError as exc:
        print(f"{prog}: --platforms: {exc}", file=sys.stderr)
        return 2
    backends = tuple(args.backend or ("python", "native"))
    start = time.perf_counter()
    try:
        if args.check:
            refusals = []
            with Exporter(Path(tempfile.gettempdir()), fmi, backends, log=lambda *_: None) as ex:
                for f in args.files:
                    for s in load_model_file(f, names=args.model, requires=args.requires):
                        r = ex.check(s)
                        if r:
                            refusals.append(r)
                        else:
                            print(f"{s.where()}: {s.model.name}: every check passed")
            for r in refusals:
                print(f"{prog}: {one_line(r)}", file=sys.stderr)
            return 1 if refusals else 0
        out = Path(args.out)
        built = export_files(args.files, out, args.model, args.requires, fmi, backends,
                             cache=Path(args.cache) if args.cache else None, platforms=platforms)
    except NativeRefusal as exc:
        print(f"{prog}: {one_line(exc)} (the Python-hosted FMUs are written)", file=sys.stderr)
        return 1
    except ModelFileError as exc:
        print(f"{prog}: {one_line(exc)}", file=sys.stderr)
        return 2
    except BuildError as exc:
        print(f"{prog}: {one_line(exc)}", file=sys.stderr)
        return 1
    except OSError as exc:  # the machine's (a temporary or cache folder that cannot be written, ...)
        print(f"{prog}: {exc.filename + ': ' if exc.filename else ''}{exc.strerror or exc}", file=sys.stderr)
        return 1
    print(f"{len(built)} FMU(s) in {time.perf_counter() - start:.1f} s")
    return 0
