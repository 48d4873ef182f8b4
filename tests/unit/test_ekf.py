"""The EKF against the batch Kalman formulas written out here."""

from __future__ import annotations

import numpy as np

from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.model.radar import measure, measurement_jacobian
from isac_mission.tracking.ekf import TargetTracker, ekf_predict, ekf_update
from isac_mission.types import Gaussian


def _case(seed: int) -> tuple[Gaussian, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = np.array([800.0, 1500.0, 25.0, -4.0])
    A = rng.normal(size=(4, 4))
    P = A @ A.T + np.diag([50.0, 50.0, 2.0, 2.0])
    uav = x[:2] + rng.uniform(-700, 700, (3, 2))
    r = rng.uniform(0.5, 9.0, 6)
    z = measure(x, uav) + rng.normal(size=6) * np.sqrt(r)
    return Gaussian(x + rng.normal(size=4), P), uav, r, z


def test_predict_is_f_p_ft_plus_w() -> None:
    g, *_ = _case(0)
    F, W = transition_matrix(2.0), process_noise(2.0, 0.7)
    out = ekf_predict(g, F, W)
    np.testing.assert_allclose(out.x, F @ g.x)
    np.testing.assert_allclose(out.P, F @ g.P @ F.T + W)


def test_sequential_update_equals_batch_ekf() -> None:
    for seed in range(4):
        g, uav, r, z = _case(seed)
        H = measurement_jacobian(g.x, uav)
        S = H @ g.P @ H.T + np.diag(r)
        K = g.P @ H.T @ np.linalg.inv(S)
        x_ref = g.x + K @ (z - measure(g.x, uav))
        P_ref = (np.eye(4) - K @ H) @ g.P
        out = ekf_update(g, z, uav, r)
        np.testing.assert_allclose(out.x, x_ref, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(out.P, P_ref, rtol=1e-8, atol=1e-9)


def test_missing_measurements_give_the_partial_update() -> None:
    g, uav, r, z = _case(5)
    z_missing = z.copy()
    z_missing[[1, 4]] = np.nan
    keep = [0, 2, 3, 5]
    H = measurement_jacobian(g.x, uav)[keep]
    K = g.P @ H.T @ np.linalg.inv(H @ g.P @ H.T + np.diag(r[keep]))
    x_ref = g.x + K @ (z[keep] - measure(g.x, uav)[keep])
    np.testing.assert_allclose(ekf_update(g, z_missing, uav, r).x, x_ref, rtol=1e-9)


def test_no_measurement_leaves_belief_unchanged_and_p_stays_symmetric() -> None:
    g, uav, r, z = _case(6)
    out = ekf_update(g, np.full(6, np.nan), uav, r)
    np.testing.assert_allclose(out.x, g.x)
    np.testing.assert_allclose(out.P, g.P)
    tracker = TargetTracker(g, transition_matrix(1.0), process_noise(1.0, 0.5))
    for _ in range(5):
        tracker.predict()
        b = tracker.update(z, uav, r)
        np.testing.assert_array_equal(b.P, b.P.T)
        assert np.all(np.linalg.eigvalsh(b.P) > 0)


def test_iterated_update_removes_the_linearisation_error_when_noise_is_tiny() -> None:
    """Sub-millimetre noise and a 10 m prior error (the literal eq. 8 regime): the plain EKF's
    update is off by the linearisation error, the iterated one converges to the truth."""
    x = np.array([800.0, 1500.0, 25.0, -4.0])
    uav = x[:2] + np.array([[300.0, 40.0], [-120.0, 260.0], [90.0, -310.0]])
    r = np.full(6, 1e-8)
    z = measure(x, uav)
    prior = Gaussian(x + np.array([8.0, -6.0, 1.0, 0.5]), np.diag([100.0, 100.0, 4.0, 4.0]))
    plain = ekf_update(prior, z, uav, r)
    iterated = ekf_update(prior, z, uav, r, iterations=10)
    plain_err = np.linalg.norm(plain.x[:2] - x[:2])
    iter_err = np.linalg.norm(iterated.x[:2] - x[:2])
    assert plain_err > 0.05
    assert iter_err < 1e-3
