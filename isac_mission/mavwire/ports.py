"""Where MAVLink peers meet: the loopback host, PX4 SITL's base ports and the MAVLink ids.

Every MAVLink socket of the project binds and sends on 127.0.0.1. PX4 SITL vehicle m (MAVLink
system m + 1) talks to its offboard client on UDP 14540 + m and to a ground station on 14550 + m.
"""

from __future__ import annotations

from typing import Final

from isac_mission.mavwire.dialect import mavlink2

LOOPBACK: Final = "127.0.0.1"
OFFBOARD_BASE_PORT: Final = 14540
"""PX4 SITL instance m talks to its offboard client on UDP 14540 + m."""
GCS_BASE_PORT: Final = 14550
"""PX4 SITL instance m talks to a ground station on UDP 14550 + m."""
GCS_SYSTEM_ID: Final = 255
"""Our MAVLink system id (a ground station's, as QGroundControl)."""
GCS_COMPONENT_ID: Final[int] = mavlink2.MAV_COMP_ID_MISSIONPLANNER  # 190
AUTOPILOT_COMPONENT_ID: Final[int] = mavlink2.MAV_COMP_ID_AUTOPILOT1  # 1

Address = tuple[str, int]
"""A UDP (host, port)."""
