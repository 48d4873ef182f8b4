"""Attention for a newcomer (planning/tracks.py `newcomer_beliefs`; docs/model.md, "Planning
for several targets"): with `planner.newcomer_weight` w > 0 (1 by default) a tentative track is a target
of the objective, weighed w x its existence (its hits over the hits that confirm it) x its
priority; with w = 0 it is only kept clear of, as before the key existed.

- the tracker's existence of a tentative track is its hits over confirm_hits (a confirmed
  track's 1), from a tracker restored with hand-made hits;
- the planner's input: the tentative track among the targets with exactly that weight, still a
  keep-out point; none at w = 0 or at priority 0;
- the plan's objective is the weighted sum of the confirmed and the tentative track's bounds,
  each computed here from the plan's positions and shares alone.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.model.radar import SensingParams
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import SlotInput
from isac_mission.planning.tracks import TracksPlan, multi_target_kit, plan_tracks
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.multi_target import (
    MultiTargetTracker,
    SavedTrack,
    TrackerSettings,
    TrackerState,
)
from isac_mission.tracking.priorities import Priorities
from isac_mission.tracking.tracker import TrackPrediction
from isac_mission.types import FloatArray, Gaussian, SlotPlan, SolveReport
from tests.support.independent.pcrb import posterior_trace

P_PRED = np.diag([25.0, 25.0, 1.0, 1.0])
"""The confirmed track's predicted covariance (m^2, m^2/s^2)."""
P_NEW = np.diag([400.0, 400.0, 25.0, 25.0])
"""The tentative track's: a newcomer, placed coarsely."""


@pytest.fixture(scope="module")
def multi() -> Scenario:
    return load_scenario("multi-target")


@pytest.fixture(scope="module")
def kit(multi: Scenario) -> SolverKit:
    return multi_target_kit(multi)


def _with_weight(s: Scenario, w: float) -> Scenario:
    return s.with_changes(planner=s.planner.model_copy(update={"newcomer_weight": w}))


def _predictions(existence: float) -> tuple[TrackPrediction, ...]:
    """Track 1 confirmed west of the fleet; track 5 tentative to the east, near UAV 2."""
    known = np.array([600.0, 1600.0, 30.0, 0.0])
    new = np.array([2300.0, 1500.0, -10.0, 15.0])
    return (
        TrackPrediction(1, True, Gaussian(known, P_PRED), np.linalg.inv(P_PRED)),
        TrackPrediction(5, False, Gaussian(new, P_NEW), np.linalg.inv(P_NEW), existence),
    )


def _plan(
    s: Scenario, kit: SolverKit, preds: tuple[TrackPrediction, ...], **kw: object
) -> TracksPlan:
    return plan_tracks(
        s,
        "proposed",
        kit,
        preds,
        s.uav_start_xy,
        np.full(s.M, 1.0 / s.M),
        None,
        np.zeros((s.M, 2)),
        None,
        **kw,  # type: ignore[arg-type]
    )


def _input(
    s: Scenario, kit: SolverKit, preds: tuple[TrackPrediction, ...], **kw: object
) -> SlotInput:
    seen: list[SlotInput] = []

    def capture(inp: SlotInput, _kit: SolverKit, _method: str) -> SlotPlan:
        seen.append(inp)
        n = len(inp.prev_xy_m)
        return SlotPlan(
            inp.prev_xy_m,
            np.zeros(n, dtype=np.int64),
            inp.prev_bandwidth_share,
            0.0,
            SolveReport("ok"),
        )

    _plan(s, kit, preds, planner=capture, **kw)
    (inp,) = seen
    return inp


def test_a_tentative_tracks_existence_is_its_hits_over_the_hits_that_confirm_it(
    multi: Scenario,
) -> None:
    settings = TrackerSettings.from_scenario(multi)
    assert settings.confirm_hits == 3
    belief = Gaussian(np.array([2300.0, 1500.0, -10.0, 15.0]), P_NEW)
    tracks = (
        SavedTrack(1, True, belief, np.linalg.inv(P_NEW), (True, True, True), 0),
        SavedTrack(2, False, belief, np.linalg.inv(P_NEW), (True,), 0),
        SavedTrack(3, False, belief, np.linalg.inv(P_NEW), (True, False, True), 0),
    )
    tracker = MultiTargetTracker.restored(settings, TrackerState(tracks, (), 4))
    existence = {p.track_id: p.existence for p in tracker.predict()}
    assert existence == {1: 1.0, 2: pytest.approx(1 / 3), 3: pytest.approx(2 / 3)}


def test_at_weight_0_a_tentative_track_is_only_kept_clear_of(
    multi: Scenario, kit: SolverKit
) -> None:
    assert multi.planner.newcomer_weight == 1.0
    off = _with_weight(multi, 0.0)
    assert "newcomer_weight" not in off.trace_config()["planner"]
    assert multi.trace_config()["planner"]["newcomer_weight"] == 1.0
    inp = _input(off, kit, _predictions(2 / 3))
    assert [b.track_id for b in inp.targets] == [1]
    assert inp.keep_out_xy_m is not None
    assert np.any(np.all(inp.keep_out_xy_m == [2300.0, 1500.0], axis=1))


@pytest.mark.parametrize(("w", "existence", "priority"), [(0.5, 2 / 3, 3.0), (1.0, 1 / 3, 1.0)])
def test_a_tentative_track_enters_the_objective_weighed_w_times_existence_times_priority(
    multi: Scenario, kit: SolverKit, w: float, existence: float, priority: float
) -> None:
    s = _with_weight(multi, w)
    priorities = Priorities.of({5: priority})
    inp = _input(s, kit, _predictions(existence), priorities=priorities)
    assert [b.track_id for b in inp.targets] == [1, 5]
    assert inp.targets[0].weight == 1.0
    new = inp.targets[1]
    assert new.weight == pytest.approx(w * existence * priority, rel=1e-15)
    np.testing.assert_array_equal(new.state_pred, [2300.0, 1500.0, -10.0, 15.0])
    np.testing.assert_array_equal(new.cov_pred, P_NEW)
    assert inp.keep_out_xy_m is not None  # and it is still a keep-out point
    assert np.any(np.all(inp.keep_out_xy_m == [2300.0, 1500.0], axis=1))
    silenced = _input(s, kit, _predictions(existence), priorities=Priorities.of({5: 0.0}))
    assert [b.track_id for b in silenced.targets] == [1]


def _bound(b: TargetBelief, xy: FloatArray, eta: FloatArray, sensing: SensingParams) -> float:
    """One target's bound at the plan: eq. 8's variances at the plan's ranges and shares, the
    rest the independent checker's (`posterior_trace`)."""
    r = sensing.variances(np.linalg.norm(b.state_pred[None, :2] - xy, axis=1), eta)
    return posterior_trace(b.prior_information, b.state_pred, xy, r)


def test_the_plans_objective_is_the_weighted_sum_with_the_newcomer(
    multi: Scenario, kit: SolverKit
) -> None:
    s = _with_weight(multi, 1.0)
    planned = _plan(s, kit, _predictions(2 / 3))
    plan, inp = planned.plan, planned.slot_input
    assert inp is not None and plan.report.status == "ok"
    sensing = kit.sensing
    want = sum(
        b.weight * _bound(b, plan.uav_xy_m, plan.bandwidth_share, sensing) for b in inp.targets
    )
    assert plan.pcrb_trace == pytest.approx(want, rel=1e-9)
    alone = _plan(s, kit, _predictions(2 / 3), priorities=Priorities.of({5: 0.0})).plan
    newcomer_alone = replace(inp.targets[1], weight=1.0)
    # the fleet places the newcomer better when it counts
    assert _bound(newcomer_alone, plan.uav_xy_m, plan.bandwidth_share, sensing) < _bound(
        newcomer_alone, alone.uav_xy_m, alone.bandwidth_share, sensing
    )
