"""Benchmark case PogoStickMem with a linear law (spring_law 0, gamma 0): the same physics as the
PogoStick case, through the element composition with the absement state -- the row to hold
against PogoStick's (at most 1.3x its time).  Reference: the closed form, as PogoStick.
"""
from __future__ import annotations

from . import Case, closed_form_reference
from .pogostick_mem import scipy_loop

CASE = Case(
    name="PogoStickMem-linear",
    fmu="PogoStickMem",
    model="pogofmu.runtime.models.pogo_stick_mem:MODEL",
    params={"spring_law": 0, "gamma": 0.0},
    scipy_loop=scipy_loop,
    reference=closed_form_reference,
    reference_label="closed form (pogofmu.references.closed_form, 19 events)",
    compare_to="PogoStick",
    max_ratio=1.3,
)
