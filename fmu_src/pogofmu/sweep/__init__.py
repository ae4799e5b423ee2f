"""Parameter sweeps and Monte Carlo runs of an FMU on Dask, one Parquet row per run.

    pogofmu sweep dist/PogoStick.fmu --grid k=50:200:4 --grid c=0.1,0.5 --out k_c.parquet
    pogofmu sweep dist/Penetrator.fmu --sample K=lognormal(9.21,0.5) --samples 200 --seed 1 --out soil.parquet

The runs are the shipped FMU artefact simulated by fmpy (``simulate_fmu``) in Dask worker
processes — or, for an FMU whose binary exports ``pogofmu_fmi2_run_grid`` / ``pogofmu_fmi3_run_grid``
(the native FMUs, dist/native/ and dist/native/fmi3/), by that function: fmpy's communication loop
written in C over the FMU's own FMI functions (native/pg_run_grid.h, once for both versions), the
same rows to the bit without fmpy's Python per step (``Runner.run``). FMI 2.0 and FMI 3.0 FMUs of
one model give the same table; a local cluster (``--workers W``, one thread each) or an existing one
(``--scheduler tcp://host:8786``). The FMU file is sent to the workers once and extracted once
per worker; each run gets a fresh FMU instance (0.7 ms, while extracting costs ~8 ms a run).
Runs go in chunks, one Dask task per chunk, so that scheduling costs little against the runs.

Every finished chunk is written at once as a part file next to the output
(``OUT.parquet.parts/``); when every run is done the parts are joined, ordered by ``run_id``,
into ``OUT.parquet`` and the part folder is removed. ``--resume`` reads the parts of an
interrupted sweep, checks that it is the same sweep (FMU file, points, settings) and runs only
the missing points. A run that fails (a parameter the FMU refuses, a leg that bottoms out, an
event storm, even a worker that dies) is a row with ``status`` and the FMU's own ``message``.

Host-side code: fmpy, numpy, dask.distributed, pyarrow, tqdm; never imported inside an FMU.
"""
from __future__ import annotations

# the package by job: spec (points, settings, checks), runner (one run, in a worker), parquet (the
# table and its parts), cluster (Dask), command (pogofmu sweep)
from .cluster import QUIET_CLUSTER, check_workers, close_cluster, execute, open_cluster, run_sweep  # noqa: F401
from .command import add_arguments, sweep_main  # noqa: F401
from .parquet import check_output, failed_runs, schema  # noqa: F401
from .runner import Runner, run_chunk  # noqa: F401
from .spec import (DISTRIBUTIONS, INTEGER_TYPES, REAL_TYPES, SUMMARY_OUTPUTS, Settings, Sweep,  # noqa: F401
                   SweepError, check_names, check_point_types, default_step, draw, make_points, parse_grid,
                   parse_sample, prepare, read_fmu_description, recorded_outputs, run_span)
