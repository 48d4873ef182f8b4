"""A multi-target mission continued from a slot line of its live trace (`serve --resume`) goes on
exactly as the uninterrupted mission: the tracker restored from slot k's line
(records/tracks.py `resume_point`, tracking/multi_target.py `MultiTargetTracker.restored`),
fed slots k + 1 .. N's reports, gives the same tracks with the same IDs, confirmations, beliefs
and bounds to the last bit, and writes the same lines; the resumed mission's shares and BSs are
those the next plan starts from, so its next plan is the uninterrupted one's.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.errors import MessageError
from isac_mission.model.run_noise import draw_multi_target_noise
from isac_mission.planning.tracks import multi_target_kit
from isac_mission.records.jsonlines import loads_line
from isac_mission.records.tracks import (
    ResumePoint,
    TracksSlot,
    resume_fields,
    resume_point,
    slot_line,
)
from isac_mission.service.ground.mission import MissionState
from isac_mission.tracking.factory import restored_tracker
from isac_mission.tracking.multi_target import MultiTargetTracker, TrackerSettings
from isac_mission.tracking.tracker import TrackPrediction
from isac_mission.types import FloatArray, SlotPlan
from isac_mission.wire import DetectionSetMsg, TruthSetMsg
from sim.multi_target_scene import MultiTargetScene
from tests.support.ground_steps import commit_plan, plan_slot_of, processed
from tests.support.live_cli import ROOT

SLOTS = 24  # the entering target comes in at slot 20: candidates, tentative tracks, confirmations
SEED = 3
LOST = range(9, 12)
"""Slots whose reports are all lost: every track misses three slots in a row and is deleted, and
the targets are found again under new IDs."""
METHOD = "proposed"


@dataclass(frozen=True)
class Flown:
    """One slot of the uninterrupted mission: what went into it and the line it wrote."""

    predictions: tuple[TrackPrediction, ...]
    planned_for: int
    plan: SlotPlan
    start_xy: FloatArray
    velocity: FloatArray
    msgs: dict[int, DetectionSetMsg]
    truth: TruthSetMsg
    uav_xy: FloatArray
    slot: TracksSlot
    line: str


def _line(o: TracksSlot) -> str:
    """The live loop's line of a slot (without its latency)."""
    return slot_line(o, resume_fields(o))


@pytest.fixture(scope="module")
def scenario() -> Scenario:
    return load_scenario(ROOT / "config" / "multi-target.yaml").with_changes(N=SLOTS)


@pytest.fixture(scope="module")
def flown(scenario: Scenario) -> list[Flown]:
    """The live state's recursion over the whole mission, the world's reports taken at the
    plans' waypoints with the plans' shares (tests/numerics/test_multi_target_mission.py)."""
    s = scenario
    scene = MultiTargetScene(s, SEED)
    errors = draw_multi_target_noise(s, SEED).initial_errors
    mission = MissionState(s, multi_target_kit(s), METHOD, errors)
    uav_xy, velocity = s.uav_start_xy.copy(), np.zeros((s.M, 2))
    out = []
    for n in range(1, s.N + 1):
        predictions = mission.predict()
        planned_for, plan = plan_slot_of(mission, uav_xy, velocity)
        start_xy, start_v = uav_xy, velocity
        velocity = (
            plan.uav_velocity_mps
            if plan.uav_velocity_mps is not None
            else (plan.uav_xy_m - uav_xy) / s.dt
        )
        uav_xy = plan.uav_xy_m
        reports = scene.reports(n, uav_xy, plan.bandwidth_share)
        msgs = {
            m: DetectionSetMsg(n, 0.0, m, r.measurements, uav_xy[m], plan.bandwidth_share[m])
            for m, r in enumerate(reports)
            # One report lost every slot (a UAV that contributes nothing), all of them in LOST.
            if m != n % s.M and n not in LOST
        }
        origins = tuple(tuple(int(o) for o in r.origin) for r in reports)
        truth = TruthSetMsg(n, 0.0, scene.truth(n), origins)
        o = processed(mission, n, msgs, truth, uav_xy)
        out.append(
            Flown(
                predictions, planned_for, plan, start_xy, start_v, msgs, truth, uav_xy, o, _line(o)
            )
        )
    return out


def test_the_mission_exercises_what_a_resume_must_carry(flown: list[Flown]) -> None:
    """Not vacuous: candidates, tentative tracks, misses, deletions and new IDs happen."""
    saved = [f.slot.tracker_state for f in flown]
    assert all(st is not None for st in saved)
    assert any(st.candidates for st in saved if st is not None)
    assert any(not t.confirmed for st in saved if st is not None for t in st.tracks)
    assert any(t.misses_in_row for st in saved if st is not None for t in st.tracks)
    ids = [{t.track_id for t in f.slot.tracks} for f in flown]
    assert any(a - b for a, b in itertools.pairwise(ids)), "no track ever deleted"
    # After the deletions, new tracks get IDs above every earlier one.
    before, after = set().union(*ids[: LOST[-1]]), set().union(*ids[LOST[-1] :])
    assert after and min(after) > max(before), (before, after)


@pytest.mark.parametrize("k", range(1, SLOTS))
def test_a_tracker_restored_from_slot_k_goes_on_exactly(
    scenario: Scenario, flown: list[Flown], k: int
) -> None:
    s = scenario
    point = resume_point(loads_line(flown[k - 1].line))
    assert point.slot == k
    before = MultiTargetTracker.restored(TrackerSettings.from_scenario(s), point.tracker)
    _assert_same_state(before, flown[k - 1].slot)
    errors = draw_multi_target_noise(s, SEED).initial_errors
    mission = _resumed(s, point, errors)
    assert mission.slot == k and mission.last_plan is None and not mission.done
    np.testing.assert_array_equal(mission.eta, flown[k - 1].plan.bandwidth_share)
    np.testing.assert_array_equal(mission.assoc, flown[k - 1].plan.bs_of_uav)
    for f in flown[k:]:
        n = f.slot.slot
        predictions = mission.predict()
        assert [(p.track_id, p.confirmed) for p in predictions] == [
            (p.track_id, p.confirmed) for p in f.predictions
        ], f"slot {n}"
        for got, want in zip(predictions, f.predictions, strict=True):
            np.testing.assert_array_equal(got.prediction.x, want.prediction.x)
            np.testing.assert_array_equal(got.prediction.P, want.prediction.P)
            np.testing.assert_array_equal(got.prior_information, want.prior_information)
        commit_plan(mission, f.planned_for, f.plan, f.start_xy, f.velocity)
        o = processed(mission, n, f.msgs, f.truth, f.uav_xy)
        # The whole line: tracks (IDs, confirmed, x, P, bound, weight) and what the tracker
        # carries on (J, hits, misses, refutations, candidates, the next ID), bit for bit.
        assert _line(o) == f.line, f"resumed after slot {k}: slot {n} differs"


def _resumed(s: Scenario, point: ResumePoint, errors: FloatArray | None = None) -> MissionState:
    """The mission state a resume from `point` continues with."""
    tracker = restored_tracker(s, point.tracker)
    return MissionState.resumed(
        s, multi_target_kit(s), METHOD, tracker, point.slot, point.plan_eta, point.assoc, errors
    )


def _assert_same_state(tracker: MultiTargetTracker, o: TracksSlot) -> None:
    """The restored tracker's state is the saved one, array for array."""
    got, want = tracker.saved(), o.tracker_state
    assert want is not None
    assert got.next_id == want.next_id
    assert len(got.tracks) == len(want.tracks) and len(got.candidates) == len(want.candidates)
    for a, b in zip(got.tracks, want.tracks, strict=True):
        assert (a.track_id, a.confirmed, a.hits, a.misses_in_row) == (
            b.track_id,
            b.confirmed,
            b.hits,
            b.misses_in_row,
        )
        np.testing.assert_array_equal(a.belief.x, b.belief.x)
        np.testing.assert_array_equal(a.belief.P, b.belief.P)
        np.testing.assert_array_equal(a.information, b.information)
        assert (a.refuted is None) == (b.refuted is None)
    for c, d in zip(got.candidates, want.candidates, strict=True):
        np.testing.assert_array_equal(c.x, d.x)
        np.testing.assert_array_equal(c.P, d.P)


@pytest.mark.parametrize("k", [3, 12, 20])
def test_the_resumed_mission_plans_the_next_slot_as_the_uninterrupted_one(
    scenario: Scenario, flown: list[Flown], k: int
) -> None:
    """Its shares and BSs are the last plan's (`plan_eta`, `assoc`): the same inputs, the same
    plan (the per-slot methods do not read the previous plan; the receding horizon, which does,
    plans one target and is refused on this path)."""
    s = scenario
    point = resume_point(loads_line(flown[k - 1].line))
    mission = _resumed(s, point)
    nxt = flown[k]
    planned_for, plan = plan_slot_of(mission, nxt.start_xy, nxt.velocity, commit=False)
    assert planned_for == nxt.planned_for
    np.testing.assert_allclose(plan.uav_xy_m, nxt.plan.uav_xy_m, atol=1e-6)
    np.testing.assert_allclose(plan.bandwidth_share, nxt.plan.bandwidth_share, atol=1e-9)
    np.testing.assert_array_equal(plan.bs_of_uav, nxt.plan.bs_of_uav)


def test_a_line_without_the_resume_fields_names_what_is_missing(flown: list[Flown]) -> None:
    line = loads_line(flown[4].line)
    del line["tracker"]
    with pytest.raises(MessageError, match=r"slot 5's line has no `tracker`"):
        resume_point(line)
    del line["plan_eta"]
    with pytest.raises(MessageError, match=r"no `plan_eta` or `tracker`"):
        resume_point(line)


def test_restored_ids_must_be_below_the_next_id(scenario: Scenario, flown: list[Flown]) -> None:
    """IDs never repeat after a resume: a state whose next ID is not above its tracks' is
    refused."""
    st = flown[-1].slot.tracker_state
    assert st is not None and st.tracks
    settings = TrackerSettings.from_scenario(scenario)
    with pytest.raises(ValueError, match="next track ID"):
        MultiTargetTracker.restored(settings, replace(st, next_id=st.tracks[-1].track_id))
