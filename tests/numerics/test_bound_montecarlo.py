"""The PCRB against Monte Carlo: the EKF's mean squared error approaches tr(PCRB) where it is tight.

The bound is a lower bound on the MSE of any estimator; with metre-level noise and a Gaussian
prior the EKF is nearly efficient, so MSE / tr(PCRB) must sit near 1. Both directions are tested:
a bound that is too loose (ratio > 1.5) fails as surely as a filter that is too poor.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from isac_mission.config import Scenario
from isac_mission.experiment.closed_loop import draw_run_noise, run_closed_loop
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.model.radar import measure
from isac_mission.planning.kit import SolverKit
from isac_mission.tracking.ekf import ekf_predict, ekf_update
from isac_mission.tracking.pcrb import Bound, SensingParams, bound_step
from isac_mission.types import Gaussian


def test_static_geometry_mse_matches_bound_within_chi_square(paper: Scenario) -> None:
    """Fixed UAVs, 400 independent missions of 8 slots: per-component squared errors are
    chi-square distributed around the bound if the EKF attains it."""
    s = paper
    F, W = transition_matrix(s.dt), process_noise(s.dt, s.kappa)
    sens = SensingParams.from_scenario(s)
    eta = np.full(s.M, 1.0 / s.M)
    rng = np.random.default_rng(2024)
    runs, slots = 400, 8
    sq_err = np.zeros((runs, 4))
    for r in range(runs):
        x = s.x0.copy()
        belief = Gaussian(s.x0 + rng.multivariate_normal(np.zeros(4), s.P0), s.P0)
        bound = Bound.from_covariance(s.P0)
        for _ in range(slots):
            x = F @ x + rng.multivariate_normal(np.zeros(4), W)
            pred = ekf_predict(belief, F, W)
            r_diag = sens.variances(np.linalg.norm(pred.x[:2] - s.uav_start_xy, axis=1), eta)
            true_var = sens.variances(np.linalg.norm(x[:2] - s.uav_start_xy, axis=1), eta)
            z = measure(x, s.uav_start_xy) + rng.standard_normal(2 * s.M) * np.sqrt(true_var)
            belief = ekf_update(pred, z, s.uav_start_xy, r_diag)
            bound = bound_step(bound, F, W, pred.x, s.uav_start_xy, r_diag)
        sq_err[r] = (belief.x - x) ** 2
        if r == 0:
            C_ref = np.diag(bound.C)
    ratio = sq_err.mean(axis=0) / C_ref
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], runs) / runs
    assert np.all(ratio > lo), ratio
    assert np.all(ratio < hi), ratio


def test_closed_loop_efficiency_on_paper_scenario(paper: Scenario, full_size: bool) -> None:
    """Location MSE over tr(PCRB)'s position part, slots 2..N, all runs, between 0.8 and 1.5."""
    runs = 40 if full_size else 12
    kit = SolverKit(paper)
    results = [
        run_closed_loop(paper, "proposed", draw_run_noise(paper, 5000 + r), kit)
        for r in range(runs)
    ]
    err = np.array([r.est - r.true for r in results])
    C = np.array([r.pcrb for r in results])
    mse = np.sum(err[:, 1:, :2] ** 2, axis=-1).mean()
    bound = np.trace(C[:, 1:, :2, :2], axis1=-2, axis2=-1).mean()
    ratio = mse / bound
    assert 0.8 <= ratio <= 1.5, f"MSE / tr(PCRB_pos) = {ratio:.3f} over {runs} runs"


@pytest.mark.parametrize("case", range(3))
def test_bound_recursion_equals_information_filter_for_linear_case(case: int) -> None:
    """Fixed H: the recursion must equal the Kalman information filter, computed here directly."""
    rng = np.random.default_rng(case)
    F, W = transition_matrix(1.0), process_noise(1.0, 0.3)
    x = np.array([100.0, 200.0, 5.0, -3.0])
    uav = rng.uniform(-500, 500, (3, 2))
    r_diag = rng.uniform(0.5, 5.0, 6)
    P0 = np.diag(rng.uniform(1, 50, 4))
    b = bound_step(Bound.from_covariance(P0), F, W, x, uav, r_diag)
    from isac_mission.model.radar import measurement_jacobian

    H = measurement_jacobian(x, uav)
    expected = np.linalg.inv(F @ P0 @ F.T + W) + H.T @ np.diag(1 / r_diag) @ H
    np.testing.assert_allclose(b.J, expected, rtol=1e-10)
    np.testing.assert_allclose(b.C @ b.J, np.eye(4), atol=1e-9)
