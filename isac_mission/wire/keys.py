"""Key expressions of one mission: `isac/<mission>/...` (docs/bus.md, "Keys")."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from isac_mission.errors import ConfigError, MessageError

_MISSION_RE: Final = re.compile(r"^[A-Za-z0-9_-]+$")


@dataclass(frozen=True)
class Keys:
    """Key expressions of one mission: `isac/<mission>/...` (docs/bus.md, "Keys")."""

    mission: str

    def __post_init__(self) -> None:
        if not _MISSION_RE.match(self.mission):
            raise ConfigError(f"mission id {self.mission!r}: use letters, digits, '_' or '-'")

    @property
    def prefix(self) -> str:
        """`isac/<mission>`."""
        return f"isac/{self.mission}"

    @property
    def everything(self) -> str:
        """`isac/<mission>/**`: every key of the mission."""
        return f"{self.prefix}/**"

    def detections(self, m: int) -> str:
        """`isac/<mission>/detections/<m>` (m: 0-based UAV index)."""
        return f"{self.prefix}/detections/{_index(m)}"

    @property
    def detections_all(self) -> str:
        """`isac/<mission>/detections/*`."""
        return f"{self.prefix}/detections/*"

    def telemetry(self, m: int) -> str:
        """`isac/<mission>/telemetry/<m>`."""
        return f"{self.prefix}/telemetry/{_index(m)}"

    @property
    def telemetry_all(self) -> str:
        """`isac/<mission>/telemetry/*`."""
        return f"{self.prefix}/telemetry/*"

    @property
    def plan(self) -> str:
        """`isac/<mission>/plan`."""
        return f"{self.prefix}/plan"

    @property
    def track(self) -> str:
        """`isac/<mission>/track`."""
        return f"{self.prefix}/track"

    @property
    def clock(self) -> str:
        """`isac/<mission>/clock`."""
        return f"{self.prefix}/clock"

    @property
    def truth(self) -> str:
        """`isac/<mission>/truth`."""
        return f"{self.prefix}/truth"

    @property
    def health(self) -> str:
        """`isac/<mission>/health`."""
        return f"{self.prefix}/health"

    @property
    def control(self) -> str:
        """`isac/<mission>/control`: an operator's commands to the ground loop."""
        return f"{self.prefix}/control"

    @property
    def control_reply(self) -> str:
        """`isac/<mission>/control/reply`: the ground loop's answer to each request."""
        return f"{self.prefix}/control/reply"

    @property
    def fleet(self) -> str:
        """`isac/<mission>/fleet`: the ground loop's commands to the bridges (hold, land, ...)."""
        return f"{self.prefix}/fleet"


def _index(m: int) -> int:
    if isinstance(m, bool) or not isinstance(m, int) or m < 0:
        raise ValueError(f"UAV index must be an int >= 0, got {m!r}")
    return m


def uav_index(key: str) -> int:
    """The 0-based UAV index at the end of `.../detections/<m>` or `.../telemetry/<m>`."""
    last = key.rsplit("/", 1)[-1]
    if not last.isdigit():
        raise MessageError(f"key {key!r}: does not end in a UAV index")
    return int(last)
