"""A vehicle's telemetry message from its MAVLink status (pure): frames, mode names, link state.

The bridge publishes it on `isac/<mission>/telemetry/<m>` at `telemetry_rate_hz`, converted from
the vehicle's local NED frame to the scenario plane (docs/bus.md, docs/frames-and-clocks.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from isac_mission.frames import ned_to_scenario, ned_to_scenario_velocity
from isac_mission.mavwire.status import VehicleStatus
from isac_mission.types import FloatArray
from isac_mission.wire import TELEMETRY_MODES, TelemetryMsg

_MANUAL_MODES: Final = frozenset({"manual", "altctl", "posctl", "acro", "stabilized", "rattitude"})


def telemetry_mode(px4_mode: str) -> str:
    """The telemetry mode name (wire.TELEMETRY_MODES) of a PX4 mode name."""
    if px4_mode in TELEMETRY_MODES:
        return px4_mode
    if px4_mode in _MANUAL_MODES:
        return "manual"
    return "other"


def vehicle_xy(st: VehicleStatus, origin_xy_m: FloatArray | Sequence[float]) -> FloatArray | None:
    """The vehicle's scenario-plane position [2], m (None before its first position), its local
    NED frame centred on `origin_xy_m` [2]."""
    if st.position_ned_m is None:
        return None
    return ned_to_scenario(st.position_ned_m, origin_xy_m)[0]


def telemetry_message(
    st: VehicleStatus,
    origin_xy_m: FloatArray | Sequence[float],
    uav: int,
    slot: int,
    override: str = "",
) -> TelemetryMsg | None:
    """Vehicle `uav`'s telemetry message at `slot` (None before its first position and
    velocity). t_s is the simulation time at which the position arrived; `override`: why the
    service does not fly it (override.py), "" while it does."""
    if st.position_ned_m is None or st.velocity_ned_mps is None:
        return None
    xy, alt = ned_to_scenario(st.position_ned_m, origin_xy_m)
    return TelemetryMsg(
        slot=slot,
        t_s=max(0.0, st.position_s or 0.0),
        uav=uav,
        position_xy_m=xy,
        altitude_m=alt,
        velocity_xy_mps=ned_to_scenario_velocity(st.velocity_ned_mps),
        mode=telemetry_mode(st.mode),
        armed=st.armed,
        landed=st.landed,
        link="lost" if st.lost else "ok",
        override=override,
    )
