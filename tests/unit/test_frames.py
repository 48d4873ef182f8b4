"""isac_mission/frames.py: scenario plane <-> local NED <-> geodetic, one set of conversions."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from isac_mission.frames import (
    EARTH_RADIUS_M,
    PX4_SITL_ORIGIN,
    GeoPoint,
    geodetic_to_scenario,
    ned_to_geodetic,
    ned_to_scenario,
    ned_to_scenario_velocity,
    ned_to_scenario_xy,
    scenario_to_geodetic,
    scenario_to_ned,
    scenario_to_ned_velocity,
)

coord_m = st.floats(min_value=-5000.0, max_value=5000.0, allow_nan=False)
alt_m = st.floats(min_value=0.0, max_value=500.0, allow_nan=False)


def test_ned_to_scenario_swaps_axes_adds_origin_and_negates_down() -> None:
    xy, alt = ned_to_scenario(np.array([10.0, 20.0, -100.0]), (1000.0, 500.0))
    np.testing.assert_allclose(xy, [1020.0, 510.0])  # x = east + x0, y = north + y0
    assert alt == 100.0


def test_scenario_to_ned_inverts_ned_to_scenario() -> None:
    origin = (-30.0, 75.0)
    ned = scenario_to_ned([12.0, -4.0], 42.0, origin)
    np.testing.assert_allclose(ned, [-79.0, 42.0, -42.0])
    xy, alt = ned_to_scenario(ned, origin)
    np.testing.assert_allclose(xy, [12.0, -4.0])
    assert alt == 42.0


@given(coord_m, coord_m, alt_m, coord_m, coord_m)
def test_scenario_ned_round_trip_is_exact_to_rounding(
    x: float, y: float, alt: float, x0: float, y0: float
) -> None:
    ned = scenario_to_ned([x, y], alt, (x0, y0))
    xy, back_alt = ned_to_scenario(ned, (x0, y0))
    # (x - x0) + x0 is x to within one rounding of the larger magnitude.
    tol = 2 * np.finfo(float).eps * max(abs(x), abs(y), abs(x0), abs(y0), 1.0)
    np.testing.assert_allclose(xy, [x, y], rtol=0.0, atol=tol)
    assert back_alt == alt


def test_ned_to_scenario_xy_accepts_a_horizontal_ned_pair() -> None:
    np.testing.assert_array_equal(
        ned_to_scenario_xy(np.array([3.0, 4.0]), (10.0, 20.0)), [14.0, 23.0]
    )


def test_velocities_swap_east_and_north() -> None:
    np.testing.assert_array_equal(ned_to_scenario_velocity(np.array([1.0, 2.0, 3.0])), [2.0, 1.0])
    v = scenario_to_ned_velocity(np.array([2.0, 1.0]))
    np.testing.assert_array_equal(v, [1.0, 2.0, 0.0])
    assert not math.copysign(1.0, v[2]) < 0  # +0.0, as the bridge has always sent
    np.testing.assert_array_equal(scenario_to_ned_velocity([2.0, 1.0], -0.5), [1.0, 2.0, -0.5])


def test_geodetic_of_the_origin_is_the_geodetic_origin() -> None:
    geo = scenario_to_geodetic(np.zeros(2), 0.0, PX4_SITL_ORIGIN)
    assert geo == PX4_SITL_ORIGIN


def test_one_degree_of_latitude_is_an_arc_of_the_earth_radius() -> None:
    arc_m = EARTH_RADIUS_M * math.pi / 180.0
    geo = scenario_to_geodetic(np.array([0.0, arc_m]), 10.0, GeoPoint(0.0, 0.0, 100.0))
    assert math.isclose(geo.lat_deg, 1.0, rel_tol=1e-12)
    assert geo.lon_deg == 0.0
    assert geo.alt_amsl_m == 110.0


def test_east_offsets_shrink_with_the_cosine_of_latitude() -> None:
    origin = GeoPoint(60.0, 10.0, 0.0)  # cos 60 deg = 1/2: a metre east is twice the degrees
    east = scenario_to_geodetic(np.array([1000.0, 0.0]), 0.0, origin)
    at_equator = scenario_to_geodetic(np.array([1000.0, 0.0]), 0.0, GeoPoint(0.0, 10.0, 0.0))
    assert math.isclose(east.lon_deg - 10.0, 2.0 * (at_equator.lon_deg - 10.0), rel_tol=1e-12)


@given(coord_m, coord_m, alt_m)
def test_geodetic_round_trip(x: float, y: float, alt: float) -> None:
    xy, back_alt = geodetic_to_scenario(
        scenario_to_geodetic(np.array([x, y]), alt, PX4_SITL_ORIGIN), PX4_SITL_ORIGIN
    )
    # Degrees near 47 and 8.5 carry ~1e-14 deg of rounding: ~1e-9 m on the ground.
    np.testing.assert_allclose(xy, [x, y], rtol=0.0, atol=1e-6)
    assert math.isclose(back_alt, alt, abs_tol=1e-9)


def test_ned_to_geodetic_goes_through_the_scenario_plane_from_the_local_origin() -> None:
    origin_xy = (100.0, -50.0)
    ned = np.array([20.0, 30.0, -15.0])  # 20 m north, 30 m east of the local origin, 15 m up
    geo = ned_to_geodetic(ned, origin_xy, PX4_SITL_ORIGIN)
    assert geo == scenario_to_geodetic(np.array([130.0, -30.0]), 15.0, PX4_SITL_ORIGIN)
    raised = ned_to_geodetic(ned, origin_xy, PX4_SITL_ORIGIN, ground_down_m=2.0)
    assert math.isclose(raised.alt_amsl_m - geo.alt_amsl_m, 2.0, abs_tol=1e-12)
