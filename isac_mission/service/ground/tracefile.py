"""The ground loop's trace file (docs/trace.md): a new trace, or the continuation of one.

The loop writes through `isac_mission.records.TraceWriter` with an fsync per slot, as the
offline experiment writes its traces; on a resume, the last complete slot tells the loop where
to pick up.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from isac_mission.config import Scenario
from isac_mission.records import SlotRecord, TraceWriter, read_trace
from isac_mission.service.ground.settings import GroundSettings

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class OpenedTrace:
    """writer: None when the settings name no trace; last: the last complete slot of a resumed
    trace (None: start at slot 1)."""

    writer: TraceWriter | None
    last: SlotRecord | None = None


def open_trace(s: Scenario, settings: GroundSettings) -> OpenedTrace:
    """Create `settings.trace_path` with its config line, or (settings.resume) reopen it after
    its last complete slot. A trace killed before its config line was complete starts afresh.
    Raises MessageError for a corrupt trace."""
    path = settings.trace_path
    if path is None:
        return OpenedTrace(None)
    path.parent.mkdir(parents=True, exist_ok=True)
    if settings.resume and path.exists() and b"\n" not in path.read_bytes():
        # Killed before its config line was complete: no slot to lose, start afresh.
        log.warning("%s has no complete line; starting a new trace", path)
    elif settings.resume and path.exists():
        trace = read_trace(path)
        writer = TraceWriter.resume(path, fsync=True)
        return OpenedTrace(writer, trace.slots[-1] if trace.slots else None)
    config = s.trace_config() | {"seed": s.seed, "method": settings.method} | settings.trace_config
    return OpenedTrace(TraceWriter(path, config, fsync=True))
