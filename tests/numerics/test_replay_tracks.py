"""`isac-mission replay` on a trace of several tracks (experiment/replay.py): a live trace, written
by the ground loop's mission state and output (service/ground/mission.py, tracefile.py) from the
simulated world's reports with a report lost every slot, replays to itself slot by slot: the
tracker restored from each previous line predicts the tracks the loop planned for, and the same
planner on the same inputs makes the same plan. A line without what the tracker carries (an
offline trace's) has nothing to replay from."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.console.replay import load_replay
from isac_mission.experiment.replay import replay_trace
from isac_mission.model.run_noise import draw_multi_target_noise
from isac_mission.planning.tracks import multi_target_kit
from isac_mission.records import TraceWriter, read_trace
from isac_mission.records.tracks import resume_fields
from isac_mission.service.ground.mission import MissionState
from isac_mission.service.ground.tracefile import live_trace_config, track_set_slot
from isac_mission.wire import DetectionSetMsg, TruthSetMsg
from sim.multi_target_scene import MultiTargetScene
from tests.support.ground_steps import plan_slot_of

SEED = 5
SLOTS = 8
METHOD = "proposed"


@pytest.fixture(scope="module")
def scenario() -> Scenario:
    return load_scenario("multi-target").with_changes(N=SLOTS)


@pytest.fixture(scope="module")
def live_trace(scenario: Scenario, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The mission state flown over the world's reports (one lost each slot), traced as the
    ground loop traces it: the slot's line with what a restart needs."""
    s = scenario
    path = tmp_path_factory.mktemp("replay-tracks") / "trace_proposed.jsonl"
    scene = MultiTargetScene(s, SEED)
    errors = draw_multi_target_noise(s, SEED).initial_errors
    mission = MissionState(s, multi_target_kit(s), METHOD, errors)
    uav_xy, velocity = s.uav_start_xy.copy(), np.zeros((s.M, 2))
    with TraceWriter(path, live_trace_config(s, METHOD, {})) as writer:
        for n in range(1, s.N + 1):
            _, plan = plan_slot_of(mission, uav_xy, velocity)
            if plan.uav_velocity_mps is not None:
                velocity = plan.uav_velocity_mps
            else:
                velocity = (plan.uav_xy_m - uav_xy) / s.dt
            uav_xy = plan.uav_xy_m
            reports = scene.reports(n, uav_xy, plan.bandwidth_share)
            msgs = {
                m: DetectionSetMsg(n, 0.0, m, r.measurements, uav_xy[m], plan.bandwidth_share[m])
                for m, r in enumerate(reports)
                if m != n % s.M
            }
            origins = tuple(tuple(int(o) for o in r.origin) for r in reports)
            truth = TruthSetMsg(n, 0.0, scene.truth(n), origins)
            slot = track_set_slot(mission.process(n, msgs, truth, uav_xy))
            writer.write_slot(slot, {"latency_ms": 0.0, **resume_fields(slot)})
    return path


def test_a_live_trace_of_tracks_replays_to_itself(scenario: Scenario, live_trace: Path) -> None:
    trace = read_trace(live_trace)
    assert not trace.labelled and len(trace.lines) == SLOTS
    assert any(len(line.tracks) > 1 for line in trace.lines)  # several tracks to plan for
    rows = replay_trace(trace, scenario)
    # Slot 1's initial estimates are not traced: every later slot is replayed.
    assert [r.slot for r in rows] == list(range(2, SLOTS + 1))
    for r in rows:
        np.testing.assert_allclose(r.replay_gap_m, 0.0, atol=1e-6)  # the same plan
        np.testing.assert_array_equal(r.start_gap_m, 0.0)  # the loop started on its last plan
        assert r.replay_fallback == r.fallback


def test_a_trace_without_the_tracker_has_nothing_to_replay(
    scenario: Scenario, live_trace: Path, tmp_path: Path
) -> None:
    lines = live_trace.read_text().splitlines()
    stripped = [lines[0]]
    for text in lines[1:]:
        obj = json.loads(text)
        obj.pop("tracker", None)
        stripped.append(json.dumps(obj))
    path = tmp_path / "offline-like.jsonl"
    path.write_text("\n".join(stripped) + "\n")
    assert replay_trace(read_trace(path), scenario) == []


def test_view_draws_every_track_and_target_of_a_trace_of_tracks(live_trace: Path) -> None:
    trace = read_trace(live_trace)
    (run,) = load_replay([live_trace])["runs"]
    assert len(run["frames"]) == SLOTS
    for f, line in zip(run["frames"], trace.lines, strict=True):
        assert [t["id"] for t in f["tracks"]] == [t.track_id for t in line.tracks]
        assert sorted(t["index"] for t in f["truths"]) == sorted(line.truth)
        # The estimate drawn for the run is the track the plan followed.
        if line.planned_for:
            (lead,) = [t for t in line.tracks if t.track_id == line.planned_for]
            np.testing.assert_allclose(f["target_est"], lead.x)
            assert f["pcrb_pos"] == pytest.approx(lead.pcrb_position_trace)
