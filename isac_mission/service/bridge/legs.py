"""Leg shapes: where the setpoint is between two waypoints (pure; scenario plane, m, m/s, s).

A *carrot* (`CarrotLeg`, `plan_leg`) moves in a straight line from where it is toward the
waypoint at the constant speed needed to arrive at `arrive_by_s`, never above V_max, with that
velocity as feed-forward, and stops at the waypoint. A smooth leg (`HermiteLeg`, `hermite_leg`)
runs on the cubic that keeps position and velocity continuous across legs. Legs chain: the next
leg starts where the setpoint is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from isac_mission.types import FloatArray


def as_xy(value: FloatArray | Sequence[float], name: str = "xy_m") -> FloatArray:
    """`value` as a float array [2]; ValueError naming `name` unless it is 2 finite numbers."""
    arr = np.array(value, dtype=float)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 2 finite numbers, got {value!r}")
    return arr


@dataclass(frozen=True)
class CarrotLeg:
    """A setpoint moving from `start_xy_m` [2] at time `start_s` toward `goal_xy_m` [2] at
    `speed_mps` in a straight line, then resting at the goal (scenario plane, m, s)."""

    start_xy_m: FloatArray
    goal_xy_m: FloatArray
    start_s: float
    speed_mps: float

    @property
    def distance_m(self) -> float:
        """Length of the leg, m."""
        return float(np.hypot(*(self.goal_xy_m - self.start_xy_m)))

    @property
    def end_s(self) -> float:
        """When the carrot reaches the goal, s."""
        d = self.distance_m
        return self.start_s if d <= 0.0 else self.start_s + d / self.speed_mps

    def sample(self, t_s: float) -> tuple[FloatArray, FloatArray]:
        """Carrot position [2], m, and velocity [2], m/s, at time `t_s`."""
        d = self.distance_m
        if d <= 0.0 or t_s >= self.end_s:
            return self.goal_xy_m.copy(), np.zeros(2)
        u = (self.goal_xy_m - self.start_xy_m) / d
        s = self.speed_mps * max(0.0, t_s - self.start_s)
        return self.start_xy_m + u * s, u * self.speed_mps


@dataclass(frozen=True)
class HermiteLeg:
    """A setpoint on the cubic from (start_xy_m, start_v_mps) at `start_s` to (goal_xy_m,
    goal_v_mps) at `end_s`, then resting at the goal (scenario plane, m, m/s, s).

    Position and velocity are continuous across legs, so a vehicle with finite acceleration can
    follow it; a constant-speed carrot jumps in velocity at every slot boundary, and a vehicle
    limited to a few m/s^2 then trails the plan by metres.
    """

    start_xy_m: FloatArray
    start_v_mps: FloatArray
    goal_xy_m: FloatArray
    goal_v_mps: FloatArray
    start_s: float
    end_s: float

    def sample(self, t_s: float) -> tuple[FloatArray, FloatArray]:
        """Setpoint position [2], m, and velocity [2], m/s, at time `t_s`."""
        T = self.end_s - self.start_s
        if T <= 0.0 or t_s >= self.end_s:
            return self.goal_xy_m.copy(), np.zeros(2)
        s = max(0.0, t_s - self.start_s) / T
        p0, p1 = self.start_xy_m, self.goal_xy_m
        m0, m1 = self.start_v_mps * T, self.goal_v_mps * T
        h00, h10, h01, h11 = (
            2 * s**3 - 3 * s**2 + 1,
            s**3 - 2 * s**2 + s,
            -2 * s**3 + 3 * s**2,
            s**3 - s**2,
        )
        d00, d10, d01, d11 = (
            6 * s**2 - 6 * s,
            3 * s**2 - 4 * s + 1,
            -6 * s**2 + 6 * s,
            3 * s**2 - 2 * s,
        )
        xy = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1
        v = (d00 * p0 + d10 * m0 + d01 * p1 + d11 * m1) / T
        return np.asarray(xy), np.asarray(v)


def hermite_leg(
    from_xy_m: FloatArray,
    from_v_mps: FloatArray,
    goal_xy_m: FloatArray,
    now_s: float,
    arrive_by_s: float,
    max_speed_mps: float,
) -> HermiteLeg:
    """The smooth leg to `goal_xy_m` by `arrive_by_s`, ending at the leg's mean velocity (the
    best guess of the next leg's), capped at `max_speed_mps`."""
    T = arrive_by_s - now_s
    mean_v = (np.asarray(goal_xy_m) - np.asarray(from_xy_m)) / T
    speed = float(np.hypot(*mean_v))
    if speed > max_speed_mps:
        mean_v = mean_v * (max_speed_mps / speed)
    return HermiteLeg(
        start_xy_m=np.asarray(from_xy_m, dtype=float),
        start_v_mps=np.asarray(from_v_mps, dtype=float),
        goal_xy_m=np.asarray(goal_xy_m, dtype=float),
        goal_v_mps=mean_v,
        start_s=float(now_s),
        end_s=float(arrive_by_s),
    )


def plan_leg(
    from_xy_m: FloatArray | Sequence[float],
    goal_xy_m: FloatArray | Sequence[float],
    now_s: float,
    arrive_by_s: float | None,
    max_speed_mps: float,
) -> CarrotLeg:
    """The carrot leg from `from_xy_m` to `goal_xy_m` starting at `now_s`: the constant speed
    that arrives at `arrive_by_s`, at most `max_speed_mps` (and exactly that when `arrive_by_s`
    is None or not in the future). Positions [2] in m, times in s."""
    if not (math.isfinite(max_speed_mps) and max_speed_mps > 0):
        raise ValueError(f"max_speed_mps must be finite and > 0, got {max_speed_mps}")
    a, b = as_xy(from_xy_m, "from_xy_m"), as_xy(goal_xy_m, "goal_xy_m")
    d = float(np.hypot(*(b - a)))
    speed = max_speed_mps
    if arrive_by_s is not None and arrive_by_s > now_s:
        speed = min(max_speed_mps, d / (arrive_by_s - now_s))
    if speed <= 0.0:  # d == 0
        speed = max_speed_mps
    return CarrotLeg(start_xy_m=a, goal_xy_m=b, start_s=float(now_s), speed_mps=float(speed))
