"""Several targets' truth and their unlabelled detections (model/targets.py, model/detections.py,
model/run_noise.py), each against an independent computation:

- the coordinated turn against a fine numerical integration of the turning motion, and its
  noise-free path on the circle of radius v / omega;
- the waypoint motion on a hand-made square at constant speed;
- the presence windows; the process noise's covariance by Monte Carlo against W(kappa);
- the detections by Monte Carlo: the detection rate against P_d (binomial bound), the false alarms'
  Poisson mean and their uniform spread (Kolmogorov-Smirnov), the measurement noise against eq. 8,
  the labels, the random order, a UAV without a share sensing nothing;
- the SNR model's P_d = exp(-threshold / SNR) against a Rayleigh-fluctuating echo drawn here;
- the multi-target draws leave a single-target run's numbers unchanged.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from isac_mission.config import load_scenario
from isac_mission.config.targets import DetectionSpec, TargetSpec
from isac_mission.model.detections import (
    CLUTTER,
    SlotDraws,
    detection_probability,
    unlabelled_detections,
)
from isac_mission.model.kinematics import process_noise
from isac_mission.model.radar import SensingParams, measure
from isac_mission.model.run_noise import draw_multi_target_noise, draw_run_noise
from isac_mission.model.targets import coordinated_turn_matrix, target_paths, waypoint_states


def spec(**changes: object) -> TargetSpec:
    base = TargetSpec(
        "t", (1000.0, 1000.0, 20.0, 0.0), 0.1, "constant_velocity", 0.0, (), 0, 30, True
    )
    return replace(base, **changes)  # type: ignore[arg-type]


@pytest.mark.parametrize("omega", [0.05, -0.2, 1e-14])
def test_the_coordinated_turn_is_the_integrated_turning_motion(omega: float) -> None:
    x = np.array([100.0, -50.0, 12.0, -7.0])
    y = x.copy()
    steps = 20000
    h = 2.0 / steps
    for _ in range(steps):  # RK4 of p' = v, v' = omega J v

        def f(s: np.ndarray) -> np.ndarray:
            return np.array([s[2], s[3], -omega * s[3], omega * s[2]])

        k1 = f(y)
        k2 = f(y + h / 2 * k1)
        k3 = f(y + h / 2 * k2)
        k4 = f(y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    np.testing.assert_allclose(coordinated_turn_matrix(2.0, omega) @ x, y, atol=1e-8)


def test_a_noise_free_turning_target_stays_on_its_circle() -> None:
    omega = 0.05
    t = spec(motion="coordinated_turn", turn_rate_radps=omega, x0=(1500.0, 1200.0, 0.0, 25.0))
    paths = target_paths([t], 1.0, 0.0, 30, np.zeros((1, 30, 4)))
    states = paths.states[:, 0]
    centre = np.array([1500.0 - 25.0 / omega, 1200.0])
    np.testing.assert_allclose(np.linalg.norm(states[:, :2] - centre, axis=1), 25.0 / omega)
    np.testing.assert_allclose(np.linalg.norm(states[:, 2:], axis=1), 25.0)
    heading = np.arctan2(states[:, 3], states[:, 2])
    np.testing.assert_allclose(np.unwrap(heading) - heading[0], omega * np.arange(31), atol=1e-12)


def test_the_waypoint_motion_flies_a_square_at_constant_speed() -> None:
    square = [(100.0, 0.0), (100.0, 100.0), (0.0, 100.0)]
    states = waypoint_states((0.0, 0.0, 25.0, 0.0), square, 1.0, 14)
    np.testing.assert_allclose(states[4], [100.0, 0.0, 0.0, 25.0])  # at the corner, turned
    np.testing.assert_allclose(states[6], [100.0, 50.0, 0.0, 25.0])
    np.testing.assert_allclose(states[10], [50.0, 100.0, -25.0, 0.0])
    np.testing.assert_allclose(states[14], [-50.0, 100.0, -25.0, 0.0])  # on past the last one
    np.testing.assert_allclose(np.linalg.norm(states[:, 2:], axis=1), 25.0)


def test_targets_are_present_only_in_their_window() -> None:
    late = spec(first_slot=5, last_slot=12)
    paths = target_paths([spec(), late], 1.0, 0.5, 20, np.zeros((2, 20, 4)))
    assert paths.present[:, 0].all()
    assert paths.present[:, 1].tolist() == [5 <= n <= 12 for n in range(21)]
    assert np.isnan(paths.states[4, 1]).all() and np.isnan(paths.states[13, 1]).all()
    np.testing.assert_allclose(paths.states[5, 1], late.x0)
    states, idx = paths.at(3)
    assert idx.tolist() == [0] and states.shape == (1, 4)


def test_the_process_noise_has_the_models_covariance(rng: np.random.Generator) -> None:
    runs, kappa = 4000, 0.5
    normals = rng.standard_normal((runs, 1, 4))
    F = coordinated_turn_matrix(1.0, 0.1)
    t = spec(motion="coordinated_turn", turn_rate_radps=0.1, last_slot=1)
    steps = np.array(
        [target_paths([t], 1.0, kappa, 1, normals[r][None]).states[1, 0] for r in range(runs)]
    )
    w = steps - F @ np.asarray(t.x0)
    W = process_noise(1.0, kappa)
    # each entry of the sample covariance within 5 standard errors of W's
    se = np.sqrt((W**2 + np.outer(np.diag(W), np.diag(W))) / runs)
    assert np.all(np.abs(np.cov(w.T) - W) < 5 * se + 1e-12)


SENSING = SensingParams(radar_gain=5e6, alpha_d=1e3, alpha_v=1e-2, B=20e6, Ts=0.01)


def detection(**changes: object) -> DetectionSpec:
    base = DetectionSpec("fixed", 0.9, 0.0, 2.0, (0.0, 4000.0), (-60.0, 60.0))
    return replace(base, **changes)  # type: ignore[arg-type]


def draws(rng: np.random.Generator, M: int, T: int, rate: float) -> SlotDraws:
    return SlotDraws(
        normals=rng.standard_normal((M, T, 2)),
        detect=rng.uniform(size=(M, T)),
        target_keys=rng.uniform(size=(M, T)),
        clutter=tuple(rng.uniform(size=(int(c), 3)) for c in rng.poisson(rate, size=M)),
    )


def test_unlabelled_detections_have_the_models_statistics(rng: np.random.Generator) -> None:
    targets = np.array([[1000.0, 1000.0, 20.0, 5.0], [1600.0, 900.0, -10.0, 10.0]])
    gains = np.array([5e6, 1e7])
    uav = np.array([[400.0, 1200.0], [2000.0, 2000.0]])
    eta = np.array([0.4, 0.6])
    det = detection()
    runs = 3000
    detected = np.zeros((2, 2))
    errors: list[list[list[np.ndarray]]] = [[[], []], [[], []]]
    clutter_counts, clutter_points, first_is_clutter = [], [], 0
    for _ in range(runs):
        reports = unlabelled_detections(
            targets, gains, uav, eta, SENSING, det, draws(rng, 2, 2, 2.0)
        )
        for m, rep in enumerate(reports):
            assert rep.measurements.shape == (len(rep.origin), 2)
            for t in range(2):
                rows = rep.measurements[rep.origin == t]
                assert len(rows) <= 1
                if len(rows):
                    detected[m, t] += 1
                    clean = measure(targets[t], uav[m : m + 1])
                    errors[m][t].append(rows[0] - clean)
            c = rep.measurements[rep.origin == CLUTTER]
            clutter_counts.append(len(c))
            clutter_points.append(c)
            if len(rep.origin) > 1 and rep.origin[0] == CLUTTER:
                first_is_clutter += 1
    # detection rate: binomial, 5 sigma
    sigma = math.sqrt(0.9 * 0.1 / runs)
    assert np.all(np.abs(detected / runs - 0.9) < 5 * sigma)
    # measurement noise: eq. 8's variances at each target's gain, by a chi-square bound per entry
    for m in range(2):
        for t in range(2):
            e = np.asarray(errors[m][t])
            clean = measure(targets[t], uav[m : m + 1])
            var = replace(SENSING, radar_gain=float(gains[t])).variances(clean[:1], eta[m : m + 1])
            for k in range(2):
                ratio = float(np.mean(e[:, k] ** 2) / var[k])
                assert abs(ratio - 1) < 5 * math.sqrt(2 / len(e)), (m, t, k, ratio)
    # false alarms: Poisson mean 2 (5 standard errors), uniform in the window (KS)
    counts = np.asarray(clutter_counts)
    assert abs(counts.mean() - 2.0) < 5 * math.sqrt(2.0 / len(counts))
    pts = np.vstack(clutter_points)
    assert stats.kstest(pts[:, 0], "uniform", args=(0.0, 4000.0)).pvalue > 1e-4
    assert stats.kstest(pts[:, 1], "uniform", args=(-60.0, 120.0)).pvalue > 1e-4
    # the order carries no label: clutter comes first about as often as its share
    assert 0.2 < first_is_clutter / (2 * runs) < 0.8


def test_a_uav_without_a_share_senses_nothing(rng: np.random.Generator) -> None:
    targets = np.array([[1000.0, 1000.0, 20.0, 5.0], [np.nan] * 4])
    reports = unlabelled_detections(
        targets,
        np.array([5e6, 5e6]),
        np.array([[400.0, 1200.0], [900.0, 900.0]]),
        np.array([0.0, 1.0]),
        SENSING,
        detection(detection_prob=1.0),
        draws(rng, 2, 2, 5.0),
    )
    assert len(reports[0].origin) == 0
    assert (reports[1].origin != 1).all()  # the absent target is never detected
    assert (reports[1].origin == 0).sum() == 1


def test_the_snr_model_is_a_rayleigh_echo_against_its_threshold(rng: np.random.Generator) -> None:
    det = detection(model="snr", snr_threshold=10**1.3)
    ranges = np.array([300.0, 800.0, 1500.0, 3000.0])
    pd = detection_probability(ranges, np.full(4, 5e6), det, SENSING.B, SENSING.Ts)
    mean_snr = 5e6 / ranges**4 * SENSING.B * SENSING.Ts
    fluctuation = rng.exponential(size=(200000, 1))  # |h|^2 of a Rayleigh echo, mean 1
    simulated = np.mean(mean_snr[None] * fluctuation > det.snr_threshold, axis=0)
    np.testing.assert_allclose(pd, simulated, atol=5 * math.sqrt(0.25 / 200000))
    assert pd[0] > pd[-1]  # farther, fainter, less often seen


def test_multi_target_draws_leave_single_target_numbers_alone() -> None:
    s = load_scenario("paper")
    before = draw_run_noise(s, 7)
    noise = draw_multi_target_noise(load_scenario("multi-target"), 7)
    after = draw_run_noise(s, 7)
    np.testing.assert_array_equal(before.process, after.process)
    np.testing.assert_array_equal(before.measurement, after.measurement)
    assert noise.target_normals.shape == (3, 60, 4) and len(noise.slots) == 60
    counts = [len(c) for slot in noise.slots for c in slot.clutter]
    assert abs(np.mean(counts) - 2.0) < 5 * math.sqrt(2.0 / len(counts))
