"""sim/sensing.py: detection noise has the model's variance at each bandwidth share; misses."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from isac_mission.config import parse_scenario
from isac_mission.model.radar import measure, noise_variances
from sim.sensing import SensingModel, Sensor, equal_shares

ALPHA = 1e-3  # two-sided 99.9 % intervals


def _model(miss: float = 0.0) -> SensingModel:
    return replace(SensingModel.from_scenario(parse_scenario({})), missed_detection_prob=miss)


def test_noise_variance_matches_the_model_at_two_bandwidth_shares() -> None:
    model = _model()
    sensor = Sensor(model, np.random.default_rng(2024))
    target = np.array([1500.0, 1500.0, 30.0, -10.0])
    # Two UAVs at different ranges with two different shares.
    uav_xy = np.array([[1500.0, 2100.0], [900.0, 1200.0]])
    eta = np.array([0.2, 0.8])
    n = 4000
    truth = measure(target, uav_xy)
    err = np.empty((n, 4))
    for i in range(n):
        d = sensor.sense(i, target, uav_xy, eta)
        err[i] = np.concatenate([d.range_m, d.radial_velocity_mps]) - truth
    var_d, var_v = noise_variances(
        truth[:2],
        eta,
        radar_gain=model.radar_gain,
        alpha_d=model.alpha_d,
        alpha_v=model.alpha_v,
        B=model.B,
        Ts=model.Ts,
    )
    lo, hi = stats.chi2.ppf(ALPHA / 2, n - 1), stats.chi2.ppf(1 - ALPHA / 2, n - 1)
    expected = np.concatenate([var_d, var_v])
    names = ["range eta=0.2", "range eta=0.8", "velocity eta=0.2", "velocity eta=0.8"]
    for k, name in enumerate(names):
        s2 = float(np.var(err[:, k], ddof=1))
        ratio = (n - 1) * s2 / expected[k]
        assert lo < ratio < hi, (
            f"{name}: sample variance {s2:.4g} vs model {expected[k]:.4g} "
            f"((n-1)s^2/sigma^2 = {ratio:.0f} outside [{lo:.0f}, {hi:.0f}])"
        )
        # and unbiased: |mean| within the two-sided 99.9 % normal bound
        z = float(np.mean(err[:, k]) / np.sqrt(expected[k] / n))
        assert abs(z) < stats.norm.ppf(1 - ALPHA / 2), f"{name}: biased (z = {z:.2f})"


def test_missed_detection_frequency_is_within_a_binomial_bound() -> None:
    p = 0.2
    sensor = Sensor(_model(p), np.random.default_rng(5))
    target = np.array([1500.0, 1500.0, 30.0, 0.0])
    uav_xy = np.array([[1500.0, 2100.0], [900.0, 1200.0], [2100.0, 1200.0]])
    n = 3000
    missed = 0
    for i in range(n):
        d = sensor.sense(i, target, uav_xy, equal_shares(3))
        # a miss loses both quantities of that UAV together
        np.testing.assert_array_equal(np.isnan(d.range_m), np.isnan(d.radial_velocity_mps))
        missed += int(np.count_nonzero(np.isnan(d.range_m)))
    trials = 3 * n
    lo = stats.binom.ppf(ALPHA / 2, trials, p)
    hi = stats.binom.ppf(1 - ALPHA / 2, trials, p)
    assert lo <= missed <= hi, f"{missed} misses in {trials}, expected [{lo:.0f}, {hi:.0f}]"


def test_no_misses_when_the_probability_is_zero() -> None:
    sensor = Sensor(_model(0.0), np.random.default_rng(1))
    uav_xy = np.array([[1500.0, 2100.0], [900.0, 1200.0]])
    for i in range(200):
        d = sensor.sense(i, np.array([1500.0, 1500, 1, 1]), uav_xy, equal_shares(2))
        assert np.all(d.received)


def test_same_seed_gives_the_same_detections_and_positions_pass_through() -> None:
    target = np.array([1000.0, 1000.0, 5.0, 5.0])
    uav_xy = np.array([[1200.0, 1000.0], [1000.0, 700.0]])
    a = Sensor(_model(0.3), np.random.default_rng(9))
    b = Sensor(_model(0.3), np.random.default_rng(9))
    for i in range(30):
        da = a.sense(i, target, uav_xy, equal_shares(2))
        db = b.sense(i, target, uav_xy, equal_shares(2))
        np.testing.assert_array_equal(da.range_m, db.range_m)
        np.testing.assert_array_equal(da.radial_velocity_mps, db.radial_velocity_mps)
        np.testing.assert_array_equal(da.uav_xy_m, uav_xy)
        assert da.slot == i


def test_a_uav_without_bandwidth_senses_nothing() -> None:
    sensor = Sensor(_model(), np.random.default_rng(1))
    d = sensor.sense(
        0,
        np.array([1000.0, 1000, 0, 0]),
        np.array([[1200.0, 1000], [800, 1000]]),
        np.array([0, 1.0]),
    )
    assert not d.received[0] and d.received[1]


def test_shapes_are_checked() -> None:
    sensor = Sensor(_model(), np.random.default_rng(1))
    with pytest.raises(ValueError, match="eta"):
        sensor.sense(0, np.zeros(4) + 1, np.array([[0.0, 0.0]]), np.array([0.5, 0.5]))
