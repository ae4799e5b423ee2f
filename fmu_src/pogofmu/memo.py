"""Host-side: results computed once per model object (a model is immutable; an export checks it and
then builds up to four FMUs of it, which need the same generated C and the same dependencies)."""
from __future__ import annotations

import functools


def once_per_model(fn):
    """``fn(model)`` computed once for each model object (by identity: a model's fields hold dicts and
    functions, so it is not hashable; the model is kept with its result, so its id is not reused)."""
    done = {}

    @functools.wraps(fn)
    def wrapper(model):
        known = done.get(id(model))
        if known is None or known[0] is not model:
            known = done[id(model)] = (model, fn(model))
        return known[1]
    return wrapper
