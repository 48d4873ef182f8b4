"""A trace read from disk (docs/trace.md, "Reading"): its config, every slot line's tracks, the
labelled target's slot records, and how its live runs ended."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from isac_mission.records.slot import _ATTRIBUTE, _PER_UAV_XY, MissionEnd, SlotRecord
from isac_mission.records.tracks import TracksLine
from isac_mission.types import FloatArray


@dataclass(frozen=True)
class Trace:
    """A trace read from disk: the config mapping and the slot records in file order.

    truncated is True when an incomplete final line (a killed writer's) was dropped; ends: the
    `end` line of every live run that wrote to it, in file order (a resumed trace has one per
    run that ended; none offline, and none after a kill).
    """

    config: dict[str, Any]
    slots: list[SlotRecord]
    path: Path | None = None
    truncated: bool = False
    ends: list[MissionEnd] = field(default_factory=list)
    lines: list[TracksLine] = field(default_factory=list)
    """Every slot line's tracks, whatever the number of targets (records/tracks.py)."""
    format: str = ""
    """Line 1's format (records/header.py)."""
    written_by: str | None = None
    """The release of isac-mission that wrote the trace (line 1's `isac_mission_version`; None
    for a trace written before 0.4.0)."""

    @property
    def end(self) -> MissionEnd | None:
        """How the last run ended, if its end line follows the last slot (None: unknown, e.g.
        killed, or offline)."""
        last = self.lines[-1].slot if self.lines else (self.slots[-1].slot if self.slots else 0)
        if self.ends and self.ends[-1].last_slot == last:
            return self.ends[-1]
        return None

    @property
    def labelled(self) -> bool:
        """The trace is the labelled target's: every slot line has its SlotRecord."""
        return len(self.slots) == len(self.lines)

    @property
    def method(self) -> str:
        """The run's method: config["method"], else the first slot's, else ""."""
        named = self.config.get("method")
        if isinstance(named, str):
            return named
        return self.lines[0].method if self.lines else ""

    def stack(self, name: str) -> FloatArray:
        """One array field stacked over slots: e.g. "uav_xy" -> [N, M, 2]; "pcrb_trace" -> [N].

        Fields that are None in a slot (target_true, plan_xy) become NaN of the right shape.
        """
        values = [getattr(rec, _ATTRIBUTE.get(name, name)) for rec in self.slots]
        default: tuple[int, ...] = ()
        if name == "target_true":
            default = (4,)
        elif name in _PER_UAV_XY and self.slots:
            default = (self.slots[0].n_uavs, 2)
        shape = next((np.shape(v) for v in values if v is not None), default)
        return np.array(
            [np.full(shape, np.nan) if v is None else np.asarray(v, dtype=float) for v in values],
            dtype=np.float64,
        ).reshape((len(values), *shape))

    def __iter__(self) -> Iterator[SlotRecord]:
        return iter(self.slots)

    def __len__(self) -> int:
        return len(self.slots)
