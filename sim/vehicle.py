"""Kinematic multirotor (pure: numpy only, deterministic, no I/O).

The vehicle is a point mass with a yaw angle, flown by a simple PX4-like cascaded controller:

- position loop: per axis, desired velocity = feed-forward velocity + P gain x position error;
  the P part is bounded by a braking profile sqrt(2 a_brake |e|) so the vehicle can always stop
  at the target with less than the available acceleration (no overshoot to speak of);
- velocity saturation: horizontal speed <= `max_horizontal_speed_mps` (on the norm of the
  horizontal vector), vertical velocity within [-max_climb_rate_mps, +max_descent_rate_mps]
  (NED: down is positive);
- acceleration saturation: the velocity error is removed within one step as far as the
  horizontal (norm) and vertical acceleration limits allow, and velocity is integrated with the
  trapezoidal rule for position;
- yaw: proportional, rate-limited to `max_yaw_rate_rps`, turning the short way round;
- the ground: the vehicle cannot go below `ground_down_m` (NED down of the ground; 0 when the
  local origin is on the ground). At the ground a downward velocity is zeroed.

Frames and units: local NED (north, east, down), m, m/s, m/s^2, rad, rad/s, s. Arrays are
numpy float64 of shape (3,).

A `Setpoint` has NaN for every component it leaves free. Per axis, a position component is
tracked with the velocity component (if given) as feed-forward; an axis without a position
component tracks its velocity component; an axis with neither is braked to zero velocity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from isac_mission.errors import IsacError
from isac_mission.types import FloatArray

_NAN3: tuple[float, float, float] = (math.nan, math.nan, math.nan)


def _vec3(values: FloatArray | tuple[float, float, float] | list[float]) -> FloatArray:
    """A fresh float64 array of shape (3,); raises IsacError on any other shape."""
    arr = np.array(values, dtype=np.float64)
    if arr.shape != (3,):
        raise IsacError(f"expected a 3-vector, got shape {arr.shape}")
    return arr


@dataclass(frozen=True)
class VehicleLimits:
    """Kinematic limits, PX4-multirotor-like defaults (MPC_* parameters in brackets).

    Attributes:
        max_horizontal_speed_mps: Bound on the horizontal speed norm, m/s (MPC_XY_VEL_MAX 12).
        max_horizontal_accel_mps2: Bound on the horizontal acceleration norm, m/s^2 (MPC_ACC_HOR_MAX 5).
        max_climb_rate_mps: Bound on the upward speed, m/s (MPC_Z_VEL_MAX_UP 3).
        max_descent_rate_mps: Bound on the downward speed, m/s (MPC_Z_VEL_MAX_DN 1.5).
        max_vertical_accel_mps2: Bound on the vertical acceleration magnitude, m/s^2 (MPC_ACC_DOWN_MAX 3).
        max_yaw_rate_rps: Bound on the yaw rate, rad/s (MPC_MAN_Y_MAX 90 deg/s).
        position_gain_per_s: Horizontal and vertical position P gain, 1/s (MPC_XY_P 0.95, MPC_Z_P 1).
        yaw_gain_per_s: Yaw P gain, 1/s (MC_YAW_P 2.8; 2 here).
        braking_fraction: Fraction of the acceleration limit used by the braking profile (0, 1].
        ground_down_m: NED down coordinate of the ground, m; the vehicle never goes below it.
    """

    max_horizontal_speed_mps: float = 12.0
    max_horizontal_accel_mps2: float = 5.0
    max_climb_rate_mps: float = 3.0
    max_descent_rate_mps: float = 1.5
    max_vertical_accel_mps2: float = 3.0
    max_yaw_rate_rps: float = math.radians(90.0)
    position_gain_per_s: float = 1.0
    yaw_gain_per_s: float = 2.0
    braking_fraction: float = 0.8
    ground_down_m: float = 0.0

    def __post_init__(self) -> None:
        positive = {
            "max_horizontal_speed_mps": self.max_horizontal_speed_mps,
            "max_horizontal_accel_mps2": self.max_horizontal_accel_mps2,
            "max_climb_rate_mps": self.max_climb_rate_mps,
            "max_descent_rate_mps": self.max_descent_rate_mps,
            "max_vertical_accel_mps2": self.max_vertical_accel_mps2,
            "max_yaw_rate_rps": self.max_yaw_rate_rps,
            "position_gain_per_s": self.position_gain_per_s,
            "yaw_gain_per_s": self.yaw_gain_per_s,
        }
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0.0):
                raise IsacError(f"VehicleLimits.{name} must be finite and > 0 (got {value})")
        if not (0.0 < self.braking_fraction <= 1.0):
            raise IsacError(
                f"VehicleLimits.braking_fraction must be in (0, 1] (got {self.braking_fraction})"
            )
        if not math.isfinite(self.ground_down_m):
            raise IsacError(
                f"VehicleLimits.ground_down_m must be finite (got {self.ground_down_m})"
            )


@dataclass(frozen=True)
class VehicleState:
    """Kinematic state in the local NED frame.

    Attributes:
        position_ned_m: (3,) north, east, down, m.
        velocity_ned_mps: (3,) north, east, down velocity, m/s.
        yaw_rad: Heading, rad, in (-pi, pi], 0 = north, positive clockwise seen from above.
    """

    position_ned_m: FloatArray = field(default_factory=lambda: np.zeros(3))
    velocity_ned_mps: FloatArray = field(default_factory=lambda: np.zeros(3))
    yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_ned_m", _vec3(self.position_ned_m))
        object.__setattr__(self, "velocity_ned_mps", _vec3(self.velocity_ned_mps))
        self.position_ned_m.setflags(write=False)
        self.velocity_ned_mps.setflags(write=False)


@dataclass(frozen=True)
class Setpoint:
    """What the controller tracks; NaN components are free (see the module docstring).

    Attributes:
        position_ned_m: (3,) target position, m; NaN per free axis.
        velocity_ned_mps: (3,) target (or feed-forward) velocity, m/s; NaN per free axis.
        yaw_rad: Target heading, rad; NaN keeps the heading (unless `yaw_rate_rps` is set).
        yaw_rate_rps: Target yaw rate, rad/s, used when `yaw_rad` is NaN; NaN = 0.
    """

    position_ned_m: FloatArray = field(default_factory=lambda: np.array(_NAN3))
    velocity_ned_mps: FloatArray = field(default_factory=lambda: np.array(_NAN3))
    yaw_rad: float = math.nan
    yaw_rate_rps: float = math.nan

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_ned_m", _vec3(self.position_ned_m))
        object.__setattr__(self, "velocity_ned_mps", _vec3(self.velocity_ned_mps))
        self.position_ned_m.setflags(write=False)
        self.velocity_ned_mps.setflags(write=False)

    @classmethod
    def hold_at(cls, position_ned_m: FloatArray, yaw_rad: float = math.nan) -> Setpoint:
        """A setpoint that holds the given (3,) position, m, with zero feed-forward velocity."""
        return cls(position_ned_m=position_ned_m, velocity_ned_mps=np.zeros(3), yaw_rad=yaw_rad)


def wrap_pi(angle_rad: float) -> float:
    """The angle wrapped to (-pi, pi], rad."""
    wrapped = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


def stopping_point(state: VehicleState, limits: VehicleLimits) -> FloatArray:
    """(3,) NED position, m, where the vehicle comes to rest braking at the braking profile's
    deceleration from its current velocity (used to enter HOLD without bouncing back)."""
    v = state.velocity_ned_mps
    p = state.position_ned_m.copy()
    a_h = limits.braking_fraction * limits.max_horizontal_accel_mps2
    a_v = limits.braking_fraction * limits.max_vertical_accel_mps2
    speed_h = float(np.hypot(v[0], v[1]))
    if speed_h > 0.0:
        p[:2] += v[:2] * (speed_h / (2.0 * a_h))
    p[2] += v[2] * abs(v[2]) / (2.0 * a_v)
    p[2] = min(p[2], limits.ground_down_m)
    return p


def _braked_speed(distance_m: float, gain: float, accel: float) -> float:
    """Speed, m/s, the position loop asks for at `distance_m` from the target."""
    return min(gain * distance_m, math.sqrt(2.0 * accel * distance_m))


def desired_velocity(state: VehicleState, setpoint: Setpoint, limits: VehicleLimits) -> FloatArray:
    """(3,) NED velocity, m/s, the position loop commands, before acceleration limits."""
    p_sp = setpoint.position_ned_m
    v_sp = setpoint.velocity_ned_mps
    pos = state.position_ned_m
    has_p = np.isfinite(p_sp)
    has_v = np.isfinite(v_sp)
    v_ff = np.where(has_v, v_sp, 0.0)
    err = np.where(has_p, p_sp - pos, 0.0)
    gain = limits.position_gain_per_s

    # Horizontal: P on the error vector, bounded by the braking profile.
    v_des = v_ff.copy()
    e_h = float(np.hypot(err[0], err[1]))
    if e_h > 0.0:
        a_b = limits.braking_fraction * limits.max_horizontal_accel_mps2
        v_des[:2] += err[:2] * (_braked_speed(e_h, gain, a_b) / e_h)
    speed_h = float(np.hypot(v_des[0], v_des[1]))
    if speed_h > limits.max_horizontal_speed_mps:
        v_des[:2] *= limits.max_horizontal_speed_mps / speed_h

    # Vertical.
    e_v = abs(float(err[2]))
    if e_v > 0.0:
        a_b = limits.braking_fraction * limits.max_vertical_accel_mps2
        v_des[2] += math.copysign(_braked_speed(e_v, gain, a_b), float(err[2]))
    v_des[2] = min(max(v_des[2], -limits.max_climb_rate_mps), limits.max_descent_rate_mps)
    return v_des


def step(state: VehicleState, setpoint: Setpoint, limits: VehicleLimits, dt: float) -> VehicleState:
    """Advance the vehicle by `dt` seconds toward `setpoint` within `limits`.

    Args:
        state: Current state (local NED).
        setpoint: Position and/or velocity target; NaN components are free.
        limits: Speed, acceleration and yaw-rate limits.
        dt: Time step, s, > 0.

    Returns:
        The state after `dt`. Pure and deterministic.
    """
    if not (math.isfinite(dt) and dt > 0.0):
        raise IsacError(f"step: dt must be finite and > 0 (got {dt})")
    v0 = state.velocity_ned_mps
    v_des = desired_velocity(state, setpoint, limits)

    accel = (v_des - v0) / dt
    a_h = float(np.hypot(accel[0], accel[1]))
    if a_h > limits.max_horizontal_accel_mps2:
        accel[:2] *= limits.max_horizontal_accel_mps2 / a_h
    accel[2] = min(max(accel[2], -limits.max_vertical_accel_mps2), limits.max_vertical_accel_mps2)

    v1 = v0 + accel * dt
    p1 = state.position_ned_m + 0.5 * (v0 + v1) * dt
    if p1[2] >= limits.ground_down_m:
        p1[2] = limits.ground_down_m
        v1[2] = min(v1[2], 0.0)

    yaw = state.yaw_rad
    if math.isfinite(setpoint.yaw_rad):
        yaw_rate = limits.yaw_gain_per_s * wrap_pi(setpoint.yaw_rad - yaw)
    elif math.isfinite(setpoint.yaw_rate_rps):
        yaw_rate = setpoint.yaw_rate_rps
    else:
        yaw_rate = 0.0
    yaw_rate = min(max(yaw_rate, -limits.max_yaw_rate_rps), limits.max_yaw_rate_rps)
    if math.isfinite(setpoint.yaw_rad) and abs(yaw_rate * dt) >= abs(
        wrap_pi(setpoint.yaw_rad - yaw)
    ):
        yaw = wrap_pi(setpoint.yaw_rad)
    else:
        yaw = wrap_pi(yaw + yaw_rate * dt)
    return VehicleState(position_ned_m=p1, velocity_ned_mps=v1, yaw_rad=yaw)
