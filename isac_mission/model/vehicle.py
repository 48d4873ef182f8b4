"""The vehicles' motion between slot instants: cubic Hermite legs (pure; scenario plane, m, m/s, s).

A leg runs from (p0, v0) at the start of a slot to (p1, v1) at its end, T = dt later, on the
cubic that matches position and velocity at both ends. It is what the bridge streams as setpoints
(service/bridge/legs.py), what the planner's vehicle model (planner.vehicle_model) plans
(positions and velocities at slot boundaries, with the leg between them) and what `simulate`
flies with the vehicle model on. One model for all of them: `VehicleModel` (V_max, a_max, dt).

On a cubic the acceleration is linear in time, so its largest norm over the leg is at one of
the two ends (`end_accelerations`): |a(0)|, |a(T)| <= a_max is exact. The velocity is a quadratic
Bezier curve with control points v0, 3 (p1 - p0) / T - v0 - v1, v1 (`velocity_control_points`);
its norm never exceeds the largest control point's (convex hull), so bounding the three by V_max
keeps the whole leg within V_max (conservative by at most the hull's bulge). The exact largest
speed (`peak_speed`) is at an end or where d|v|^2/ds = 0, a cubic in s.

The mean-velocity leg (derivation; docs/model.md, "Vehicle model"). Write the end point as the
coasting point plus a deviation, p1 = p0 + v0 T + d, and end the leg at its mean velocity
v1 = (p1 - p0) / T = v0 + d / T (what the bridge has flown since its smooth legs, and what the
planner plans with planner.vehicle_model). Substituting into the Hermite basis:

    p(s) = p0 + v0 T s + d s^2 (2 - s),   v(s) = v0 + (d / T)(4 s - 3 s^2),
    a(s) = (d / T^2)(4 - 6 s),

so a(0) = 4 d / T^2 and a(T) = -2 d / T^2: |a(0)| = 4 |p1 - (p0 + v0 T)| / T^2 and |a(T)| is half
of it. The leg is within a_max if and only if |d| <= a_max T^2 / 4: its exact reach is the disk of
radius a_max T^2 / 4 around the coasting point p0 + v0 T (`VehicleModel.reach_radius_m`). Its
velocity runs along the segment v0 + (d / T) g with g = 4 s - 3 s^2 in [0, 4/3] (the largest, 4/3,
at s = 2/3), so its peak speed is max(|v0|, |v0 + 4 d / (3 T)|): at most |v0| + a_max T / 3 on the
reach disk (a vehicle at V_max that the plan pushes further along its velocity would go faster
mid-leg; `VehicleModel.check_leg` says so).

Every leg function uses only + - * / on its arguments, so it takes numpy arrays ([..., 2],
broadcast) and CasADi symbols alike (planning/horizon_nlp.py builds the same legs symbolically);
`VehicleModel`'s checks and `peak_speed` are numpy only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from isac_mission.types import BoolArray, FloatArray


def hermite_position(p0: Any, v0: Any, p1: Any, v1: Any, T_s: float, s: float) -> Any:
    """Position on the leg at fraction s in [0, 1] of its duration T_s (m)."""
    h00 = 2 * s**3 - 3 * s**2 + 1
    h10 = s**3 - 2 * s**2 + s
    h01 = -2 * s**3 + 3 * s**2
    h11 = s**3 - s**2
    return h00 * p0 + h10 * T_s * v0 + h01 * p1 + h11 * T_s * v1


def hermite_velocity(p0: Any, v0: Any, p1: Any, v1: Any, T_s: float, s: float) -> Any:
    """Velocity on the leg at fraction s in [0, 1] (m/s)."""
    d00 = 6 * s**2 - 6 * s
    d10 = 3 * s**2 - 4 * s + 1
    d01 = -6 * s**2 + 6 * s
    d11 = 3 * s**2 - 2 * s
    return (d00 * p0 + d01 * p1) / T_s + d10 * v0 + d11 * v1


def end_accelerations(p0: Any, v0: Any, p1: Any, v1: Any, T_s: float) -> tuple[Any, Any]:
    """(a(0), a(T)) in m/s^2: the leg's acceleration at its two ends, where its norm peaks."""
    delta = p1 - p0
    a0 = (6 * delta - 4 * T_s * v0 - 2 * T_s * v1) / T_s**2
    a1 = (-6 * delta + 2 * T_s * v0 + 4 * T_s * v1) / T_s**2
    return a0, a1


def velocity_control_points(p0: Any, v0: Any, p1: Any, v1: Any, T_s: float) -> tuple[Any, Any, Any]:
    """The Bezier control points (m/s) of the leg's velocity: its speed is at most their
    largest norm at every instant of the leg."""
    return v0, 3 * (p1 - p0) / T_s - v0 - v1, v1


def mean_velocity(p0: Any, p1: Any, T_s: float) -> Any:
    """(p1 - p0) / T_s (m/s): the end velocity of the mean-velocity leg (module docstring)."""
    return (p1 - p0) / T_s


def _norm(x: FloatArray) -> FloatArray:
    return np.asarray(np.linalg.norm(x, axis=-1), dtype=float)


def peak_speed(
    p0: FloatArray, v0: FloatArray, p1: FloatArray, v1: FloatArray, T_s: float
) -> FloatArray:
    """The exact largest speed over the leg (m/s), one per leg of the [..., 2] arguments ([...]).

    v(s) = A s^2 + B s + C with C = b0, B = 2 (b1 - b0), A = b0 - 2 b1 + b2 (the control points
    b0, b1, b2); |v|^2 peaks at s = 0, s = 1 or a root in (0, 1) of
    d|v|^2/ds / 2 = 2|A|^2 s^3 + 3 A.B s^2 + (|B|^2 + 2 A.C) s + B.C.
    """
    p0, v0, p1, v1 = np.broadcast_arrays(*(np.asarray(x, float) for x in (p0, v0, p1, v1)))
    b0, b1, b2 = velocity_control_points(p0, v0, p1, v1, T_s)
    C, B, A = b0, 2 * (b1 - b0), b0 - 2 * b1 + b2
    flat = [x.reshape(-1, 2) for x in (A, B, C)]
    out = np.empty(flat[0].shape[0])
    for i, (a, b, c) in enumerate(zip(*flat, strict=True)):
        coeffs = [2 * a @ a, 3 * a @ b, b @ b + 2 * a @ c, b @ c]
        candidates = [0.0, 1.0]
        scale = max(abs(k) for k in coeffs)
        if scale > 0:
            first = next(j for j, k in enumerate(coeffs) if abs(k) > 1e-12 * scale)
            for root in np.roots(coeffs[first:]):
                if abs(root.imag) < 1e-9 and 0.0 < root.real < 1.0:
                    candidates.append(float(root.real))
        out[i] = max(float(np.linalg.norm(a * s * s + b * s + c)) for s in candidates)
    return out.reshape(A.shape[:-1])


@dataclass(frozen=True)
class LegCheck:
    """How a leg (or a batch [...] of legs) stands against the vehicle model's limits.

    Attributes:
        accel_mps2: [...] the largest acceleration norm over the leg (exact: at an end).
        peak_speed_mps: [...] the largest speed over the leg (exact, `peak_speed`).
        hull_speed_mps: [...] the largest velocity control point norm (>= peak_speed_mps; the
            bound a symbolic planner can state with + - * / only).
        feasible: [...] accel_mps2 <= a_max and peak_speed_mps <= V_max (with the tolerance).
    """

    accel_mps2: FloatArray
    peak_speed_mps: FloatArray
    hull_speed_mps: FloatArray
    feasible: BoolArray


class HasLimits(Protocol):
    """What `VehicleModel.of` reads (config.Scenario has it): V_max (m/s), a_max (m/s^2), dt (s)."""

    @property
    def v_max(self) -> float: ...
    @property
    def a_max(self) -> float: ...
    @property
    def dt(self) -> float: ...


@dataclass(frozen=True)
class VehicleModel:
    """A multirotor that flies cubic Hermite legs of one slot each within V_max and a_max.

    Attributes:
        v_max_mps: V_max, the largest speed anywhere on a leg (m/s).
        a_max_mps2: a_max, the largest acceleration norm anywhere on a leg (m/s^2).
        dt_s: The slot length T, each leg's duration (s).
    """

    v_max_mps: float
    a_max_mps2: float
    dt_s: float

    def __post_init__(self) -> None:
        for name in ("v_max_mps", "a_max_mps2", "dt_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"VehicleModel.{name} must be finite and > 0 (got {value})")

    @classmethod
    def of(cls, scenario: HasLimits) -> VehicleModel:
        """The scenario's vehicles: V_max, a_max (uavs.max_accel_mps2) and dt."""
        return cls(float(scenario.v_max), float(scenario.a_max), float(scenario.dt))

    @property
    def reach_radius_m(self) -> float:
        """a_max dt^2 / 4 (m): the exact reach of the mean-velocity leg around the coasting point."""
        return self.a_max_mps2 * self.dt_s**2 / 4

    def coasting_point(self, p0: FloatArray, v0: FloatArray) -> FloatArray:
        """p0 + v0 dt [..., 2] (m): where a vehicle at p0 with velocity v0 coasts to in one slot."""
        return np.asarray(p0, float) + np.asarray(v0, float) * self.dt_s

    def end_velocity(self, p0: FloatArray, p1: FloatArray) -> FloatArray:
        """(p1 - p0) / dt [..., 2] (m/s): the planned end velocity of the mean-velocity leg."""
        return np.asarray(mean_velocity(np.asarray(p0, float), np.asarray(p1, float), self.dt_s))

    def check_leg(
        self,
        p0: FloatArray,
        v0: FloatArray,
        p1: FloatArray,
        v1: FloatArray | None = None,
        tol: float = 1e-9,
    ) -> LegCheck:
        """The leg(s) from (p0, v0) to (p1, v1) [..., 2] against a_max and V_max (exact; `tol`
        relative slack); v1 None: the mean-velocity leg."""
        p0, v0, p1 = (np.asarray(x, float) for x in (p0, v0, p1))
        v1 = self.end_velocity(p0, p1) if v1 is None else np.asarray(v1, float)
        p0, v0, p1, v1 = np.broadcast_arrays(p0, v0, p1, v1)
        a0, a1 = end_accelerations(p0, v0, p1, v1, self.dt_s)
        accel = np.maximum(_norm(a0), _norm(a1))
        hull = np.max(
            [_norm(b) for b in velocity_control_points(p0, v0, p1, v1, self.dt_s)], axis=0
        )
        speed = peak_speed(p0, v0, p1, v1, self.dt_s)
        ok = (accel <= self.a_max_mps2 * (1 + tol)) & (speed <= self.v_max_mps * (1 + tol))
        return LegCheck(accel, speed, np.asarray(hull, float), np.asarray(ok))

    def sample(
        self,
        p0: FloatArray,
        v0: FloatArray,
        p1: FloatArray,
        v1: FloatArray | None,
        fractions: Sequence[float] | FloatArray,
    ) -> tuple[FloatArray, FloatArray]:
        """Positions (m) and velocities (m/s), each [S, ..., 2], of the leg(s) at the S fractions
        in [0, 1] of the slot; v1 None: the mean-velocity leg."""
        p0, v0, p1 = (np.asarray(x, float) for x in (p0, v0, p1))
        v1 = self.end_velocity(p0, p1) if v1 is None else np.asarray(v1, float)
        T = self.dt_s
        xy = [hermite_position(p0, v0, p1, v1, T, float(s)) for s in fractions]
        v = [hermite_velocity(p0, v0, p1, v1, T, float(s)) for s in fractions]
        return np.asarray(xy, float), np.asarray(v, float)
