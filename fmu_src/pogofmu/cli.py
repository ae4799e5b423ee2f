"""The ``pogofmu`` command (declared in pyproject.toml's [project.scripts]); ``pogofmu --help``."""
from __future__ import annotations

import os
import sys

# command: (module, function, one line for --help); each gets the rest of the line and its own prog
COMMANDS = {
    "export": ("pogofmu.exporter.export", "main", "export model files (HybridModels) as FMUs: FMI 2.0/3.0, Python-hosted/native"),
    "run": ("pogofmu.experiments", "main", "simulate each FMU's default experiment: CSV, event table, figures"),
    "ssp": ("pogofmu.ssp.cli", "main", "run or check an SSP system (events synchronized, or model exchange)"),
    "sweep": ("pogofmu.sweep", "sweep_main", "grids and Monte Carlo of an FMU or a system on Dask, to Parquet"),
    "study": ("pogofmu.studies", "study_main", "the studies: work-precision, soil, landing, coupling"),
    "mirror": ("pogofmu.studies.mirror", "main", "the SSP system of a segmented telescope mirror of R rings"),
}


def usage() -> str:
    lines = ["usage: pogofmu [--version] [--help] COMMAND [ARGS ...]", "",
             "FMUs of hybrid models with exact state events: export, run, compose, sweep and study them.", "",
             "commands:"]
    lines += [f"  {name:7s} {text}" for name, (_, _, text) in COMMANDS.items()]
    lines += ["", "pogofmu COMMAND --help tells each command's options. Errors are one line; --debug (where a",
              "command has it) or POGOFMU_DEBUG=1 shows the traceback of an unexpected one."]
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    if not argv:
        print(usage(), file=sys.stderr)
        return 2
    if argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    if argv[0] in ("-V", "--version"):
        from pogofmu import __version__

        print(f"pogofmu {__version__}")
        return 0
    cmd, rest = argv[0], argv[1:]
    if cmd == "ssp" and rest[:1] == ["mirror"]:  # (the mirror's command before it left the SSP package)
        cmd, rest = "mirror", rest[1:]
    if cmd not in COMMANDS:
        print(f"pogofmu: unknown command {cmd!r}: the commands are {', '.join(COMMANDS)} (pogofmu --help)",
              file=sys.stderr)
        return 2
    module, function, _ = COMMANDS[cmd]
    import importlib

    try:
        return getattr(importlib.import_module(module), function)(rest, prog=f"pogofmu {cmd}") or 0
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the last resort: one line, never a traceback by default
        if os.environ.get("POGOFMU_DEBUG", "") not in ("", "0") or "--debug" in rest:
            raise
        print(f"error: unexpected {type(exc).__name__}: {exc} -- this is a bug of pogofmu, please report it "
              f"(POGOFMU_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
