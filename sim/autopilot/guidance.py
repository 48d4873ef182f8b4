"""Setpoints the autonomous modes share (pure: numpy only): fly to a point at a speed, land
below a point, and the fall of a disarmed vehicle.

Frames and units: local NED (north, east, down), m, m/s, s; arrays of shape (3,) or (2,).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from isac_mission.types import FloatArray
from sim.vehicle import Setpoint, VehicleLimits, VehicleState

GRAVITY_MPS2 = 9.80665


@dataclass(frozen=True)
class Guidance:
    """What an autonomous mode asks of the controller this step.

    Attributes:
        setpoint: The setpoint to track.
        max_speed_mps: Cap on the horizontal speed, m/s (the mode's cruise speed); None = the
            airframe's limit.
    """

    setpoint: Setpoint
    max_speed_mps: float | None = None

    def limits(self, limits: VehicleLimits) -> VehicleLimits:
        """The airframe's limits with the horizontal speed capped at `max_speed_mps`."""
        if self.max_speed_mps is None or self.max_speed_mps >= limits.max_horizontal_speed_mps:
            return limits
        return _capped(limits, max(self.max_speed_mps, 0.1))


@functools.lru_cache(maxsize=64)
def _capped(limits: VehicleLimits, speed_mps: float) -> VehicleLimits:
    """`limits` with the horizontal speed capped at `speed_mps` (cached: built once per cap)."""
    return replace(limits, max_horizontal_speed_mps=speed_mps)


def goto(target_ned_m: FloatArray, speed_mps: float | None, yaw_rad: float = math.nan) -> Guidance:
    """Fly to and hold at `target_ned_m` (3,) at horizontal speed `speed_mps` (None: the limit)."""
    return Guidance(Setpoint.hold_at(np.asarray(target_ned_m, dtype=float), yaw_rad), speed_mps)


def land_below(
    xy_ned_m: FloatArray,
    height_m: float,
    limits: VehicleLimits,
    slow_below_m: float,
    slow_mps: float,
) -> Guidance:
    """Descend over `xy_ned_m` (2,): at the maximum descent rate above `slow_below_m` of height,
    at `slow_mps` (MPC_LAND_SPEED) below it."""
    rate = limits.max_descent_rate_mps if height_m > slow_below_m else slow_mps
    return Guidance(
        Setpoint(
            position_ned_m=np.array([xy_ned_m[0], xy_ned_m[1], math.nan]),
            velocity_ned_mps=np.array([0.0, 0.0, rate]),
        )
    )


def fall_step(state: VehicleState, ground_down_m: float, dt_s: float) -> VehicleState:
    """A disarmed vehicle's step: free fall under gravity (no drag) until it hits the ground at
    `ground_down_m`, where it stops dead."""
    v0 = state.velocity_ned_mps
    v1 = v0 + np.array([0.0, 0.0, GRAVITY_MPS2 * dt_s])
    p1 = state.position_ned_m + 0.5 * (v0 + v1) * dt_s
    if p1[2] >= ground_down_m:
        p1[2] = ground_down_m
        v1 = np.zeros(3)
    return VehicleState(position_ned_m=p1, velocity_ned_mps=v1, yaw_rad=state.yaw_rad)


def horizontal_distance_m(a_ned_m: FloatArray, b_ned_m: FloatArray) -> float:
    """Horizontal distance between two NED points, m."""
    return float(math.hypot(a_ned_m[0] - b_ned_m[0], a_ned_m[1] - b_ned_m[1]))
