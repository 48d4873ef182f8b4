"""PX4 flight modes and their MAVLink encoding, written once for the service and the simulator.

PX4 reports its mode in HEARTBEAT.custom_mode (with MAV_MODE_FLAG_CUSTOM_MODE_ENABLED in
base_mode) as `(sub_mode << 24) | (main_mode << 16)`; DO_SET_MODE and SET_MODE ask for one by the
same (main, sub) pair. Main modes: MANUAL 1, ALTCTL 2, POSCTL 3, AUTO 4, ACRO 5, OFFBOARD 6,
STABILIZED 7, RATTITUDE 8; AUTO sub-modes: READY 1, TAKEOFF 2, LOITER (hold) 3, MISSION 4, RTL 5,
LAND 6, ... So OFFBOARD = 0x00060000, TAKEOFF = 0x02040000, HOLD = 0x03040000, MISSION = 0x04040000,
RTL = 0x05040000, LAND = 0x06040000.

`px4_mode_name` decodes any custom mode to a lower-case name (the service's view of a real or
simulated vehicle); `FlightMode` is the subset of modes the simulated vehicle flies, with
`FlightMode.px4_custom_mode` and `mode_from_px4` encoding and decoding it by the same tables.
"""

from __future__ import annotations

from enum import Enum
from typing import Final

from isac_mission.mavwire.dialect import mavlink2

PX4_MAIN_MODES: Final[dict[int, str]] = {
    1: "manual",
    2: "altctl",
    3: "posctl",
    4: "auto",
    5: "acro",
    6: "offboard",
    7: "stabilized",
    8: "rattitude",
}
"""PX4 main modes (custom_mode bits 16-23)."""
PX4_AUTO_SUB_MODES: Final[dict[int, str]] = {
    1: "ready",
    2: "takeoff",
    3: "hold",  # AUTO.LOITER
    4: "mission",
    5: "rtl",
    6: "land",
    8: "follow_target",
    9: "precland",
    10: "vtol_takeoff",
}
"""PX4 AUTO sub-modes (custom_mode bits 24-31)."""
PX4_MAIN_AUTO: Final = 4
PX4_MAIN_OFFBOARD: Final = 6
PX4_SUB_TAKEOFF: Final = 2
PX4_SUB_HOLD: Final = 3
PX4_SUB_MISSION: Final = 4
PX4_SUB_RTL: Final = 5
PX4_SUB_LAND: Final = 6


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """HEARTBEAT.custom_mode of a PX4 mode: (sub_mode << 24) | (main_mode << 16)."""
    return ((sub_mode & 0xFF) << 24) | ((main_mode & 0xFF) << 16)


def px4_main_sub(custom_mode: int) -> tuple[int, int]:
    """The PX4 (main mode, sub-mode) of a HEARTBEAT.custom_mode (bits 16-23, 24-31)."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


def px4_mode_name(custom_mode: int) -> str:
    """The PX4 mode of a HEARTBEAT.custom_mode, lower case.

    "offboard", "hold", "takeoff", "land", "mission", "rtl", "manual", "posctl", ... ; an AUTO
    mode with an unknown sub-mode is "auto"; an unknown main mode is "unknown".
    """
    main, sub = px4_main_sub(custom_mode)
    if main == PX4_MAIN_AUTO:
        return PX4_AUTO_SUB_MODES.get(sub, "auto")
    return PX4_MAIN_MODES.get(main, "unknown")


def heartbeat_mode_name(autopilot: int, base_mode: int, custom_mode: int) -> str:
    """The mode a HEARTBEAT reports: the PX4 name when the autopilot is PX4 and the
    custom-mode flag is set, "unknown" otherwise (other autopilots are not decoded)."""
    if autopilot != mavlink2.MAV_AUTOPILOT_PX4:
        return "unknown"
    if not base_mode & mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return "unknown"
    return px4_mode_name(custom_mode)


class FlightMode(Enum):
    """The PX4 flight modes the simulated vehicle flies, with their PX4 custom-mode encoding."""

    HOLD = "HOLD"
    TAKEOFF = "TAKEOFF"
    LAND = "LAND"
    OFFBOARD = "OFFBOARD"
    RTL = "RTL"
    MISSION = "MISSION"

    @property
    def px4_name(self) -> str:
        """The `px4_mode_name` of this mode ("hold", "takeoff", "land", "offboard", "rtl",
        "mission")."""
        return self.value.lower()

    @property
    def px4_custom_mode(self) -> int:
        """HEARTBEAT.custom_mode: (sub_mode << 24) | (main_mode << 16)."""
        return px4_custom_mode(*_PX4_MAIN_SUB[self])


_PX4_MAIN_SUB: Final[dict[FlightMode, tuple[int, int]]] = {
    FlightMode.OFFBOARD: (PX4_MAIN_OFFBOARD, 0),
    FlightMode.TAKEOFF: (PX4_MAIN_AUTO, PX4_SUB_TAKEOFF),
    FlightMode.HOLD: (PX4_MAIN_AUTO, PX4_SUB_HOLD),
    FlightMode.LAND: (PX4_MAIN_AUTO, PX4_SUB_LAND),
    FlightMode.RTL: (PX4_MAIN_AUTO, PX4_SUB_RTL),
    FlightMode.MISSION: (PX4_MAIN_AUTO, PX4_SUB_MISSION),
}
_BY_PX4_NAME: Final[dict[str, FlightMode]] = {mode.px4_name: mode for mode in FlightMode}


def mode_from_px4(main_mode: int, sub_mode: int) -> FlightMode | None:
    """The simulated mode for a PX4 (main, sub) mode pair, or None if not simulated.

    OFFBOARD takes any sub-mode, as PX4 does; an AUTO sub-mode is decoded by `px4_mode_name`'s
    table (TAKEOFF, HOLD, LAND, RTL and MISSION are simulated)."""
    if main_mode == PX4_MAIN_OFFBOARD:
        return FlightMode.OFFBOARD
    if main_mode == PX4_MAIN_AUTO and sub_mode in PX4_AUTO_SUB_MODES:
        return _BY_PX4_NAME.get(PX4_AUTO_SUB_MODES[sub_mode])
    return None
