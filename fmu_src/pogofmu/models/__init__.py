"""Model variants: each module defines ``MODEL``, a :class:`pogofmu.model.HybridModel`."""
