"""The one tracker interface (tracking/tracker.py) and the factory that picks a tracker and a
detection model from the scenario (tracking/factory.py)."""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.model.radar import SensingParams
from isac_mission.model.scene import LabelledScene, UnlabelledScene
from isac_mission.tracking.cycle import CycleModel, TrackState, predict, update
from isac_mission.tracking.factory import draw_noise, keep_out_tracks, scene_for, tracker_for
from isac_mission.tracking.multi_target import MultiTargetTracker, TrackerSettings
from isac_mission.tracking.pcrb import Bound
from isac_mission.tracking.tracker import (
    LABELLED_TRACK_ID,
    LabelledTracker,
    Tracker,
    labelled_measurements,
    labelled_reports,
)
from isac_mission.types import Gaussian


def test_labelled_reports_carry_every_measurement_and_every_miss() -> None:
    nan = np.nan
    z = np.array([100.0, nan, 300.0, nan, 1.5, 2.0, nan, nan])  # 4 UAVs: ranges, then velocities
    reports = labelled_reports(z)
    assert [len(r) for r in reports] == [1, 1, 1, 0]
    np.testing.assert_array_equal(labelled_measurements(reports), z)
    with pytest.raises(ValueError, match="UAV 1: 2 measurements"):
        labelled_measurements([np.zeros((0, 2)), np.ones((2, 2))])


def test_the_labelled_tracker_is_the_slot_recursion_number_for_number(paper: Scenario) -> None:
    """Driven by the same measurements, the tracker's track is tracking/cycle.py's state: the
    same floats, not close ones."""
    s = paper
    model = CycleModel.from_scenario(s)
    sensing = SensingParams.from_scenario(s)
    rng = np.random.default_rng(4)
    prior = Gaussian(s.x0 + rng.standard_normal(4), s.P0.copy())
    tracker = LabelledTracker.from_prior(model, prior)
    state = TrackState(prior, Bound.from_covariance(s.P0.copy()))
    uav_xy, eta = s.uav_start_xy.copy(), np.full(s.M, 1 / s.M)
    for n in range(6):
        (prediction,) = tracker.predict()
        want = predict(model, state)
        assert prediction.track_id == LABELLED_TRACK_ID and prediction.confirmed
        np.testing.assert_array_equal(prediction.prediction.x, want.prediction.x)
        np.testing.assert_array_equal(prediction.prior_information, want.prior)
        z = np.concatenate([rng.uniform(200, 900, s.M), rng.uniform(-20, 20, s.M)])
        if n == 3:
            z[[0, s.M]] = np.nan  # UAV 0 missed the target
        tracking = tracker.update(labelled_reports(z), uav_xy, eta, sensing)
        step = update(model, state, want, sensing, z, uav_xy, eta)
        state = step.state
        (track,) = tracking.tracks
        np.testing.assert_array_equal(track.belief.x, state.belief.x)
        np.testing.assert_array_equal(track.belief.P, state.belief.P)
        np.testing.assert_array_equal(track.bound.J, state.bound.J)
        assert track.variances is not None
        np.testing.assert_array_equal(track.variances, step.r_used)
        assert track.weight == (s.M - 1 if n == 3 else s.M)
        assert tracking.started == () and tracking.deleted == ()
    with pytest.raises(ValueError, match="one target"):
        tracker.add_confirmed(prior)


def test_both_trackers_follow_one_known_target_through_the_interface(paper: Scenario) -> None:
    """The several-target tracker with n = 1 (a known prior, every UAV's report its echo) follows
    the target as the labelled one does, through the same calls."""
    multi = load_scenario("multi-target")
    s = paper
    sensing = SensingParams.from_scenario(s)
    trackers: list[Tracker] = [
        LabelledTracker(CycleModel.from_scenario(s)),
        MultiTargetTracker(TrackerSettings.from_scenario(multi)),
    ]
    prior = Gaussian(s.x0.copy(), s.P0.copy())
    assert [t.add_confirmed(prior) for t in trackers] == [1, 1]
    x = s.x0.copy()
    uav_xy, eta = s.uav_start_xy.copy(), np.full(s.M, 1 / s.M)
    F = s.motion.transition(s.dt)
    for _ in range(5):
        x = F @ x
        d = np.linalg.norm(x[:2] - uav_xy, axis=1)
        v = ((x[:2] - uav_xy) @ x[2:]) / d
        reports = [np.array([[d[m], v[m]]]) for m in range(s.M)]
        for t in trackers:
            (pred,) = t.predict()
            assert pred.track_id == 1 and pred.confirmed
            (track,) = t.update(reports, uav_xy, eta, sensing).tracks
            assert np.linalg.norm(track.belief.x[:2] - x[:2]) < 1.0


def test_the_factory_picks_the_tracker_and_the_scene_from_the_scenario(paper: Scenario) -> None:
    multi = load_scenario("multi-target")
    assert isinstance(tracker_for(paper), LabelledTracker) and keep_out_tracks(paper) == 0
    assert isinstance(tracker_for(multi), MultiTargetTracker) and keep_out_tracks(multi) > 0
    assert isinstance(scene_for(paper, draw_noise(paper, 1)), LabelledScene)
    scene = scene_for(multi, draw_noise(multi, 1))
    assert isinstance(scene, UnlabelledScene)
    assert scene.truth(1).shape == (len(multi.targets), 4)
    with pytest.raises(ValueError, match="scripted truth"):
        scene_for(multi, draw_noise(multi, 1), truth=np.zeros((multi.N + 1, 4)))
