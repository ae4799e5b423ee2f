"""pogofmu: hybrid pogo-stick models (Pei, Quadrelli & Wright 2020) exported as FMI 2.0
co-simulation and FMI 3.0 model-exchange/co-simulation FMUs with exact state-event location.

Two floors: :mod:`pogofmu.runtime` is the code that goes into every FMU (models, engine, FMI
adapters; standard library only); the host-side tools beside it — :mod:`pogofmu.master`
(default experiments), :mod:`pogofmu.ssp` (the SSP master), :mod:`pogofmu.sweep`,
:mod:`pogofmu.studies` and :mod:`pogofmu.cli` (the ``pogofmu`` command) — drive the built FMUs
through fmpy and never go into an FMU.
"""
from .runtime import __version__  # noqa: F401 (one place for the version: the FMUs carry it)
