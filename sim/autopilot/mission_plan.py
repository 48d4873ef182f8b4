"""Mission items the simulated vehicle flies, and the check an uploaded item must pass (pure).

Flown (as PX4 flies them for a multirotor; docs/service.md, "Missions"):

- NAV_TAKEOFF (22): climb over the position where the item begins (or its lat/lon, if not 0)
  to its altitude;
- NAV_WAYPOINT (16): fly to lat/lon/alt at the mission speed; reached within the acceptance
  radius (param2, 0: NAV_ACC_RAD) and NAV_MC_ALT_RAD of altitude, then wait param1 s; param4
  the heading, deg (NaN: keep);
- NAV_LAND (21): fly to lat/lon (0, 0: here) at the present altitude, then land; reached on
  touchdown (then the vehicle disarms after COM_DISARM_LAND);
- NAV_RETURN_TO_LAUNCH (20): switch to RTL;
- DO_CHANGE_SPEED (178): param2 the new horizontal speed, m/s (<= 0: no change).

Frames: MAV_FRAME_GLOBAL(_INT) (altitude AMSL) and MAV_FRAME_GLOBAL_RELATIVE_ALT(_INT)
(altitude above home) for the NAV items; any frame for RTL and DO_CHANGE_SPEED. Anything else is
refused with the MAV_MISSION_RESULT naming it (UNSUPPORTED, UNSUPPORTED_FRAME, INVALID_PARAMn)
and the vehicle keeps its previous plan, as PX4 does. Only MAV_MISSION_TYPE_MISSION is stored
(fences and rally points are refused as UNSUPPORTED).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final

from isac_mission.mavwire.dialect import mavlink2

CMD_WAYPOINT: Final[int] = mavlink2.MAV_CMD_NAV_WAYPOINT
CMD_TAKEOFF: Final[int] = mavlink2.MAV_CMD_NAV_TAKEOFF
CMD_LAND: Final[int] = mavlink2.MAV_CMD_NAV_LAND
CMD_RTL: Final[int] = mavlink2.MAV_CMD_NAV_RETURN_TO_LAUNCH
CMD_CHANGE_SPEED: Final[int] = mavlink2.MAV_CMD_DO_CHANGE_SPEED
NAV_COMMANDS: Final = frozenset({CMD_WAYPOINT, CMD_TAKEOFF, CMD_LAND})
"""Commands with a position (lat/lon/alt in a global frame)."""
SUPPORTED_COMMANDS: Final = NAV_COMMANDS | {CMD_RTL, CMD_CHANGE_SPEED}
ABSOLUTE_FRAMES: Final = frozenset({mavlink2.MAV_FRAME_GLOBAL, mavlink2.MAV_FRAME_GLOBAL_INT})
RELATIVE_FRAMES: Final = frozenset(
    {mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
)
MAX_ITEMS: Final = 500
"""Plans above this many items are refused as MAV_MISSION_NO_SPACE."""


@dataclass(frozen=True)
class MissionItem:
    """One item as MISSION_ITEM_INT carries it: lat/lon in degE7 (x, y), altitude z in m."""

    seq: int
    frame: int
    command: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float

    @classmethod
    def from_message(cls, msg: Any) -> MissionItem:
        """From MISSION_ITEM_INT (x, y in degE7) or MISSION_ITEM (x, y in degrees)."""
        if msg.get_type() == "MISSION_ITEM_INT":
            x, y = int(msg.x), int(msg.y)
        else:
            fx, fy = float(msg.x), float(msg.y)
            finite = math.isfinite(fx) and math.isfinite(fy)
            x, y = (round(fx * 1e7), round(fy * 1e7)) if finite else (2**31, 2**31)
        return cls(
            seq=int(msg.seq),
            frame=int(msg.frame),
            command=int(msg.command),
            autocontinue=int(msg.autocontinue),
            param1=float(msg.param1),
            param2=float(msg.param2),
            param3=float(msg.param3),
            param4=float(msg.param4),
            x=x,
            y=y,
            z=float(msg.z),
        )

    def to_message(self, target: tuple[int, int], current: bool, as_int: bool) -> Any:
        """MISSION_ITEM_INT (`as_int`) or MISSION_ITEM for the client `target` (sys, comp)."""
        fields = (self.seq, self.frame, self.command, int(current), self.autocontinue)
        params = (self.param1, self.param2, self.param3, self.param4)
        if as_int:
            return mavlink2.MAVLink_mission_item_int_message(
                *target, *fields, *params, self.x, self.y, self.z, 0
            )
        return mavlink2.MAVLink_mission_item_message(
            *target, *fields, *params, self.x * 1e-7, self.y * 1e-7, self.z, 0
        )

    @property
    def lat_deg(self) -> float:
        return self.x * 1e-7

    @property
    def lon_deg(self) -> float:
        return self.y * 1e-7

    @property
    def has_position(self) -> bool:
        """False for a TAKEOFF or LAND with lat = lon = 0 (here)."""
        return not (self.command in (CMD_TAKEOFF, CMD_LAND) and self.x == 0 and self.y == 0)


def check_item(item: MissionItem) -> int:
    """MAV_MISSION_ACCEPTED, or the MAV_MISSION_RESULT naming what the item gets wrong."""
    if item.command not in SUPPORTED_COMMANDS:
        return int(mavlink2.MAV_MISSION_UNSUPPORTED)
    if item.command == CMD_CHANGE_SPEED:
        ok = math.isfinite(item.param2)
        return int(mavlink2.MAV_MISSION_ACCEPTED if ok else mavlink2.MAV_MISSION_INVALID_PARAM2)
    if item.command not in NAV_COMMANDS:
        return int(mavlink2.MAV_MISSION_ACCEPTED)
    if item.frame not in ABSOLUTE_FRAMES | RELATIVE_FRAMES:
        return int(mavlink2.MAV_MISSION_UNSUPPORTED_FRAME)
    if item.command == CMD_WAYPOINT and not (math.isfinite(item.param1) and item.param1 >= 0):
        return int(mavlink2.MAV_MISSION_INVALID_PARAM1)
    if item.command == CMD_WAYPOINT and not (math.isfinite(item.param2) and item.param2 >= 0):
        return int(mavlink2.MAV_MISSION_INVALID_PARAM2)
    if not abs(item.x) <= 900_000_000:
        return int(mavlink2.MAV_MISSION_INVALID_PARAM5_X)
    if not abs(item.y) <= 1_800_000_000:
        return int(mavlink2.MAV_MISSION_INVALID_PARAM6_Y)
    if not math.isfinite(item.z):
        return int(mavlink2.MAV_MISSION_INVALID_PARAM7)
    return int(mavlink2.MAV_MISSION_ACCEPTED)
