"""`AutopilotState`: an immutable snapshot of one simulated vehicle (what the world and the
tests read)."""

from __future__ import annotations

from dataclasses import dataclass

from isac_mission.mavwire.modes import FlightMode
from isac_mission.types import FloatArray


@dataclass(frozen=True)
class AutopilotState:
    """A snapshot of the vehicle, as the world and tests see it.

    Attributes:
        time_s: Simulation time of the snapshot, s.
        position_ned_m: (3,) local NED position, m.
        velocity_ned_mps: (3,) local NED velocity, m/s.
        yaw_rad: Heading, rad.
        position_xy_m: (2,) scenario-plane position (x east, y north), m.
        altitude_m: Height above the ground, m.
        mode: Current flight mode.
        armed: Motors armed.
        landed: On the ground (land detector).
        gcs_lost: No client heartbeat for COM_DL_LOSS_T (after one was heard).
        battery_remaining: Charge left, fraction in [0, 1].
    """

    time_s: float
    position_ned_m: FloatArray
    velocity_ned_mps: FloatArray
    yaw_rad: float
    position_xy_m: FloatArray
    altitude_m: float
    mode: FlightMode
    armed: bool
    landed: bool
    gcs_lost: bool
    battery_remaining: float = 1.0
