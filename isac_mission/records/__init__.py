"""The run trace: JSON Lines, one file per run and method (format in docs/trace.md).

Line 1 names the format and holds every resolved parameter (SI units: records/header.py); every
further line is one slot: the labelled target's `SlotRecord`, or a tracker's line of tracks
(records/tracks.py), both with the tracks of the slot. The offline experiment and the live
ground loop write the same lines through the same `TraceWriter`; `read_trace` reads every
format, version 1 included.

In memory, arrays are numpy float64 (`assoc` int64) and a missing number is NaN; on disk every
non-finite number is written as JSON `null` (the file is strict JSON: no NaN or Infinity tokens),
and `null` reads back as NaN.
"""

from isac_mission.records.header import TRACE_FORMAT
from isac_mission.records.jsonlines import to_jsonable
from isac_mission.records.reader import read_trace
from isac_mission.records.slot import (
    CONTRACT_KEYS,
    OPTIONAL_KEYS,
    MissionEnd,
    SlotRecord,
)
from isac_mission.records.trace import Trace
from isac_mission.records.writer import TraceWriter

__all__ = [
    "CONTRACT_KEYS",
    "OPTIONAL_KEYS",
    "TRACE_FORMAT",
    "MissionEnd",
    "SlotRecord",
    "Trace",
    "TraceWriter",
    "read_trace",
    "to_jsonable",
]
