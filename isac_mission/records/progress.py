"""How far a trace got: its slots on disk and how its last run ended, whatever its format
(docs/trace.md).

`serve --resume` asks this before it touches anything: a trace whose last slot is the
scenario's N has nothing left to fly. Read only: the file is never written.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from isac_mission.errors import MessageError
from isac_mission.records.reader import read_trace
from isac_mission.records.slot import MissionEnd


@dataclass(frozen=True)
class TraceProgress:
    """A trace's progress: slots, the complete slot lines on disk; last_slot, the number of the
    last of them (0: none); labelled, every slot line is the labelled target's (a SlotRecord);
    config, its config line (empty when the file has no complete line); end, how its last run
    ended when its `end` line follows the last slot (`Trace.end`; None: killed, offline, or no
    line yet); last_line: the last slot line as parsed (None: no slot)."""

    path: Path
    slots: int
    last_slot: int
    labelled: bool
    config: dict[str, Any]
    end: MissionEnd | None = None
    last_line: dict[str, Any] | None = None


def trace_progress(path: str | Path) -> TraceProgress:
    """How far the trace at `path` got. An incomplete final line (a killed writer's) does not
    count; a file without one complete line has no slots. MessageError for a file that cannot
    be read or does not parse (naming the file and the line)."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as err:
        raise MessageError(f"{p}: cannot read: {err.strerror}") from None
    if b"\n" not in data:
        return TraceProgress(p, 0, 0, True, {})
    trace = read_trace(p)
    last = trace.lines[-1] if trace.lines else None
    return TraceProgress(
        p,
        len(trace.lines),
        0 if last is None else last.slot,
        trace.labelled,
        trace.config,
        trace.end,
        None if last is None else last.line,
    )
