"""sim/vehicle.py: the kinematic multirotor tracks setpoints within its limits, without overshoot."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from isac_mission.errors import IsacError
from sim.vehicle import (
    Setpoint,
    VehicleLimits,
    VehicleState,
    step,
    stopping_point,
    wrap_pi,
)

DT = 0.02
LIMITS = VehicleLimits()
# Float rounding in the saturation (a norm rescaled to the limit) is a few ulp of the limit.
ROUND = 1e-9


def fly(state: VehicleState, sp: Setpoint, seconds: float, limits: VehicleLimits = LIMITS):
    """The trajectory of `seconds` of flight toward `sp`: list of states, first = `state`."""
    states = [state]
    for _ in range(round(seconds / DT)):
        states.append(step(states[-1], sp, limits, DT))
    return states


def hovering_at(north: float, east: float, alt: float) -> VehicleState:
    return VehicleState(position_ned_m=np.array([north, east, -alt]))


def test_a_50_m_step_arrives_without_overshooting_half_a_metre() -> None:
    start = hovering_at(0.0, 0.0, 10.0)
    states = fly(start, Setpoint.hold_at(np.array([50.0, 0.0, -10.0])), 20.0)
    north = np.array([s.position_ned_m[0] for s in states])
    assert north.max() <= 50.0 + 0.5
    # Lower bound on the time: 12 m/s cruise with 5 m/s^2 ramps takes about 6.6 s for 50 m.
    t_arrive = DT * int(np.argmax(np.abs(north - 50.0) < 0.1))
    assert 6.0 < t_arrive < 12.0
    final = states[-1]
    assert final.position_ned_m == pytest.approx([50.0, 0.0, -10.0], abs=1e-3)
    assert final.velocity_ned_mps == pytest.approx([0.0, 0.0, 0.0], abs=1e-3)


def test_diagonal_step_keeps_the_speed_norm_within_the_limit() -> None:
    states = fly(hovering_at(0, 0, 10), Setpoint.hold_at(np.array([60.0, -80.0, -10.0])), 20.0)
    speeds = [float(np.hypot(*s.velocity_ned_mps[:2])) for s in states]
    assert max(speeds) <= LIMITS.max_horizontal_speed_mps * (1 + ROUND)
    assert max(speeds) >= LIMITS.max_horizontal_speed_mps * (1 - ROUND), "cruises at the limit"


def test_acceleration_never_exceeds_the_limits() -> None:
    states = fly(hovering_at(0, 0, 5), Setpoint.hold_at(np.array([-40.0, 30.0, -25.0])), 25.0)
    v = np.array([s.velocity_ned_mps for s in states])
    a = np.diff(v, axis=0) / DT
    assert np.hypot(a[:, 0], a[:, 1]).max() <= LIMITS.max_horizontal_accel_mps2 * (1 + ROUND)
    assert np.abs(a[:, 2]).max() <= LIMITS.max_vertical_accel_mps2 * (1 + ROUND)


def test_climb_and_descent_rates_are_limited_separately() -> None:
    up = fly(hovering_at(0, 0, 0), Setpoint.hold_at(np.array([0.0, 0.0, -40.0])), 30.0)
    down = fly(hovering_at(0, 0, 40), Setpoint.hold_at(np.array([0.0, 0.0, -1.0])), 40.0)
    vz_up = np.array([s.velocity_ned_mps[2] for s in up])
    vz_down = np.array([s.velocity_ned_mps[2] for s in down])
    assert vz_up.min() == pytest.approx(-LIMITS.max_climb_rate_mps)
    assert vz_down.max() == pytest.approx(LIMITS.max_descent_rate_mps)
    assert up[-1].position_ned_m[2] == pytest.approx(-40.0, abs=1e-3)
    assert down[-1].position_ned_m[2] == pytest.approx(-1.0, abs=1e-3)


def test_velocity_setpoint_is_tracked_and_free_axes_brake() -> None:
    start = VehicleState(
        position_ned_m=np.array([0.0, 0.0, -10.0]), velocity_ned_mps=np.array([0.0, 0.0, -2.0])
    )
    sp = Setpoint(velocity_ned_mps=np.array([3.0, -4.0, math.nan]))  # z free: brake to 0
    final = fly(start, sp, 5.0)[-1]
    assert final.velocity_ned_mps == pytest.approx([3.0, -4.0, 0.0], abs=1e-9)


def test_velocity_setpoint_beyond_the_limit_is_saturated() -> None:
    sp = Setpoint(velocity_ned_mps=np.array([100.0, 0.0, -100.0]))
    final = fly(hovering_at(0, 0, 10), sp, 10.0)[-1]
    assert final.velocity_ned_mps[0] == pytest.approx(LIMITS.max_horizontal_speed_mps)
    assert final.velocity_ned_mps[2] == pytest.approx(-LIMITS.max_climb_rate_mps)


def test_the_vehicle_never_goes_below_the_ground() -> None:
    sp = Setpoint(velocity_ned_mps=np.array([0.0, 0.0, 5.0]))
    states = fly(hovering_at(0, 0, 3), sp, 10.0)
    assert max(s.position_ned_m[2] for s in states) <= LIMITS.ground_down_m
    assert states[-1].velocity_ned_mps[2] == 0.0


def test_yaw_turns_the_short_way_at_the_rate_limit() -> None:
    start = VehicleState(yaw_rad=math.radians(170.0))
    sp = Setpoint(position_ned_m=np.zeros(3), yaw_rad=math.radians(-170.0))
    first = step(start, sp, LIMITS, DT)
    assert wrap_pi(first.yaw_rad - start.yaw_rad) > 0, "through 180 deg, not back through 0"
    states = fly(VehicleState(yaw_rad=0.0), Setpoint(yaw_rad=math.pi / 2), 5.0)
    rates = np.diff([s.yaw_rad for s in states]) / DT
    assert rates.max() <= LIMITS.max_yaw_rate_rps * (1 + ROUND)
    assert states[-1].yaw_rad == pytest.approx(math.pi / 2, abs=1e-3)


def test_step_is_deterministic_and_leaves_its_inputs_alone() -> None:
    state = hovering_at(1.0, 2.0, 3.0)
    sp = Setpoint.hold_at(np.array([10.0, 20.0, -30.0]))
    a = step(state, sp, LIMITS, DT)
    b = step(state, sp, LIMITS, DT)
    assert np.array_equal(a.position_ned_m, b.position_ned_m)
    assert np.array_equal(a.velocity_ned_mps, b.velocity_ned_mps)
    assert state.position_ned_m == pytest.approx([1.0, 2.0, -3.0])
    with pytest.raises(ValueError, match="read-only"):
        a.position_ned_m[0] = 5.0


def test_stopping_point_is_where_braking_ends() -> None:
    moving = VehicleState(
        position_ned_m=np.array([0.0, 0.0, -20.0]), velocity_ned_mps=np.array([8.0, 0.0, 0.0])
    )
    p = stopping_point(moving, LIMITS)
    a_brake = LIMITS.braking_fraction * LIMITS.max_horizontal_accel_mps2
    assert p == pytest.approx([8.0**2 / (2 * a_brake), 0.0, -20.0])
    held = fly(moving, Setpoint.hold_at(p), 10.0)
    north = [s.position_ned_m[0] for s in held]
    assert max(north) <= p[0] + 0.05, "holding at the stopping point does not bounce back"


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"max_horizontal_speed_mps": 0.0}, "max_horizontal_speed_mps"),
        ({"max_climb_rate_mps": math.nan}, "max_climb_rate_mps"),
        ({"braking_fraction": 1.5}, "braking_fraction"),
    ],
)
def test_invalid_limits_are_refused_with_the_bad_value_named(kwargs, match) -> None:
    with pytest.raises(IsacError, match=match):
        VehicleLimits(**kwargs)


def test_invalid_dt_and_shapes_are_refused() -> None:
    with pytest.raises(IsacError, match="dt"):
        step(VehicleState(), Setpoint(), LIMITS, 0.0)
    with pytest.raises(IsacError, match="3-vector"):
        VehicleState(position_ned_m=np.zeros(2))


finite = st.floats(min_value=-200.0, max_value=200.0, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(
    target=st.tuples(finite, finite, st.floats(min_value=-100.0, max_value=0.0)),
    v0=st.tuples(st.floats(-8.0, 8.0), st.floats(-8.0, 8.0), st.floats(-1.4, 1.4)),
)
def test_limits_hold_for_any_position_step(target, v0) -> None:
    start = VehicleState(position_ned_m=np.array([0.0, 0.0, -50.0]), velocity_ned_mps=np.array(v0))
    states = fly(start, Setpoint.hold_at(np.array(target)), 4.0)
    v = np.array([s.velocity_ned_mps for s in states])
    a = np.diff(v, axis=0) / DT
    assert np.hypot(v[:, 0], v[:, 1]).max() <= max(
        LIMITS.max_horizontal_speed_mps, float(np.hypot(v0[0], v0[1]))
    ) * (1 + ROUND)
    assert np.hypot(a[:, 0], a[:, 1]).max() <= LIMITS.max_horizontal_accel_mps2 * (1 + ROUND)
    assert np.abs(a[:, 2]).max() <= LIMITS.max_vertical_accel_mps2 * (1 + ROUND)
