"""The operator's priorities live (service/ground/mission.py `MissionState.set_priority`, the
scenario's script): applied from the next planned slot, refused by name when wrong, traced
(each track's `priority`: its plan's; the line's `priorities`: the table as of the slot's
processing, the script's later changes still to come), continued by a resume from any slot line
(`serve --resume`: records/tracks.py `resume_point`, `MissionState.resumed`), and replayed: a
live trace with a changed priority replays to its own plans (experiment/replay.py), which it
does not without the recorded priorities.

The mission: multi-target.yaml with two known targets (tracks 1 and 2 from slot 1), one report
lost each slot; the operator sets track 2 to 4 after slot SET_AFTER, and the scenario's script
sets track 1 to 3 from slot SCRIPTED on.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from isac_mission.config import Scenario, parse_scenario
from isac_mission.experiment.replay import replay_trace
from isac_mission.model.run_noise import draw_multi_target_noise
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.tracks import multi_target_kit
from isac_mission.records import TraceWriter, read_trace
from isac_mission.records.jsonlines import loads_line
from isac_mission.records.tracks import TracksSlot, resume_fields, resume_point, slot_line
from isac_mission.service.ground.mission import MissionState
from isac_mission.service.ground.report import GroundReport
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.service.ground.tracefile import (
    RecordOutput,
    TrackSetOutput,
    live_trace_config,
    slot_record,
    track_set_slot,
)
from isac_mission.tracking.factory import restored_tracker
from isac_mission.tracking.priorities import Priorities
from isac_mission.types import FloatArray, SlotPlan
from isac_mission.wire import DetectionSetMsg, TruthSetMsg
from sim.multi_target_scene import MultiTargetScene
from tests.support.live_cli import ROOT

SLOTS = 8
SEED = 3
SET_AFTER = 3
SCRIPTED = 6
METHOD = "proposed"


@dataclass(frozen=True)
class Flown:
    """One slot of the uninterrupted mission: the plan's inputs and table, the line it wrote."""

    planned_for: int
    plan: SlotPlan
    start_xy: FloatArray
    velocity: FloatArray
    priorities: Priorities
    slot: TracksSlot
    line: str


@pytest.fixture(scope="module")
def scenario() -> Scenario:
    data = yaml.safe_load((ROOT / "config" / "multi-target.yaml").read_text())
    known, _, turning = data["targets"]
    data["targets"] = [known, turning | {"prior": "known"}]
    data["timing"]["duration_s"] = SLOTS
    data["priorities"] = [{"slot": SCRIPTED, "track": 1, "weight": 3.0}]
    return parse_scenario(data)


def _line(o: TracksSlot) -> str:
    return slot_line(o, {"latency_ms": 0.0, **resume_fields(o)})


@pytest.fixture(scope="module")
def kit(scenario: Scenario) -> SolverKit:
    return multi_target_kit(scenario)


@dataclass(frozen=True)
class Report:
    """A UAV's report as it arrived (service/ground/mission.py `ArrivedReport`)."""

    uav_xy_m: FloatArray
    bandwidth_share: float
    report: FloatArray


@pytest.fixture(scope="module")
def flown(scenario: Scenario, kit: SolverKit) -> list[Flown]:
    s = scenario
    scene = MultiTargetScene(s, SEED)
    errors = draw_multi_target_noise(s, SEED).initial_errors
    mission = MissionState(s, kit, METHOD, errors)
    uav_xy, velocity = s.uav_start_xy.copy(), np.zeros((s.M, 2))
    out = []
    for n in range(1, s.N + 1):
        job = mission.next_job(uav_xy, velocity)
        planned = job.run_tracks()
        mission.commit(job, planned)
        plan = planned.plan
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
            if m != n % s.M
        }
        origins = tuple(tuple(int(o) for o in r.origin) for r in reports)
        truth = TruthSetMsg(n, 0.0, scene.truth(n), origins)
        g = mission.process(n, msgs, truth, uav_xy)
        if n == SET_AFTER:
            mission.set_priority(2, 4.0)  # while slot n + 1 is not planned yet
        o = track_set_slot(g)
        out.append(Flown(planned.planned_for, plan, start_xy, start_v, job.priorities, o, _line(o)))
    return out


def test_the_changes_apply_from_the_next_planned_slot_and_are_traced(flown: list[Flown]) -> None:
    expected = {
        n: Priorities.of(({2: 4.0} if n > SET_AFTER else {}) | ({1: 3.0} if n >= SCRIPTED else {}))
        for n in range(1, SLOTS + 1)
    }
    for f in flown:
        n = f.slot.slot
        assert f.priorities == expected[n], f"slot {n}"
        line = loads_line(f.line)
        ids = {t["id"] for t in line["tracks"]}
        assert {1, 2} <= ids, f"slot {n}: a known target's track was lost"
        # Each track's priority: its plan's; the line's `priorities`: what the mission went on
        # with when the slot was processed (the operator's change, made after slot SET_AFTER was
        # processed, is in the next line).
        assert {t["id"]: t.get("priority", 1.0) for t in line["tracks"]} == {
            i: expected[n][i] for i in ids
        }
        assert line.get("priorities", []) == expected[n].to_json(), f"slot {n}"
    # Not vacuous: the plans changed where the priorities did.
    assert flown[SET_AFTER].priorities != flown[SET_AFTER - 1].priorities


def test_set_priority_refuses_by_name_and_changes_nothing(
    scenario: Scenario, kit: SolverKit
) -> None:
    s = scenario
    mission = MissionState(s, kit, METHOD)
    with pytest.raises(ValueError, match=r"^no track 1: the tracker has never had it"):
        mission.set_priority(1, 2.0)  # nothing predicted yet: no track at all
    mission.predict()
    assert mission.track_ids_had() == {1, 2}
    for track, weight, message in [
        (7, 2.0, r"^no track 7: the tracker has never had it \(its tracks: 1, 2\)$"),
        (1, 12.0, r"^priority 12 for track 1: a priority is in \[0, 10\]$"),
        (1, -1.0, r"^priority -1 for track 1: a priority is in \[0, 10\]$"),
        (2, math.nan, r"^priority nan for track 2: a priority is a finite number"),
        (2, math.inf, r"^priority inf for track 2: a priority is a finite number"),
        (0, 1.0, r"^track 0: a track ID is >= 1$"),
    ]:
        with pytest.raises(ValueError, match=message):
            mission.set_priority(track, weight)
    assert mission.priorities == Priorities()
    assert mission.next_planned_slot == 1
    job = mission.next_job(s.uav_start_xy)
    assert mission.next_planned_slot == 2  # slot 1's job is made: a change now goes into 2's
    mission.set_priority(2, 0.0)
    assert job.priorities == Priorities()  # a job made before keeps its table
    assert mission.next_job(s.uav_start_xy).priorities == Priorities.of({2: 0.0})


@pytest.mark.parametrize("k", range(1, SLOTS))
def test_a_resume_from_slot_k_plans_the_next_slot_as_the_uninterrupted_mission(
    scenario: Scenario, kit: SolverKit, flown: list[Flown], k: int
) -> None:
    s = scenario
    point = resume_point(loads_line(flown[k - 1].line))
    mission = MissionState.resumed(
        s,
        kit,
        METHOD,
        restored_tracker(s, point.tracker),
        point.slot,
        point.plan_eta,
        point.assoc,
        draw_multi_target_noise(s, SEED).initial_errors,
        point.priorities,
    )
    nxt = flown[k]
    job = mission.next_job(nxt.start_xy, nxt.velocity)
    if k == SET_AFTER:
        # The operator's change came after slot k was processed: line k + 1 has it, line k not
        # (a line holds the table as of its slot's processing), so a resume from line k plans
        # without it, as a mission killed before line k + 1 was written must.
        assert job.priorities == Priorities() != nxt.priorities
        return
    assert job.priorities == nxt.priorities, f"resumed after slot {k}"
    planned = job.run_tracks()
    assert planned.planned_for == nxt.planned_for
    np.testing.assert_allclose(planned.plan.uav_xy_m, nxt.plan.uav_xy_m, atol=1e-6)
    np.testing.assert_allclose(planned.plan.bandwidth_share, nxt.plan.bandwidth_share, atol=1e-9)


def _write(path: Path, s: Scenario, lines: list[str]) -> None:
    with TraceWriter(path, live_trace_config(s, METHOD, {})):
        pass
    with path.open("a") as f:
        for line in lines:
            f.write(line + "\n")


def test_a_live_trace_with_a_changed_priority_replays_to_its_plans(
    scenario: Scenario, flown: list[Flown], tmp_path: Path
) -> None:
    s = scenario
    path = tmp_path / "trace_proposed.jsonl"
    _write(path, s, [f.line for f in flown])
    trace = read_trace(path)
    assert trace.config.get("priorities") == [{"slot": SCRIPTED, "track": 1, "weight": 3.0}]
    rows = replay_trace(trace, s)
    assert [r.slot for r in rows] == list(range(2, SLOTS + 1))
    for r in rows:
        np.testing.assert_allclose(r.replay_gap_m, 0.0, atol=1e-6, err_msg=f"slot {r.slot}")
        assert r.replay_fallback == r.fallback
    # Without the recorded priorities (the script alone), the plans after the operator's change
    # are not reproduced.
    stripped = tmp_path / "without.jsonl"
    lines = []
    for f in flown:
        obj: dict[str, Any] = json.loads(f.line)
        obj.pop("priorities", None)
        for t in obj["tracks"]:
            if t["id"] == 2:
                t.pop("priority", None)
        lines.append(json.dumps(obj))
    _write(stripped, s, lines)
    rows = replay_trace(read_trace(stripped), s)
    gaps = {r.slot: float(np.max(r.replay_gap_m)) for r in rows}
    assert all(gaps[n] < 1e-6 for n in range(2, SET_AFTER + 1)), gaps
    assert max(gaps[n] for n in range(SET_AFTER + 1, SLOTS + 1)) > 1e-3, gaps


def test_the_track_set_message_carries_the_priorities(
    scenario: Scenario, kit: SolverKit, tmp_path: Path
) -> None:
    """What the console sees: each track's priority as the mission goes on with it."""
    s = scenario
    mission = MissionState(s, kit, METHOD)
    mission.predict()
    mission.set_priority(2, 4.0)
    job = mission.next_job(s.uav_start_xy)
    mission.commit(job, job.run_tracks())
    g = mission.process(1, {}, None, s.uav_start_xy)
    output = TrackSetOutput(s, GroundSettings(trace_path=tmp_path / "t.jsonl"), None)
    msg = output.track_message(g, 1.0)
    assert {t.track_id: t.priority for t in msg.tracks} == {1: 1.0, 2: 4.0}


def test_a_labelled_trace_resumes_with_its_priorities(paper: Scenario, tmp_path: Path) -> None:
    """The labelled target's live line carries `priorities` and its track's `priority`; a
    resume reads them back (tracefile.RecordOutput.open), and priority 0 holds the fleet."""
    s = paper.with_changes(N=4)
    mission = MissionState(s, SolverKit(s), METHOD)
    mission.predict()
    assert mission.track_ids_had() == {1}
    with pytest.raises(ValueError, match=r"^no track 2"):
        mission.set_priority(2, 1.0)
    mission.set_priority(1, 0.0)
    job = mission.next_job(s.uav_start_xy)
    planned = job.run_tracks()
    assert planned.planned_for == 0 and planned.slot_input is None  # the fleet holds
    mission.commit(job, planned)
    msgs = {m: Report(s.uav_start_xy[m], 1.0 / s.M, np.zeros((0, 2))) for m in range(s.M)}
    g = mission.process(1, msgs, None, s.uav_start_xy)
    record = slot_record(g, {})
    assert record.extra["priorities"] == [{"id": 1, "priority": 0.0}]
    assert record.extra["tracks"][0]["priority"] == 0.0
    path = tmp_path / "trace_proposed.jsonl"
    with TraceWriter(path, live_trace_config(s, METHOD, {})) as writer:
        writer.write_slot(record)
    output = RecordOutput(s, GroundSettings(trace_path=path, resume=True), GroundReport(), None)
    resume = output.open()
    assert resume is not None and resume.slot == 1
    assert resume.priorities == Priorities.of({1: 0.0})
