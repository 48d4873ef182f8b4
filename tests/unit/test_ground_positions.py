"""Where the ground loop plans from (service/ground/exclusion.py `VehicleWatch.positions`):
current telemetry (at most `telemetry_current_s` old), else the slot's detection positions, where
the UAVs were at the boundary, which beat late telemetry (over a late radio a round trip older;
docs/reliability.md, "Lossy, late radio links"), else fresh telemetry."""

from __future__ import annotations

import numpy as np

from isac_mission.service.ground.exclusion import VehicleWatch
from isac_mission.service.ground.report import GroundReport
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.wire import TelemetryMsg


def _tel(uav: int, t_s: float, xy: tuple[float, float], link: str = "ok") -> TelemetryMsg:
    return TelemetryMsg(
        0, t_s, uav, np.array(xy), 100.0, np.array([5.0, 0.0]), "offboard", True, False, link
    )


def test_detection_positions_win_over_telemetry_which_fills_the_gaps() -> None:
    watch = VehicleWatch(3, GroundSettings(), GroundReport())
    for m in range(3):
        watch.on_telemetry(_tel(m, 9.9, (100.0 * m, 0.0)))  # 0.1 s old at t = 10
    det = np.array([[0.5, 0.0], [np.nan, np.nan], [200.5, 0.0]])  # UAV 1's detection missing
    xy = watch.positions(10.0, det)
    np.testing.assert_array_equal(xy, [[0.5, 0.0], [100.0, 0.0], [200.5, 0.0]])
    # Current telemetry (0.01 s old) wins over the detections.
    for m in range(3):
        watch.on_telemetry(_tel(m, 9.99, (100.0 * m, 1.0)))
    np.testing.assert_array_equal(
        watch.positions(10.0, det), [[0.0, 1.0], [100.0, 1.0], [200.0, 1.0]]
    )
    for m in range(3):
        watch.on_telemetry(_tel(m, 9.9, (100.0 * m, 0.0)))
    # Without detections (a slot's own update), telemetry as before; stale telemetry: nothing.
    np.testing.assert_array_equal(watch.positions(10.0), [[0.0, 0.0], [100.0, 0.0], [200.0, 0.0]])
    assert np.all(np.isnan(watch.positions(20.0)))


def test_an_excluded_vehicle_holds_where_it_was_last_seen_whatever_its_detection_says() -> None:
    watch = VehicleWatch(2, GroundSettings(), GroundReport())
    watch.on_telemetry(_tel(0, 9.9, (0.0, 0.0)))
    watch.on_telemetry(_tel(1, 5.0, (300.0, 0.0), link="lost"))
    watch.excluded[1] = "link lost"
    xy = watch.positions(10.0, np.array([[1.0, 0.0], [320.0, 0.0]]))
    np.testing.assert_array_equal(xy, [[1.0, 0.0], [300.0, 0.0]])
