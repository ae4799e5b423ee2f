"""SSP master: run an SSP package (SSP 1.0 with FMI 2.0 FMUs, SSP 2.0 with FMI 3.0 FMUs) with fmpy.

    pogofmu ssp run dist/SpaceHopper.ssp --parameters moon --stop-time 30 --step 1e-3 [--out DIR]
    pogofmu ssp check dist/SpaceHopper.ssp

One module per job:

* :mod:`.package` — reading the package (``SystemStructure.ssd``, the ``.ssv`` parameter sets);
* :mod:`.validate` — the system checked against itself and its FMUs before anything is loaded;
* :mod:`.master` — instantiating, initializing and stepping the components;
* :mod:`.record` — every connector at every communication point, in memory or streamed to CSV;
* :mod:`.components` — one FMU instance behind one interface, whatever its FMI version and type;
* :mod:`.graph` — the update order and the algebraic loops, from the FMUs' declared dependencies;
* :mod:`.algorithms` — Gauss–Seidel and Jacobi with a fixed step, with events;
  :mod:`.native_level` — their hot path in C (``native/master/pg_level.c``, the GIL released);
* :mod:`.coupled` — the strongly coupled algorithm (``--algorithm model-exchange``, CVODE);
* :mod:`.plot` — the run's figure; :mod:`.cli` — the command line; :mod:`.__main__` — ``python -m``;
* :mod:`.libcosim_runner` — a package run under libcosim in a process of its own (studies, tests).

Applications built on it live elsewhere: the segmented mirror's system in
:mod:`pogofmu.studies.mirror` (``pogofmu mirror``), system sweeps in :mod:`pogofmu.sweep.system`.

Host-side code (fmpy, numpy, matplotlib); never imported inside an FMU.
"""
from .master import ALGORITHMS, simulate  # noqa: F401
from .package import NS, SSPError, System, parse_value, read_ssd, read_ssv, unpack  # noqa: F401
from .record import PLOT_BINS, CSVStream, Envelope, Result  # noqa: F401
from .plot import figure, plot  # noqa: F401
from .validate import validate  # noqa: F401
from .cli import main, prepare_out, run  # noqa: F401
