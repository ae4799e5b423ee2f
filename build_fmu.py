#!/usr/bin/env python3
"""Build every FMU of the project into dist/, validate it, and pack the SSP systems.

A thin caller of the package's exporter (:func:`pogofmu.exporter.build_project`, the code behind
``pogofmu export``): for each model of ``fmu_src/pogofmu/runtime/models/`` the four FMUs —
``dist/<Model>.fmu`` (FMI 2.0 co-simulation), ``dist/fmi3/<Model>.fmu`` (FMI 3.0 model exchange and
co-simulation with event mode), ``dist/native/<Model>.fmu`` and ``dist/native/fmi3/<Model>.fmu``
(native: C generated from the model, no Python at run time) — then every
``ssp/<System>/SystemStructure.ssd`` packed into ``dist/<System>.ssp`` (SSP 1.0) and
``dist/<System>-fmi3.ssp`` (SSP 2.0).  Compiled launchers are cached in ``build/``.

Usage: ``python build_fmu.py [--dest dist] [NAME ...]`` (names of models, default: all).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT / "fmu_src"))  # this checkout's package, whichever pogofmu is installed


def main(argv=None):
    from pogofmu.exporter import BuildError, build_project

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dest", default=str(ROOT / "dist"), help="output folder (default: dist/)")
    ap.add_argument("--platforms", default="all", help="the native FMUs' binaries: comma-separated FMI 3.0 platform "
                    "tuples (x86_64-linux, aarch64-linux, x86_64-windows, x86_64-darwin, aarch64-darwin; default: all)")
    ap.add_argument("names", nargs="*", help="models to build (default: all, and the SSP systems)")
    args = ap.parse_args(argv)
    from pogofmu.codegen.build import parse_platforms

    try:
        platforms = parse_platforms(args.platforms)
        return build_project(Path(args.dest).resolve(), args.names, ssp_dir=ROOT / "ssp", cache=ROOT / "build" / "native",
                             platforms=platforms)
    except ValueError as exc:
        sys.exit(f"build_fmu.py: --platforms: {exc}")
    except BuildError as exc:
        sys.exit(f"build_fmu.py: {exc}")


if __name__ == "__main__":
    main()
