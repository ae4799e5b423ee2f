"""Snapshots of a :class:`~.simulator.Simulator` as plain data (for fmi2SerializeFMUstate)."""
from __future__ import annotations

from ..model import HybridModel, Params
from .pairs import METHODS
from .settings import domain_slack
from .simulator import EventRecord, Simulator, _Segment

# =============================================================================================
# snapshots as plain data (fmi2SerializeFMUstate)
# =============================================================================================
#
# A snapshot (Simulator.snapshot) holds the model, the parameters and the method (shared objects)
# and the latest segment, whose right-hand side is a closure: none of them is data.  The plain
# form keeps every other field as JSON-able values (floats round-trip exactly through repr) and
# rebuilds the closures from the model on the way back, so that a restored simulator continues
# bit for bit as the original.  The segment is needed only while the integrator is ahead of the
# communication time (t > t_out): the next served points come from its dense output, and then its
# right-hand side is the current one (a jump or an input change at t > t_out drops the segment).

_NOT_DATA = ("model", "p", "solver", "_slack", "pair", "fun", "active", "seg")


def _encode(v):
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    if isinstance(v, list):
        return [_encode(a) for a in v]
    if isinstance(v, tuple):
        return {"tuple": [_encode(a) for a in v]}
    if isinstance(v, dict):
        return {"dict": [[k, _encode(a)] for k, a in v.items()]}
    if isinstance(v, EventRecord):
        return {"event": [v.time, v.name, v.index, list(v.x_before), list(v.x_after)]}
    if hasattr(v, "maxlen") and hasattr(v, "appendleft"):  # collections.deque
        return {"deque": [_encode(a) for a in v], "maxlen": v.maxlen}
    raise TypeError(f"engine state field of type {type(v).__name__} has no plain-data form")


def _decode(v):
    if isinstance(v, list):
        return [_decode(a) for a in v]
    if not isinstance(v, dict):
        return v
    if "tuple" in v:
        return tuple(_decode(a) for a in v["tuple"])
    if "dict" in v:
        return {k: _decode(a) for k, a in v["dict"]}
    if "event" in v:
        return EventRecord(*v["event"])
    if "deque" in v:
        from collections import deque

        return deque((_decode(a) for a in v["deque"]), v["maxlen"])
    raise ValueError(f"unknown engine state entry {sorted(v)}")


def snapshot_to_data(snap: dict) -> dict:
    """Plain data (JSON-able) of a :meth:`Simulator.snapshot`."""
    data = {k: _encode(v) for k, v in snap.items() if k not in _NOT_DATA}
    data["params"] = _encode(snap["p"].as_dict())
    data["solver"] = _encode(snap["solver"].as_dict())
    seg = snap.get("seg")
    if seg is not None and snap["t"] > snap["t_out"]:
        data["segment"] = _encode((seg.t0, seg.t1, seg.y0, seg.y1, seg.f0, tuple(seg.K)))
    else:
        data["segment"] = None
    return data


def snapshot_from_data(model: HybridModel, data: dict) -> dict:
    """The :meth:`Simulator.snapshot` that :func:`snapshot_to_data` was made from."""
    fields = {k: _decode(v) for k, v in data.items() if k not in ("params", "solver", "segment")}
    sim = Simulator.__new__(Simulator)
    sim.__dict__.update(fields)
    sim.model = model
    sim.p = Params(_decode(data["params"]))
    sim.solver = Params(_decode(data["solver"]))
    sim._slack = domain_slack(sim.solver)
    sim.pair = METHODS[int(sim.solver.method)].specialized(len(sim.x))
    sim._rebind()
    sim.seg = None
    if data["segment"] is not None:
        t0, t1, y0, y1, f0, K = _decode(data["segment"])
        sim.seg = _Segment(t0, t1, y0, y1, f0, K, sim.fun, sim.pair)
    return sim.snapshot()

