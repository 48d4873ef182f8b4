"""Writing a trace file (docs/trace.md): append-only, one complete line per slot.

The writer flushes every line at once (and `os.fsync`s it on request), so a killed run leaves
every completed slot on disk; `TraceWriter.resume` reopens a trace to continue it, dropping an
incomplete final line first.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

from isac_mission.records.header import header_line
from isac_mission.records.jsonlines import dumps_line, to_jsonable
from isac_mission.records.reader import scan_trace
from isac_mission.records.slot import MissionEnd, SlotLine, SlotRecord, check_sequence
from isac_mission.records.tracks import TracksLine, TracksSlot, slot_line


class _Numbered:
    """A TracksSlot's slot number and number of UAVs (what the order is checked on)."""

    def __init__(self, o: TracksSlot) -> None:
        self.slot = o.slot
        self.n_uavs = len(o.uav_xy_m)


class TraceWriter:
    """Append-only trace writer; a context manager.

    `TraceWriter(path, config)` creates (or replaces) the file and writes line 1 (the format and
    the config: records/header.py); `write_slot(record)` appends one slot line (a labelled
    target's `SlotRecord`, or a tracker's line of tracks: `TracksSlot` with its extra fields)
    and flushes it (and fsyncs it when `fsync=True`), so the file holds every completed slot
    even if the process is killed. Slot numbers must increase, and every line must have
    config["M"] UAVs when the config names M.
    To continue a trace after a restart, use `TraceWriter.resume(path)`.
    """

    def __init__(self, path: str | Path, config: Mapping[str, Any], *, fsync: bool = False) -> None:
        jsonable = to_jsonable(dict(config), "config")
        self._setup(Path(path), jsonable, None, None, fsync)
        self._file = self._path.open("w", encoding="utf-8", newline="\n")
        self._write_line(header_line(jsonable))

    def _setup(
        self,
        path: Path,
        config: dict[str, Any],
        last: SlotRecord | None,
        last_line: TracksLine | None,
        fsync: bool,
    ) -> None:
        self._path = path
        self._config = config
        self._last = last
        self._last_line: SlotLine | None = last_line
        self._fsync = fsync
        self._written = 0

    @classmethod
    def resume(cls, path: str | Path, *, fsync: bool = False) -> TraceWriter:
        """Reopen an existing trace for appending after a restart.

        Reads (and so validates) the whole file; drops an incomplete final line from the file
        so that the next line starts clean; `config` and `last_record` (with its `P` and `J`)
        tell the caller where to pick up. Raises MessageError if the file is corrupt.
        """
        p = Path(path)
        scan = scan_trace(p)
        writer = cls.__new__(cls)
        last = scan.trace.slots[-1] if scan.trace.slots else None
        last_line = scan.trace.lines[-1] if scan.trace.lines else None
        writer._setup(p, scan.trace.config, last, last_line, fsync)
        with p.open("r+b") as raw:
            if scan.tail_unterminated_ok:
                raw.seek(0, os.SEEK_END)
                raw.write(b"\n")
            else:
                raw.truncate(scan.good_end)
            raw.flush()
            os.fsync(raw.fileno())
        writer._file = p.open("a", encoding="utf-8", newline="\n")
        return writer

    @property
    def path(self) -> Path:
        """The trace file."""
        return self._path

    @property
    def config(self) -> dict[str, Any]:
        """The config as written on line 1 (JSON-ready)."""
        return self._config

    @property
    def last_record(self) -> SlotRecord | None:
        """The last labelled slot on disk (written or, after resume, read); None if there is
        none."""
        return self._last

    @property
    def last_slot(self) -> int:
        """The number of the last slot on disk (0: none)."""
        return 0 if self._last_line is None else self._last_line.slot

    @property
    def slots_written(self) -> int:
        """Slot lines written by this writer (not counting lines already there on resume)."""
        return self._written

    @property
    def closed(self) -> bool:
        return self._file.closed

    def _write_line(self, line: str) -> None:
        self._file.write(line + "\n")
        self._file.flush()
        if self._fsync:
            os.fsync(self._file.fileno())

    def write_slot(
        self, record: SlotRecord | TracksSlot, extra: Mapping[str, Any] | None = None
    ) -> None:
        """Append one slot line (a TracksSlot's with `extra` fields) and flush it. Raises
        MessageError for an out-of-order slot or a wrong number of UAVs, ValueError if the
        writer is closed."""
        if self._file.closed:
            raise ValueError(f"{self._path}: trace writer is closed")
        line: SlotLine = record if isinstance(record, SlotRecord) else _Numbered(record)
        check_sequence(line, self._last_line, self._config.get("M"))
        if isinstance(record, SlotRecord):
            self._write_line(dumps_line(record.to_dict()))
            self._last = record
        else:
            self._write_line(slot_line(record, extra))
        self._last_line = line
        self._written += 1

    def write_end(self, end: MissionEnd) -> None:
        """Append the line that says how this run ended (the live ground loop, at its stop)."""
        if self._file.closed:
            raise ValueError(f"{self._path}: trace writer is closed")
        self._write_line(dumps_line(end.to_dict()))

    def close(self) -> None:
        """Close the file (idempotent)."""
        if not self._file.closed:
            self._file.close()

    def __enter__(self) -> TraceWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
