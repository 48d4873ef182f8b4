"""The exact check keeps 14j from every target of the slot, each moving along the legs by its
own motion model (planning/feasibility.py; docs/model.md, "Planning for several targets"), and
with one target it is the check it was."""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.problem import belief_clearance_m, build_slot_problem
from isac_mission.planning.slot import SlotInput, plan_slot
from isac_mission.tracking.beliefs import TargetBelief


def _with(s: Scenario, **planner: object) -> Scenario:
    return s.with_changes(planner=s.planner.model_copy(update=planner))


def _belief(s: Scenario, x: np.ndarray, track_id: int) -> TargetBelief:
    P = np.diag([0.25, 0.25, 0.04, 0.04])
    return TargetBelief(x, np.linalg.inv(P), s.motion, cov_pred=P, track_id=track_id)


def _leg_min_distance(prev: np.ndarray, end: np.ndarray, x_pred: np.ndarray, dt: float) -> float:
    """The nearest a straight leg prev -> end [2] comes to a constant-velocity target that ends
    the slot at x_pred [4], on 4001 instants (this test's own: no planner code)."""
    tau = np.linspace(0.0, 1.0, 4001)[:, None]
    uav = prev + tau * (end - prev)
    target = x_pred[:2] - (1.0 - tau) * dt * x_pred[2:]
    return float(np.min(np.linalg.norm(uav - target, axis=1)))


def test_a_plan_inside_the_second_targets_moving_clearance_is_refused_though_its_point_is_clear(
    paper: Scenario,
) -> None:
    # The second target flies (-15, 0) -> (15, 0) about o in the slot; UAV 0 holds at
    # (0, c2 - 0.5) over o: more than D_s + 2 e from the target's slot-end point (the static
    # keep-out check passes) but inside the target's clearance c2 halfway through the slot.
    s = paper.with_changes(a_target=0.0)
    o = np.array([1000.0, 1000.0])
    lead = _belief(s, np.array([2500.0, 2500.0, 10.0, 0.0]), 1)
    second = _belief(s, np.array([o[0] + 15.0, o[1], 30.0, 0.0]), 2)
    c2 = belief_clearance_m(second, s)
    assert s.d_safe < c2 < s.d_safe + 5.0
    prev = o + np.array([[0.0, c2 - 0.5], [600.0, 600.0], [-600.0, 600.0]])
    inp = SlotInput(
        prev, np.full(3, 1 / 3), None, (lead, second), keep_out_xy_m=second.state_pred[None, :2]
    )
    kit = SolverKit(s, n_keep_out=1)
    cons = build_slot_problem(inp, kit).constraints
    hold = prev[None]
    bad = cons.position_violations(hold)
    assert bad["14j along the legs"][0]
    assert not bad["14j target distance"][0]  # at the slot's end it is clear of both
    assert _leg_min_distance(prev[0], prev[0], second.state_pred, s.dt) < c2
    eta = np.full(3, 1 / 3)
    assert not cons.feasible(hold, eta[None])[0]
    assert not cons.feasible_moving_one(prev, eta, 0, prev[[0]])[0]
    # The same plan against the lead alone, the second target a static keep-out point (the
    # check before every target was held moving): nothing is violated.
    static = SlotConstraints(
        cons.prev_xy,
        cons.serving_bs_xy,
        cons.bs_xy,
        cons.target_xy,
        s,
        keep_out_xy=cons.keep_out_xy,
        target_clearance_m=cons.clearance_m,
        target_velocity_mps=cons.target_velocity_mps,
    )
    assert not any(v[0] for v in static.position_violations(hold).values())
    assert static.feasible(hold, eta[None])[0]
    # Climbing 20 m higher clears the second target's path: the full and one-UAV checks agree.
    away = prev.copy()
    away[0] = o + np.array([0.0, c2 + 20.0])
    assert cons.feasible(away[None], eta[None])[0], cons.describe_violations(away, eta)
    assert list(cons.feasible_moving_one(away, eta, 0, np.stack([prev[0], away[0]]))) == [
        False,
        True,
    ]
    # A plan the planner calls ok keeps every target's clearance along every leg.
    plan = plan_slot(inp, kit, "proposed")
    assert plan.report.status == "ok", plan.report.reason
    for b in (lead, second):
        c = belief_clearance_m(b, s)
        for m in range(s.M):
            start_gap = np.linalg.norm(prev[m] - (b.state_pred[:2] - s.dt * b.state_pred[2:]))
            need = min(c, float(start_gap))
            assert _leg_min_distance(prev[m], plan.uav_xy_m[m], b.state_pred, s.dt) >= need - 1e-9


def test_with_one_target_the_check_agrees_with_an_independent_leg_distance(
    paper: Scenario,
) -> None:
    # Straight legs against a constant-velocity target: a plan passes 14j iff every leg keeps
    # min(c, its start distance) from the moving target and its end keeps c (docs/model.md,
    # "Safety"), computed here on a dense sampling, away from the boundary's ties.
    s = paper
    rng = np.random.default_rng(3)
    o = np.array([1500.0, 1500.0])
    prev = o + np.array([[0.0, 0.0], [300.0, 0.0], [0.0, 300.0]])
    x_pred = np.array([o[0] - 20.0, o[1] - 38.0, 25.0, 10.0])
    c = 33.0
    cons = SlotConstraints(
        prev, prev, prev, x_pred[:2], s, target_clearance_m=c, target_velocity_mps=x_pred[2:]
    )
    one = SlotConstraints(
        prev,
        prev,
        prev,
        x_pred[:2],
        s,
        target_clearance_m=c,
        target_velocity_mps=x_pred[2:],
        target_motion=s.motion,
    )
    start = x_pred[:2] - s.dt * x_pred[2:]
    counts = {True: 0, False: 0}
    for end in prev[0] + rng.uniform(-25, 25, (400, 2)):
        need = min(c, float(np.linalg.norm(prev[0] - start)))
        leg = _leg_min_distance(prev[0], end, x_pred, s.dt)
        at_end = float(np.linalg.norm(end - x_pred[:2]))
        if abs(leg - need) < 1e-3 or abs(at_end - c) < 1e-3:
            continue
        expect = leg >= need and at_end >= c
        plan = prev.copy()
        plan[0] = end
        bad = cons.position_violations(plan[None])
        got = not (bad["14j along the legs"][0] or bad["14j target distance"][0])
        assert got == expect
        bad_one = one.position_violations(plan[None])
        assert {k: bool(v[0]) for k, v in bad_one.items()} == {
            k: bool(v[0]) for k, v in bad.items()
        }
        counts[expect] += 1
    assert counts[True] > 50 and counts[False] > 50


@pytest.mark.parametrize(
    ("vehicle_model", "counts"),
    [
        (False, {"14j target distance": 441, "14j along the legs": 441, "one": 3742}),
        (True, {"14j target distance": 441, "14j along the legs": 462, "one": 3593}),
    ],
)
def test_with_one_target_the_check_gives_the_previous_codes_answers(
    paper: Scenario, vehicle_model: bool, counts: dict[str, int]
) -> None:
    # 2000 plans near a target (seeded); the counts and the first plans' violations are those
    # the check gave before it held 14j against every target (the lead only then).
    s = _with(paper, vehicle_model=vehicle_model)
    rng = np.random.default_rng(5)
    o = np.array([1500.0, 1500.0])
    prev = o + np.array([[0.0, 0.0], [45.0, 5.0], [10.0, 50.0]])
    velocity = np.array([[12.0, -4.0], [-6.0, 9.0], [3.0, 15.0]])
    cons = SlotConstraints(
        prev,
        prev,
        prev,
        o + np.array([-20.0, -38.0]),
        s,
        target_clearance_m=33.0,
        target_velocity_mps=np.array([25.0, 10.0]),
        start_velocity_mps=velocity,
    )
    plans = prev[None] + rng.uniform(-25, 25, (2000, 3, 2))
    bad = cons.position_violations(plans)
    eta = np.full(3, 1 / 3)
    one = np.concatenate([cons.feasible_moving_one(prev, eta, m, plans[:, m]) for m in range(3)])
    assert int(bad["14j target distance"].sum()) == counts["14j target distance"]
    assert int(bad["14j along the legs"].sum()) == counts["14j along the legs"]
    assert int(bad["14h max speed"].sum()) == 1059
    assert int(one.sum()) == counts["one"]
    first = [[k for k, v in bad.items() if v[i]] for i in (0, 3, 5, 7)]
    legs_5 = ["14j along the legs"] if vehicle_model else []
    assert first == [
        [],
        ["14h max speed", "14j target distance", "14j along the legs"],
        ["14h max speed", *legs_5],
        ["14j target distance", "14j along the legs"],
    ]
