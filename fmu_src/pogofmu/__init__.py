"""pogofmu: hybrid pogo-stick models (Pei, Quadrelli & Wright 2020) exported as FMI 2.0 co-simulation FMUs.

Layers: :mod:`pogofmu.model` (a model is plain data and pure functions), :mod:`pogofmu.engine`
(one integrator with state-event location for every model), :mod:`pogofmu.elements` (leg
elements composed in parallel), :mod:`pogofmu.models` (the model variants) and
:mod:`pogofmu.fmi` (one adapter from any model to an FMI 2.0 slave).
"""
__version__ = "0.1.0"
