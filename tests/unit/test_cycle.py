"""tracking/cycle.py: the one slot recursion is exactly the EKF and PCRB steps it chains."""

from __future__ import annotations

import numpy as np

from isac_mission.config import Scenario
from isac_mission.tracking.cycle import CycleModel, TrackState, predict, update
from isac_mission.tracking.ekf import ekf_predict, ekf_update
from isac_mission.tracking.pcrb import (
    Bound,
    SensingParams,
    bound_step,
    predict_information,
    scaled_inverse,
)
from isac_mission.types import Gaussian


def _start(s: Scenario) -> TrackState:
    return TrackState(Gaussian(s.x0.copy(), s.P0.copy()), Bound.from_covariance(s.P0.copy()))


def test_predict_gives_the_ekf_prediction_and_the_bound_prior(paper: Scenario) -> None:
    model = CycleModel.from_scenario(paper)
    state = _start(paper)
    got = predict(model, state)
    want = ekf_predict(state.belief, model.F, model.W)
    np.testing.assert_array_equal(got.prediction.x, want.x)
    np.testing.assert_array_equal(got.prediction.P, want.P)
    np.testing.assert_array_equal(got.prior, predict_information(state.bound, model.F, model.W))
    ekf_prior = predict(CycleModel.from_scenario(paper.with_changes(bound_prior="ekf")), state)
    np.testing.assert_array_equal(ekf_prior.prior, scaled_inverse(want.P))


def test_update_is_the_ekf_update_and_the_bound_step_with_the_predicted_variances(
    paper: Scenario,
) -> None:
    model = CycleModel.from_scenario(paper)
    sensing = SensingParams.from_scenario(paper)
    state = _start(paper)
    pred = predict(model, state)
    uav_xy = np.asarray(paper.uav_start_xy, dtype=float)
    eta = np.full(paper.M, 1.0 / paper.M)
    z = np.concatenate(
        [np.linalg.norm(paper.x0[None, :2] - uav_xy, axis=1) + 1.0, np.full(paper.M, 0.5)]
    )
    got = update(model, state, pred, sensing, z, uav_xy, eta)
    x_pred = pred.prediction.x
    r = sensing.variances(np.linalg.norm(x_pred[None, :2] - uav_xy, axis=1), eta)
    np.testing.assert_array_equal(got.r_used, r)
    belief = ekf_update(pred.prediction, z, uav_xy, r, model.ekf_iterations)
    bound = bound_step(state.bound, model.F, model.W, x_pred, uav_xy, r)
    np.testing.assert_array_equal(got.state.belief.x, belief.x)
    np.testing.assert_array_equal(got.state.belief.P, belief.P)
    np.testing.assert_array_equal(got.state.bound.J, bound.J)


def test_a_missing_or_unshared_measurement_gets_no_variance(paper: Scenario) -> None:
    """NaN in z (not arrived) and eta = 0 (no bandwidth: infinite variance) are both left out."""
    model = CycleModel.from_scenario(paper)
    sensing = SensingParams.from_scenario(paper)
    state = _start(paper)
    pred = predict(model, state)
    uav_xy = np.asarray(paper.uav_start_xy, dtype=float)
    m = paper.M
    z = np.concatenate([np.linalg.norm(paper.x0[None, :2] - uav_xy, axis=1), np.zeros(m)])
    z[0] = np.nan  # UAV 0's range did not arrive
    eta = np.full(m, 1.0 / (m - 1))
    eta[m - 1] = 0.0  # the last UAV has no bandwidth: no range information
    got = update(model, state, pred, sensing, z, uav_xy, eta)
    assert np.isnan(got.r_used[0]) and np.isnan(got.r_used[m - 1])
    assert np.all(np.isfinite(np.delete(got.r_used, [0, m - 1])))
    assert np.all(np.isfinite(got.state.belief.P)) and np.all(np.isfinite(got.state.bound.J))
