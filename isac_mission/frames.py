"""Frames in one place: the scenario plane, a vehicle's local NED frame, geodetic positions.

- Scenario plane: x east, y north, m, origin (0, 0) on the ground; altitude up, m.
- Local NED (MAVLink MAV_FRAME_LOCAL_NED): north, east, down, m, centred on the vehicle's local
  origin `origin_xy_m` [2], a scenario-plane point on the ground. So x = east + x0,
  y = north + y0, altitude = -down (the ground at down = 0; a frame whose ground is elsewhere
  passes `ground_down_m`).
- Geodetic: latitude and longitude in degrees (WGS-84), altitude AMSL in m, from the geodetic
  position of the scenario origin by a flat-earth (equirectangular) conversion, so that every
  vehicle of a scenario agrees on global positions whatever its local origin.

Pure functions, no I/O (docs/frames-and-clocks.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np

from isac_mission.types import FloatArray

EARTH_RADIUS_M: Final = 6_378_137.0
"""WGS-84 equatorial radius, m: the sphere of the flat-earth conversion."""


@dataclass(frozen=True)
class GeoPoint:
    """A geodetic position: latitude and longitude in degrees (WGS-84), altitude AMSL in m."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float


PX4_SITL_ORIGIN: Final = GeoPoint(47.397742, 8.545594, 488.0)
"""PX4 SITL's default home, the simulated vehicles' default geodetic origin."""


def ned_to_scenario(
    position_ned_m: FloatArray, origin_xy_m: FloatArray | Sequence[float]
) -> tuple[FloatArray, float]:
    """Scenario-plane (x east, y north) position [2], m, and altitude (-down), m, of a local
    NED position [3] whose origin is `origin_xy_m` [2] in the scenario plane."""
    return ned_to_scenario_xy(position_ned_m, origin_xy_m), -float(position_ned_m[2])


def ned_to_scenario_xy(
    position_ned_m: FloatArray, origin_xy_m: FloatArray | Sequence[float]
) -> FloatArray:
    """Scenario-plane (x east, y north) position [2], m, of a local NED position [2] or [3]
    (north, east[, down]) whose origin is `origin_xy_m` [2] in the scenario plane."""
    o = np.asarray(origin_xy_m, dtype=float)
    p = np.asarray(position_ned_m, dtype=float)
    return np.array([p[1] + o[0], p[0] + o[1]])


def scenario_to_ned(
    xy_m: FloatArray | Sequence[float], altitude_m: float, origin_xy_m: FloatArray | Sequence[float]
) -> FloatArray:
    """Local NED position [3], m, of a scenario-plane point [2] at `altitude_m`."""
    o = np.asarray(origin_xy_m, dtype=float)
    xy = np.asarray(xy_m, dtype=float)
    return np.array([xy[1] - o[1], xy[0] - o[0], -float(altitude_m)])


def ned_to_scenario_velocity(velocity_ned_mps: FloatArray | Sequence[float]) -> FloatArray:
    """Scenario-plane velocity [2] (east, north), m/s, of a NED velocity [2] or [3]."""
    v = velocity_ned_mps
    return np.array([v[1], v[0]])


def scenario_to_ned_velocity(
    velocity_xy_mps: FloatArray | Sequence[float], down_mps: float = 0.0
) -> FloatArray:
    """NED velocity [3], m/s, of a scenario-plane velocity [2] (east, north) and `down_mps`."""
    v = velocity_xy_mps
    return np.array([v[1], v[0], down_mps])


def scenario_to_geodetic(
    xy_m: FloatArray | Sequence[float], alt_m: float, origin: GeoPoint
) -> GeoPoint:
    """Flat-earth conversion of a scenario-plane point (x east, y north, m; (2,)) at `alt_m`
    above the ground to geodetic, with `origin` the geodetic position of scenario (0, 0)."""
    lat0 = math.radians(origin.lat_deg)
    lat = origin.lat_deg + math.degrees(float(xy_m[1]) / EARTH_RADIUS_M)
    lon = origin.lon_deg + math.degrees(float(xy_m[0]) / (EARTH_RADIUS_M * math.cos(lat0)))
    return GeoPoint(lat, lon, origin.alt_amsl_m + alt_m)


def ned_to_geodetic(
    position_ned_m: FloatArray,
    origin_xy_m: FloatArray | Sequence[float],
    geo_origin: GeoPoint,
    ground_down_m: float = 0.0,
) -> GeoPoint:
    """Geodetic position of a local NED position [3], m, whose frame is centred on
    `origin_xy_m` [2] in the scenario plane with the ground at down = `ground_down_m`;
    `geo_origin` is the geodetic position of scenario (0, 0) on the ground."""
    xy = ned_to_scenario_xy(position_ned_m, origin_xy_m)
    return scenario_to_geodetic(xy, float(ground_down_m - position_ned_m[2]), geo_origin)


def geodetic_to_scenario(point: GeoPoint, origin: GeoPoint) -> tuple[FloatArray, float]:
    """Inverse of `scenario_to_geodetic`: scenario-plane position [2], m, and altitude above
    the ground, m, of `point`, with `origin` the geodetic position of scenario (0, 0)."""
    lat0 = math.radians(origin.lat_deg)
    y = math.radians(point.lat_deg - origin.lat_deg) * EARTH_RADIUS_M
    x = math.radians(point.lon_deg - origin.lon_deg) * EARTH_RADIUS_M * math.cos(lat0)
    return np.array([x, y]), point.alt_amsl_m - origin.alt_amsl_m
