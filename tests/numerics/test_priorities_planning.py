"""The operator's priorities in the plans (planning/tracks.py `plan_tracks`; docs/model.md,
"Planning for several targets").

(a) With two targets, raising one track's priority lowers that track's share of the planned
    tr(PCRB), and the planner's objective for its plan is the weighted sum of the two bounds,
    each computed here from the plan's positions and shares alone (this file's own H and eq. 8's
    variances), with the weights n p_i / sum p computed here.
(b) Priority 0, exactly: the objective's value is bit for bit the one without that track (and
    does not move when the track does); the track stays among the targets with weight 0, so the
    exact check still keeps its clearance, and it is never the lead. Every confirmed track at 0:
    the fleet holds.
(c) Offline, a scripted change at slot k changes slot k's plan and not slot k-1's, and the trace
    records it; one track planned alone weighs 1 whatever its priority.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from isac_mission.config import Scenario, load_scenario, parse_scenario
from isac_mission.experiment.closed_loop import SlotOutcome
from isac_mission.experiment.runs import fly_outcomes, write_trace
from isac_mission.model.radar import SensingParams
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.problem import belief_clearance_m, build_slot_problem, targets_objective
from isac_mission.planning.slot import SlotInput
from isac_mission.planning.tracks import (
    ZERO_PRIORITY_HOLD,
    TracksPlan,
    multi_target_kit,
    plan_tracks,
)
from isac_mission.records import read_trace
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.priorities import Priorities, PriorityChange
from isac_mission.tracking.tracker import TrackPrediction
from isac_mission.types import FloatArray, SlotPlan, SolveReport
from tests.support.ground_steps import predictions_of
from tests.support.independent.pcrb import posterior_trace
from tests.support.live_cli import ROOT

P_PRED = np.diag([25.0, 25.0, 1.0, 1.0])
"""Both targets' predicted covariance (m^2, m^2/s^2)."""


@pytest.fixture(scope="module")
def multi() -> Scenario:
    return load_scenario("multi-target")


@pytest.fixture(scope="module")
def kit(multi: Scenario) -> SolverKit:
    return multi_target_kit(multi)


def _belief(s: Scenario, x: list[float], track_id: int) -> TargetBelief:
    return TargetBelief(
        np.array(x, dtype=float), np.linalg.inv(P_PRED), s.motion, P_PRED, track_id=track_id
    )


def _two_targets(s: Scenario) -> tuple[TrackPrediction, ...]:
    """Track 1, the paper's target west of the fleet's centre; track 2 east, nearer to the fleet
    (UAV 2 starts at (2193, 1100): ~500 m)."""
    return predictions_of(
        (_belief(s, [600.0, 1600.0, 30.0, 0.0], 1), _belief(s, [2150.0, 1600.0, 0.0, 20.0], 2))
    )


def _plan(
    s: Scenario,
    kit: SolverKit,
    predictions: tuple[TrackPrediction, ...],
    priorities: Priorities | None,
    planner: Any = None,
) -> TracksPlan:
    extra = {} if planner is None else {"planner": planner}
    return plan_tracks(
        s,
        "proposed",
        kit,
        predictions,
        s.uav_start_xy,
        np.full(s.M, 1.0 / s.M),
        None,
        np.zeros((s.M, 2)),
        None,
        priorities=priorities,
        **extra,
    )


def _bound(b: TargetBelief, xy: FloatArray, eta: FloatArray, sensing: SensingParams) -> float:
    """One target's bound at the plan: eq. 8's variances at the plan's ranges and shares, the
    rest the independent checker's (`posterior_trace`)."""
    r = sensing.variances(np.linalg.norm(b.state_pred[None, :2] - xy, axis=1), eta)
    return posterior_trace(b.prior_information, b.state_pred, xy, r)


class Capture:
    """A planner that records its input and holds (to look at what plan_tracks asks)."""

    def __init__(self) -> None:
        self.inputs: list[SlotInput] = []

    def __call__(self, inp: SlotInput, kit: SolverKit, method: str) -> SlotPlan:
        self.inputs.append(inp)
        n = len(inp.prev_xy_m)
        assoc = np.zeros(n, dtype=np.int64)
        return SlotPlan(inp.prev_xy_m, assoc, inp.prev_bandwidth_share, 0.0, SolveReport("ok"))


def _input(s: Scenario, kit: SolverKit, preds: Any, priorities: Priorities | None) -> SlotInput:
    capture = Capture()
    _plan(s, kit, preds, priorities, capture)
    (inp,) = capture.inputs
    return inp


# --------------------------------------------------------------------------------------------
# (a)


def test_raising_a_priority_lowers_that_tracks_share_and_the_objective_is_the_weighted_sum(
    multi: Scenario, kit: SolverKit
) -> None:
    s = multi
    preds = _two_targets(s)
    beliefs = {p.track_id: p.belief(s.motion) for p in preds}
    shares = {}
    for p2 in (1.0, 5.0):
        planned = _plan(s, kit, preds, Priorities.of({2: p2}))
        plan = planned.plan
        assert plan.report.status == "ok", plan.report.reason
        xy, eta = plan.uav_xy_m, plan.bandwidth_share
        tr = {i: _bound(b, xy, eta, kit.sensing) for i, b in beliefs.items()}
        w1, w2 = 2 * 1.0 / (1.0 + p2), 2 * p2 / (1.0 + p2)  # n p_i / sum p, here
        assert plan.pcrb_trace == pytest.approx(w1 * tr[1] + w2 * tr[2], rel=1e-9)
        shares[p2] = tr[2] / (tr[1] + tr[2])
        # The input carries those weights, lead first.
        assert planned.slot_input is not None
        got = {b.track_id: b.weight for b in planned.slot_input.targets}
        assert got == pytest.approx({1: w1, 2: w2}, rel=1e-15)
    assert shares[5.0] < shares[1.0] - 0.01, shares


def test_equal_priorities_whatever_their_value_are_the_plain_sum(
    multi: Scenario, kit: SolverKit
) -> None:
    """Every weight exactly 1 (the plans of before): the same input as with none set."""
    preds = _two_targets(multi)
    plain = _input(multi, kit, preds, None)
    assert [b.weight for b in plain.targets] == [1.0, 1.0]
    for table in (Priorities(), Priorities.of({1: 7.0, 2: 7.0})):
        inp = _input(multi, kit, preds, table)
        assert [(b.track_id, b.weight) for b in inp.targets] == [
            (b.track_id, b.weight) for b in plain.targets
        ]


# --------------------------------------------------------------------------------------------
# (b)


def test_priority_zero_the_objective_does_not_depend_on_the_track(
    multi: Scenario, kit: SolverKit
) -> None:
    s = multi
    preds = _two_targets(s)
    # Track 2 is nearer the fleet: the lead by default; at priority 0 never.
    assert _input(s, kit, preds, None).targets[0].track_id == 2
    inp = _input(s, kit, preds, Priorities.of({2: 0.0}))
    assert [(b.track_id, b.weight) for b in inp.targets] == [(1, 1.0), (2, 0.0)]
    alone = targets_objective(inp.targets[:1], kit.sensing)  # track 1's bound: the paper's
    with_zero = targets_objective(inp.targets, kit.sensing)
    moved = targets_objective(
        (inp.targets[0], replace(inp.targets[1], state_pred=np.array([100.0, 100.0, -5.0, 9.0]))),
        kit.sensing,
    )
    rng = np.random.default_rng(7)
    for _ in range(20):
        xy = s.uav_start_xy + rng.normal(0.0, 20.0, size=(s.M, 2))
        eta = rng.dirichlet(np.ones(s.M))
        value = alone.value(xy, eta)
        assert with_zero.value(xy, eta) == value  # bit for bit
        assert moved.value(xy, eta) == value

    planned = _plan(s, kit, preds, Priorities.of({2: 0.0}))
    plan = planned.plan
    assert planned.planned_for == 1 and plan.report.status == "ok", plan.report.reason
    b1 = preds[0].belief(s.motion)
    assert plan.pcrb_trace == pytest.approx(
        _bound(b1, plan.uav_xy_m, plan.bandwidth_share, kit.sensing), rel=1e-9
    )
    # Still kept clear of: the plan passes the exact check, which refuses a UAV inside track
    # 2's clearance at its predicted point.
    assert planned.slot_input is not None
    cons = build_slot_problem(planned.slot_input, kit).constraints
    assert cons.describe_violations(plan.uav_xy_m, plan.bandwidth_share) == []
    second = planned.slot_input.targets[1]
    clearance = belief_clearance_m(second, s)
    near = plan.uav_xy_m.copy()
    m = int(np.argmin(np.linalg.norm(near - second.state_pred[:2], axis=1)))
    near[m] = second.state_pred[:2] + np.array([0.0, 0.5 * clearance])
    assert any("14j" in v for v in cons.describe_violations(near, plan.bandwidth_share))


def test_every_confirmed_track_at_zero_holds(multi: Scenario, kit: SolverKit) -> None:
    s = multi
    capture = Capture()
    planned = _plan(s, kit, _two_targets(s), Priorities.of({1: 0.0, 2: 0.0}), capture)
    assert capture.inputs == []  # the planner is not asked
    assert planned.planned_for == 0 and planned.slot_input is None
    assert planned.plan.report.reason == ZERO_PRIORITY_HOLD
    assert planned.plan.report.fallback == "no track"
    np.testing.assert_array_equal(planned.plan.uav_xy_m, s.uav_start_xy)


# --------------------------------------------------------------------------------------------
# (c)

SLOTS = 4
CHANGE_AT = 3


def _two_known(duration_s: int, priorities: list[dict[str, Any]] | None) -> Scenario:
    """multi-target.yaml with the turning target's prior known (tracks 1 and 2 from slot 1) and
    without the one entering at 20 s."""
    data = yaml.safe_load((ROOT / "config" / "multi-target.yaml").read_text())
    known, _, turning = data["targets"]
    data["targets"] = [known, turning | {"prior": "known"}]
    data["timing"]["duration_s"] = duration_s
    if priorities is not None:
        data["priorities"] = priorities
    return parse_scenario(data)


def _plans(outcomes: tuple[SlotOutcome, ...]) -> list[FloatArray]:
    return [np.concatenate([o.plan.uav_xy_m.ravel(), o.plan.bandwidth_share]) for o in outcomes]


def _trace_lines(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_a_scripted_change_changes_its_slots_plan_and_not_the_one_before(tmp_path: Path) -> None:
    base = _two_known(SLOTS, None)
    script = [{"slot": CHANGE_AT, "track": 2, "weight": 5.0}]
    scripted = _two_known(SLOTS, script)
    assert scripted.priority_changes == (PriorityChange(CHANGE_AT, 2, 5.0),)
    kit = multi_target_kit(base)
    before = fly_outcomes(base, "proposed", 1, kit)
    after = fly_outcomes(scripted, "proposed", 1, kit)
    assert all(
        sorted(t.track_id for t in o.tracking.confirmed) == [1, 2] for o in before[:CHANGE_AT]
    )
    for n, (a, b) in enumerate(zip(_plans(before), _plans(after), strict=True), start=1):
        if n < CHANGE_AT:
            np.testing.assert_array_equal(b, a, err_msg=f"slot {n}")
        elif n == CHANGE_AT:
            assert np.max(np.abs(b - a)) > 1e-3, "the change did not change its slot's plan"
    k = CHANGE_AT - 1
    inp = after[k].slot_input
    assert inp is not None
    assert {t.track_id: t.weight for t in inp.targets} == pytest.approx({1: 1 / 3, 2: 5 / 3})
    # The trace records it: from line CHANGE_AT on, track 2's priority is 5.
    path = tmp_path / "proposed_run000.jsonl"
    config = scripted.trace_config() | {"seed": 1, "method": "proposed"}
    write_trace(path, config, after, scripted.priority_changes)
    lines = _trace_lines(path)
    assert lines[0]["config"]["priorities"] == script
    for line in lines[1:]:
        got = {t["id"]: t.get("priority") for t in line["tracks"]}
        assert got == ({1: None, 2: 5.0} if line["slot"] >= CHANGE_AT else {1: None, 2: None})
    trace = read_trace(path)
    assert [t.priority for t in trace.lines[CHANGE_AT - 1].tracks] == [1.0, 5.0]


def test_the_labelled_target_at_priority_zero_holds_and_alone_weighs_one(
    paper: Scenario, tmp_path: Path
) -> None:
    s = paper.with_changes(N=SLOTS)
    kit = SolverKit(s)
    before = fly_outcomes(s, "proposed", 1, kit)
    # A priority other than 0 changes nothing: one track planned for alone weighs 1.
    seven = fly_outcomes(
        replace(s, priority_changes=(PriorityChange(1, 1, 7.0),)), "proposed", 1, kit
    )
    for a, b in zip(_plans(before), _plans(seven), strict=True):
        np.testing.assert_array_equal(a, b)
    # Priority 0 from slot CHANGE_AT: that slot's fleet holds, the one before flies as before.
    zero = replace(s, priority_changes=(PriorityChange(CHANGE_AT, 1, 0.0),))
    after = fly_outcomes(zero, "proposed", 1, kit)
    for n, (a, b) in enumerate(zip(_plans(before), _plans(after), strict=True), start=1):
        if n < CHANGE_AT:
            np.testing.assert_array_equal(b, a, err_msg=f"slot {n}")
    held = after[CHANGE_AT - 1]
    assert held.planned_for == 0 and held.plan.report.reason == ZERO_PRIORITY_HOLD
    np.testing.assert_array_equal(held.plan.uav_xy_m, after[CHANGE_AT - 2].plan.uav_xy_m)
    # Still the labelled target's trace, with the priority on its track.
    path = tmp_path / "proposed_run000.jsonl"
    write_trace(path, zero.trace_config(), after, zero.priority_changes)
    trace = read_trace(path)
    assert trace.labelled and len(trace.slots) == SLOTS
    assert [line.tracks[0].priority for line in trace.lines] == [1.0, 1.0, 0.0, 0.0]
    assert trace.slots[CHANGE_AT - 1].plan_start_xy is None  # nothing was planned


def test_the_python_api_traces_a_scripted_priority() -> None:
    """`im.run_closed_loop` records the priorities each slot was planned with, as `simulate`."""
    import isac_mission as im
    from isac_mission.config import read_scenario_data

    data, _ = read_scenario_data("paper")
    data["timing"]["duration_s"] = 4
    data["priorities"] = [{"slot": 3, "track": 1, "weight": 0.0}]
    run = im.run_closed_loop(im.parse_scenario(data), 1, method="sd")
    recorded = [[t.get("priority", 1.0) for t in r.to_dict()["tracks"]] for r in run.trace.slots]
    assert recorded == [[1.0], [1.0], [0.0], [0.0]]
    assert [r.to_dict().get("fallback") for r in run.trace.slots][2:] == ["no track"] * 2
