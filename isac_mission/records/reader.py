"""Reading a trace file of any format and version (docs/trace.md): line 1 the format and the
config (records/header.py), then one slot line each, and an `end` line where a live run of the
ground loop ended. Every slot line gives its tracks (`Trace.lines`, records/tracks.py); a line
of the labelled target also its `SlotRecord` (`Trace.slots`).

An incomplete final line (the one a killed writer was in the middle of) is dropped and flagged
with `Trace.truncated`; any other line that does not parse, or breaks the slot order, raises
MessageError naming the file and the 1-based line number.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from isac_mission.errors import MessageError
from isac_mission.records.header import parse_header, written_by
from isac_mission.records.jsonlines import loads_line
from isac_mission.records.slot import CONTRACT_KEYS, MissionEnd, SlotRecord, check_sequence
from isac_mission.records.trace import Trace
from isac_mission.records.tracks import TracksLine


@dataclass(frozen=True)
class Scan:
    """A read trace and where its good bytes end (for `TraceWriter.resume`)."""

    trace: Trace
    good_end: int  # byte offset just past the last line that parsed
    tail_unterminated_ok: bool  # the last line parsed but has no newline


def scan_trace(path: Path) -> Scan:
    """Read and validate the whole file (see the module doc)."""
    try:
        data = path.read_bytes()
    except OSError as err:
        raise MessageError(f"{path}: cannot read: {err.strerror}") from None
    pieces = data.split(b"\n")
    # pieces[-1] is b"" when the file ends with a newline, else the unterminated last line.
    config: dict[str, Any] | None = None
    fmt = ""
    release: str | None = None
    slots: list[SlotRecord] = []
    lines: list[TracksLine] = []
    ends: list[MissionEnd] = []
    offset = good_end = 0
    truncated = tail_ok = False
    n_lines = len(pieces) if pieces[-1] else len(pieces) - 1
    for lineno, raw in enumerate(pieces[:n_lines], start=1):
        terminated = lineno < len(pieces)
        end = offset + len(raw) + (1 if terminated else 0)
        is_last_unterminated = not terminated
        try:
            text = raw.decode("utf-8")
            if not text.strip():
                offset = good_end = end
                continue
            if config is None:
                head = loads_line(text)
                fmt, config = parse_header(head)
                release = written_by(head)
            else:
                obj = loads_line(text)
                if isinstance(obj, dict) and "end" in obj:
                    ends.append(MissionEnd.from_dict(obj))
                else:
                    line, rec = _slot_line(obj)
                    check_sequence(line, lines[-1] if lines else None, config.get("M"))
                    lines.append(line)
                    if rec is not None:
                        slots.append(rec)
        except (MessageError, UnicodeDecodeError) as err:
            if is_last_unterminated and config is not None:
                truncated = True
                break
            what = "incomplete config line" if is_last_unterminated else str(err)
            raise MessageError(f"{path}: line {lineno}: {what}") from None
        tail_ok = is_last_unterminated
        offset = good_end = end
    if config is None:
        raise MessageError(f"{path}: empty trace: no config line")
    trace = Trace(
        config=config,
        slots=slots,
        path=path,
        truncated=truncated,
        ends=ends,
        lines=lines,
        format=fmt,
        written_by=release,
    )
    return Scan(trace=trace, good_end=good_end, tail_unterminated_ok=tail_ok)


def _slot_line(obj: Any) -> tuple[TracksLine, SlotRecord | None]:
    """A slot line's tracks, and its SlotRecord when it is the labelled target's (it has every
    contract field: docs/trace.md)."""
    if not isinstance(obj, dict):
        raise MessageError(f"a slot line must be a JSON object (got {type(obj).__name__})")
    if "config" in obj:
        raise MessageError("a second config object after line 1")
    labelled = "tracks" not in obj or all(key in obj for key in CONTRACT_KEYS)
    rec = SlotRecord.from_dict(obj) if labelled else None
    if "tracks" in obj:
        return TracksLine.parse(obj), rec
    assert rec is not None
    return TracksLine.of_labelled(obj, rec), rec


def read_trace(path: str | Path) -> Trace:
    """Read a trace file. An incomplete final line (a killed writer's) is dropped and flagged
    with `Trace.truncated`; any other line that does not parse, or breaks the slot order, raises
    MessageError naming the file and the 1-based line number."""
    return scan_trace(Path(path)).trace
