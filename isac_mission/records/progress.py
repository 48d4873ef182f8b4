"""How far a trace got: its slots on disk and how its last run ended, for a single-target
trace (`read_trace`) and a multi-target one (`records/multi_target.py`) alike (docs/trace.md).

`serve --resume` asks this before it touches anything: a trace whose last slot is the
scenario's N has nothing left to fly. Read only: the file is never written.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from isac_mission.errors import MessageError
from isac_mission.records.jsonlines import loads_line
from isac_mission.records.multi_target import TRACE_FORMAT
from isac_mission.records.reader import read_trace
from isac_mission.records.slot import MissionEnd


@dataclass(frozen=True)
class TraceProgress:
    """A trace's progress: slots, the complete slot lines on disk; last_slot, the number of the
    last of them (0: none); multi_target, a multi-target trace; config, its config line (empty
    when the file has no complete line); end, how its last run ended when its `end` line follows
    the last slot (`Trace.end`; None: killed, offline, or no line yet); last_line: a
    multi-target trace's last slot line as parsed (None: no slot, or a single-target trace)."""

    path: Path
    slots: int
    last_slot: int
    multi_target: bool
    config: dict[str, Any]
    end: MissionEnd | None = None
    last_line: dict[str, Any] | None = None


def _multi_target_progress(path: Path, lines: list[bytes]) -> TraceProgress:
    """The progress of a multi-target trace from its newline-terminated lines (line 1 the
    header, then slot lines and `end` lines; its writer ends every line, so an unterminated
    last line is a torn one)."""
    head = loads_line(lines[0].decode("utf-8"))
    numbers: list[int] = []
    ends: list[MissionEnd] = []
    last_line: dict[str, Any] | None = None
    for lineno, raw in enumerate(lines[1:], start=2):
        if not raw.strip():
            continue
        try:
            obj = loads_line(raw.decode("utf-8"))
            if isinstance(obj, dict) and "end" in obj:
                ends.append(MissionEnd.from_dict(obj))
                continue
        except (MessageError, UnicodeDecodeError) as err:
            raise MessageError(f"{path}: line {lineno}: {err}") from None
        slot = obj.get("slot") if isinstance(obj, dict) else None
        if not isinstance(slot, int) or isinstance(slot, bool):
            raise MessageError(f"{path}: line {lineno}: expected a slot line with its `slot`")
        if numbers and slot <= numbers[-1]:
            raise MessageError(f"{path}: line {lineno}: slot {slot} after slot {numbers[-1]}")
        numbers.append(slot)
        last_line = obj
    last = numbers[-1] if numbers else 0
    end = ends[-1] if ends and ends[-1].last_slot == last else None
    return TraceProgress(path, len(numbers), last, True, dict(head["config"]), end, last_line)


def trace_progress(path: str | Path) -> TraceProgress:
    """How far the trace at `path` got. An incomplete final line (a killed writer's) does not
    count; a file without one complete line has no slots. MessageError for a file that cannot
    be read or does not parse (naming the file and the line)."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as err:
        raise MessageError(f"{p}: cannot read: {err.strerror}") from None
    lines = data.split(b"\n")[:-1]  # the complete lines: an unterminated last one is dropped
    if not lines:
        return TraceProgress(p, 0, 0, False, {})
    try:
        head = loads_line(lines[0].decode("utf-8"))
    except (MessageError, UnicodeDecodeError) as err:
        raise MessageError(f"{p}: line 1: {err}") from None
    if isinstance(head, dict) and head.get("format") == TRACE_FORMAT:
        return _multi_target_progress(p, lines)
    trace = read_trace(p)
    last = trace.slots[-1].slot if trace.slots else 0
    return TraceProgress(p, len(trace.slots), last, False, trace.config, trace.end)
