"""The FMU's event log (parameter ``log_events = 1``, log category ``logEvents``): one message per
event, the only channel FMI gives an FMU to tell its host what happened inside a step.

The record — index, event name, exact time, the state before the jump — is written here by the
adapters (:mod:`.fmi2`; the native FMUs' C adapter writes the same bytes) and read back here by
the host-side tools (the sweep's event columns, the tests): one definition of the format, and
floats written with ``repr`` so that the times and states read back are the engine's to the bit.
Standard library only (this module goes into every FMU).
"""
from __future__ import annotations

import re
from typing import Iterable, List, Optional, Sequence

CATEGORY = "logEvents"

_RECORD = re.compile(r"^event (\d+) (\S+) at t = (\S+) s(?:; state before jump: (.*))?$")


def event_message(index: int, name: str, time: float, state_names: Sequence[str], x_before: Sequence[float]) -> str:
    """The log text of event ``index`` (1-based) of kind ``name`` at ``time``."""
    state = ", ".join(f"{n}={v!r}" for n, v in zip(state_names, x_before))
    return f"event {index} {name} at t = {time!r} s; state before jump: {state}"


def parse_event_message(text: str) -> Optional[dict]:
    """``{"index", "name", "time", "state": {state name: value}}`` of one event message, or None."""
    m = _RECORD.match(text)
    if not m:
        return None
    state = dict(kv.split("=") for kv in m.group(4).split(", ")) if m.group(4) else {}
    return {"index": int(m.group(1)), "name": m.group(2), "time": float(m.group(3)),
            "state": {k: float(v) for k, v in state.items()}}


def parse_event_log(messages: Iterable[tuple]) -> List[dict]:
    """The events among log messages ``(status, category, text)``, in order."""
    out = []
    for _, category, text in messages:
        record = parse_event_message(text) if category == CATEGORY else None
        if record is not None:
            out.append(record)
    return out
