"""Where MAVLink peers meet: the loopback host, PX4 SITL's port layout and the MAVLink ids.

Every MAVLink socket of the project binds and sends on 127.0.0.1. PX4 multi-vehicle SITL
instance i (MAVLink system i + 1) has two UDP links:

- the offboard link, from local port 14580 + i to the offboard client
  (MAVSDK, the service's bridge) on 14540 + i;
- the ground-station link, from local port 18570 + i to 14550: one port for the whole fleet, so one
  QGroundControl or MAVProxy on 14550 sees every vehicle, told apart by system id.

Both links answer whoever speaks to them (docs/service.md, "Ports").
"""

from __future__ import annotations

from typing import Final

from isac_mission.mavwire.dialect import mavlink2

LOOPBACK: Final = "127.0.0.1"
OFFBOARD_BASE_PORT: Final = 14540
"""PX4 SITL instance i sends its offboard link to UDP 14540 + i (where MAVSDK or the bridge listens)."""
OFFBOARD_LOCAL_BASE_PORT: Final = 14580
"""PX4 SITL instance i's offboard link binds UDP 14580 + i."""
GCS_PORT: Final = 14550
"""Every PX4 SITL instance sends its ground-station link to UDP 14550."""
GCS_LOCAL_BASE_PORT: Final = 18570
"""PX4 SITL instance i's ground-station link binds UDP 18570 + i."""
MAX_VEHICLES: Final = 254
"""System ids 1..254: vehicle indices 0..253 (255 is the ground station)."""
MAX_PORT: Final = 65535
HIGHEST_BASE_PORT: Final = MAX_PORT - (MAX_VEHICLES - 1)
"""The highest base port that leaves room for MAX_VEHICLES vehicles (base + m, m < 254)."""
GCS_SYSTEM_ID: Final = 255
"""Our MAVLink system id (a ground station's, as QGroundControl)."""
GCS_COMPONENT_ID: Final[int] = mavlink2.MAV_COMP_ID_MISSIONPLANNER  # 190
AUTOPILOT_COMPONENT_ID: Final[int] = mavlink2.MAV_COMP_ID_AUTOPILOT1  # 1

Address = tuple[str, int]
"""A UDP (host, port)."""


def check_base_port(name: str, port: int, n: int = MAX_VEHICLES) -> str | None:
    """None if `port` .. `port` + n - 1 are UDP ports, or 0 (ephemeral); else a message naming
    `name`."""
    if port == 0 or 1 <= port <= MAX_PORT - (n - 1):
        return None
    return f"{name} must be 0 (ephemeral) or leave room for {n} vehicles (got {port})"
