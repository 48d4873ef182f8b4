"""The vehicles' motion between slot instants: cubic Hermite legs (pure; scenario plane, m, m/s, s).

A leg runs from (p0, v0) at the start of a slot to (p1, v1) at its end, T = dt later, on the
cubic that matches position and velocity at both ends. It is what the bridge streams as setpoints
and what the planner's vehicle model (planner.vehicle_model) plans: positions and velocities at
slot boundaries, with the leg between them.

On a cubic the acceleration is linear in time, so its largest norm over the leg is at one of
the two ends (`end_accelerations`): |a(0)|, |a(T)| <= a_max is exact. The velocity is a quadratic
Bezier curve with control points v0, 3 (p1 - p0) / T - v0 - v1, v1 (`velocity_control_points`);
its norm never exceeds the largest control point's (convex hull), so bounding the three by V_max
keeps the whole leg within V_max (conservative by at most the hull's bulge).

Every function uses only + - * / on its arguments, so it takes numpy arrays ([..., 2], broadcast)
and CasADi symbols alike (planning/horizon_nlp.py builds the same legs symbolically).
"""

from __future__ import annotations

from typing import Any


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
