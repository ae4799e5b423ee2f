"""The ``pogofmu`` command (declared in pyproject.toml's [project.scripts]).

    pogofmu run [--dist dist] [--out results] [NAME ...]     simulate each FMU's default experiment
    pogofmu ssp run|check FILE.ssp [...]                      the SSP master
    pogofmu sweep FMU --grid ... | --sample ... --out F.parquet   grids and Monte Carlo on Dask
    pogofmu study work-precision|soil [--out DIR]             the studies (CSV + PNG)

``pogofmu COMMAND --help`` tells each command's options. ``run`` and ``ssp`` are
``pogofmu.master`` and ``pogofmu.ssp`` (``python -m pogofmu.master`` and ``python -m pogofmu.ssp``
still work); their arguments are passed on unchanged.
"""
from __future__ import annotations

import os
import sys

COMMANDS = ("run", "ssp", "sweep", "study")


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        return 0 if argv else 2
    cmd, rest = argv[0], argv[1:]
    if cmd == "run":
        from pogofmu import master

        return master.main(rest) or 0
    if cmd == "ssp":
        from pogofmu import ssp

        return ssp.main(rest) or 0
    if cmd == "sweep":
        from pogofmu.sweep import sweep_main

        return sweep_main(rest)
    if cmd == "study":
        from pogofmu.studies import study_main

        return study_main(rest)
    print(f"pogofmu: unknown command {cmd!r} (one of {', '.join(COMMANDS)}); pogofmu --help", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
