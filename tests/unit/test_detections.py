"""model/detections.py: the one noisy-detection function, and the sim's sensor drawing for it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.detections import noisy_detections
from isac_mission.model.radar import measure
from isac_mission.tracking.pcrb import SensingParams
from sim.sensing import SensingModel, Sensor

TARGET = np.array([1000.0, 1200.0, 20.0, -5.0])
UAV_XY = np.array([[1300.0, 1200.0], [1000.0, 800.0], [700.0, 1500.0]])
ETA = np.array([0.2, 0.3, 0.5])


def test_the_noise_is_the_scaled_normals_on_the_true_measurement(paper: Scenario) -> None:
    sensing = SensingParams.from_scenario(paper)
    normals = np.random.default_rng(3).standard_normal(6)
    z = noisy_detections(TARGET, UAV_XY, ETA, sensing, normals, np.ones(3) * 0.5, 0.0)
    h = measure(TARGET, UAV_XY)
    np.testing.assert_array_equal(z, h + np.sqrt(sensing.variances(h[:3], ETA)) * normals)


def test_a_miss_no_bandwidth_or_zero_range_loses_both_quantities(paper: Scenario) -> None:
    sensing = SensingParams.from_scenario(paper)
    normals = np.zeros(6)
    uniforms = np.array([0.05, 0.5, 0.5])  # UAV 0 below the miss probability
    z = noisy_detections(TARGET, UAV_XY, ETA, sensing, normals, uniforms, 0.1)
    assert np.isnan(z[0]) and np.isnan(z[3]) and np.all(np.isfinite(z[[1, 2, 4, 5]]))
    eta = np.array([0.5, 0.0, 0.5])  # UAV 1 senses nothing
    z = noisy_detections(TARGET, UAV_XY, eta, sensing, normals, np.ones(3) * 0.5, 0.0)
    assert np.isnan(z[1]) and np.isnan(z[4]) and np.all(np.isfinite(z[[0, 2, 3, 5]]))
    above = UAV_XY.copy()
    above[2] = TARGET[:2]  # UAV 2 exactly above the target
    z = noisy_detections(TARGET, above, ETA, sensing, normals, np.ones(3) * 0.5, 0.0)
    assert np.isnan(z[2]) and np.isnan(z[5]) and np.all(np.isfinite(z[[0, 1, 3, 4]]))


def test_the_sensor_draws_range_then_velocity_normals_then_the_misses(paper: Scenario) -> None:
    """The sim's draw order per slot (M, M, M) feeds the same function: same seed, same values."""
    model = replace(SensingModel.from_scenario(paper), missed_detection_prob=0.3)
    sensor = Sensor(model, np.random.default_rng(11))
    rng = np.random.default_rng(11)
    for n in range(20):
        got = sensor.sense(n, TARGET, UAV_XY, ETA)
        z_d, z_v, u = rng.standard_normal(3), rng.standard_normal(3), rng.random(3)
        want = noisy_detections(
            TARGET, UAV_XY, ETA, model.params, np.concatenate([z_d, z_v]), u, 0.3
        )
        np.testing.assert_array_equal(got.range_m, want[:3])
        np.testing.assert_array_equal(got.radial_velocity_mps, want[3:])
