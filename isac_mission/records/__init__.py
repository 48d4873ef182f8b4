"""The run trace: JSON Lines, one file per run and method (format in docs/trace.md).

Line 1 is `{"config": {...}}` with every resolved parameter (SI units); every further line is one
slot's `SlotRecord`. The offline experiment and the live ground loop write the same records
through the same `TraceWriter`; `read_trace` reads either.

In memory, arrays are numpy float64 (`assoc` int64) and a missing number is NaN; on disk every
non-finite number is written as JSON `null` (the file is strict JSON: no NaN or Infinity tokens),
and `null` reads back as NaN.
"""

from isac_mission.records.jsonlines import to_jsonable
from isac_mission.records.reader import read_trace
from isac_mission.records.slot import (
    CONTRACT_KEYS,
    OPTIONAL_KEYS,
    MissionEnd,
    SlotRecord,
    Trace,
)
from isac_mission.records.writer import TraceWriter

__all__ = [
    "CONTRACT_KEYS",
    "OPTIONAL_KEYS",
    "MissionEnd",
    "SlotRecord",
    "Trace",
    "TraceWriter",
    "read_trace",
    "to_jsonable",
]
