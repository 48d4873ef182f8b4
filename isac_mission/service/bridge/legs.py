"""Leg shapes: where the setpoint is between two waypoints (pure; scenario plane, m, m/s, s).

A *carrot* (`CarrotLeg`, `plan_leg`) moves in a straight line from where it is toward the
waypoint at the constant speed needed to arrive at `arrive_by_s`, never above V_max, with that
velocity as feed-forward, and stops at the waypoint. A smooth leg (`HermiteLeg`, `hermite_leg`)
runs on the cubic that keeps position and velocity continuous across legs (the vehicle model's
leg, isac_mission/model/vehicle.py), ending at the plan's velocity when the plan gives one. Legs chain: the next
leg starts where the setpoint is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from isac_mission.model.vehicle import hermite_position, hermite_velocity, mean_velocity
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
    goal_v_mps) at `end_s` (model/vehicle.py's Hermite leg), then coasting at goal_v_mps for
    `coast_s`, then resting where the coast ended (scenario plane, m, m/s, s).

    Position and velocity are continuous across legs, so a vehicle with finite acceleration can
    follow it; a constant-speed carrot jumps in velocity at every slot boundary, and a vehicle
    limited to a few m/s^2 then trails the plan by metres. The coast bridges the time between
    the slot boundary and the next plan (in lockstep the world holds at the boundary while the
    setpoint is sampled `setpoint_lead_s` ahead of it; in real time the plan comes a planning
    latency later): the next leg then starts at the planned velocity, not at rest.
    """

    start_xy_m: FloatArray
    start_v_mps: FloatArray
    goal_xy_m: FloatArray
    goal_v_mps: FloatArray
    start_s: float
    end_s: float
    coast_s: float = 0.0

    def sample(self, t_s: float) -> tuple[FloatArray, FloatArray]:
        """Setpoint position [2], m, and velocity [2], m/s, at time `t_s`."""
        T = self.end_s - self.start_s
        if T <= 0.0:
            return self.goal_xy_m.copy(), np.zeros(2)
        if t_s >= self.end_s:
            past = t_s - self.end_s
            if past < self.coast_s:
                return self.goal_xy_m + self.goal_v_mps * past, self.goal_v_mps.copy()
            return self.goal_xy_m + self.goal_v_mps * self.coast_s, np.zeros(2)
        s = max(0.0, t_s - self.start_s) / T
        legs = (self.start_xy_m, self.start_v_mps, self.goal_xy_m, self.goal_v_mps, T, s)
        return np.asarray(hermite_position(*legs)), np.asarray(hermite_velocity(*legs))


def hermite_leg(
    from_xy_m: FloatArray,
    from_v_mps: FloatArray,
    goal_xy_m: FloatArray,
    now_s: float,
    arrive_by_s: float,
    max_speed_mps: float,
    goal_v_mps: FloatArray | None = None,
    coast_s: float = 0.0,
) -> HermiteLeg:
    """The smooth leg to `goal_xy_m` by `arrive_by_s`, ending at the planned velocity
    `goal_v_mps` [2] when given, else at the leg's mean velocity (the mean-velocity leg of
    model/vehicle.py, the best guess of the next leg's); either capped at `max_speed_mps`.
    `coast_s`: how long the setpoint goes on at that velocity past `arrive_by_s` (HermiteLeg)."""
    T = arrive_by_s - now_s
    if goal_v_mps is None:
        end_v = np.asarray(mean_velocity(np.asarray(from_xy_m), np.asarray(goal_xy_m), T))
    else:
        end_v = as_xy(goal_v_mps, "goal_v_mps")
    speed = float(np.hypot(*end_v))
    if speed > max_speed_mps:
        end_v = end_v * (max_speed_mps / speed)
    return HermiteLeg(
        start_xy_m=np.asarray(from_xy_m, dtype=float),
        start_v_mps=np.asarray(from_v_mps, dtype=float),
        goal_xy_m=np.asarray(goal_xy_m, dtype=float),
        goal_v_mps=np.asarray(end_v, dtype=float),
        start_s=float(now_s),
        end_s=float(arrive_by_s),
        coast_s=float(coast_s),
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
