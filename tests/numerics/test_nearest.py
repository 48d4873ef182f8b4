"""The pursuit benchmark `nearest` (planning/nearest.py) on crafted slots.

Each UAV closes on its nearest track (not a one-to-one assignment) by the full step when nothing
binds, stops where the exact check still passes when a link would break (the step just past the
stop fails it, brute force along the line), flies ABA's shares, and every plan it calls "ok"
passes the exact check 14a-14j. The expected steps and stops are computed here from the geometry
and tests/support/independent/constraints.py's rate and range formulas, not from the method.
"""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.model.motion import ConstantVelocity
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.nearest import Nearest, nearest_reachable, nearest_track
from isac_mission.planning.problem import SlotInput, belief_clearance_m, build_slot_problem
from isac_mission.planning.registry import METHODS, max_targets
from isac_mission.planning.slot import plan_slot
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.types import SlotPlan
from tests.support.independent.constraints import uplink_rate_bps

LINE_SAMPLES = 2001
"""Points of the brute-force walk along a UAV's pursuit line."""


def _belief(
    s: Scenario, xy: tuple[float, float], v: tuple[float, float] = (0.0, 0.0)
) -> TargetBelief:
    """A track predicted at xy (m) with velocity v (m/s), 0.5 m / 0.2 m/s standard deviations."""
    P = np.diag([0.25, 0.25, 0.04, 0.04])
    return TargetBelief(np.array([*xy, *v], dtype=float), np.linalg.inv(P), s.motion, cov_pred=P)


def _input(s: Scenario, prev: np.ndarray, targets: tuple[TargetBelief, ...]) -> SlotInput:
    return SlotInput(np.asarray(prev, dtype=float), np.full(s.M, 1.0 / s.M), None, targets)


def _plan(s: Scenario, inp: SlotInput, kit: SolverKit | None = None) -> tuple[SlotPlan, SolverKit]:
    kit = SolverKit(s) if kit is None else kit
    return Nearest().plan(inp, kit), kit


def _unit(v: np.ndarray) -> np.ndarray:
    return np.asarray(v / np.linalg.norm(v, axis=-1, keepdims=True))


def _passes(s: Scenario, inp: SlotInput, kit: SolverKit, plan: SlotPlan) -> list[str]:
    """The exact check's complaints about a plan (planning/feasibility.py)."""
    cons = build_slot_problem(inp, kit).constraints
    return cons.describe_violations(plan.uav_xy_m, plan.bandwidth_share)


def test_it_is_registered_for_any_number_of_targets() -> None:
    assert "nearest" in METHODS
    assert max_targets("nearest") is None


def test_a_each_uav_takes_the_full_step_straight_at_its_nearest_target(paper: Scenario) -> None:
    # Two tracks far from the UAVs (hundreds of metres): nothing binds; each UAV flies V_max dt
    # straight at the track nearest to it.
    s = paper
    near_a, near_b = (700.0, 1700.0), (2300.0, 2000.0)
    prev = np.array([[900.0, 1900.0], [2100.0, 1300.0], [1300.0, 1600.0]])
    targets = (_belief(s, near_b), _belief(s, near_a))
    plan, kit = _plan(s, _input(s, prev, targets))
    assert plan.report.status == "ok", plan.report.reason
    goal = np.array([near_a, near_b, near_a])  # 283 vs 1403 m, 728 vs 1456 m, 608 vs 1077 m
    step = plan.uav_xy_m - prev
    full_m = s.v_max * s.dt  # 25 m: every target is > 25 m + its clearance away
    assert np.all(np.linalg.norm(goal - prev, axis=1) > full_m + 100.0)
    np.testing.assert_allclose(np.linalg.norm(step, axis=1), full_m, rtol=1e-9)
    np.testing.assert_allclose(_unit(step), _unit(goal - prev), atol=1e-12)
    assert _passes(s, _input(s, prev, targets), kit, plan) == []


def test_a_a_uav_close_to_a_resting_target_stops_at_its_clearance(paper: Scenario) -> None:
    # A track at rest 40 m from UAV 0: the full step would enter its clearance c (14j), so UAV 0
    # stops at c from it, on the line.
    s = paper
    target = _belief(s, (1500.0, 1500.0))
    c = belief_clearance_m(target, s)
    assert s.d_safe < c < 40.0
    prev = np.array([[1540.0, 1500.0], [2100.0, 2300.0], [900.0, 2300.0]])
    inp = _input(s, prev, (target,))
    plan, kit = _plan(s, inp)
    assert plan.report.status == "ok", plan.report.reason
    assert _passes(s, inp, kit, plan) == []
    end = plan.uav_xy_m[0]
    assert abs(end[1] - 1500.0) < 1e-9 and end[0] < 1540.0
    assert abs(np.linalg.norm(end - target.state_pred[:2]) - c) < 1e-5


def _radial_slot(s: Scenario) -> tuple[np.ndarray, np.ndarray, int]:
    """UAV 0 at 150 m from BS 3 with its one target 450 m from BS 3 on the same ray (pursuit
    carries it straight away from the BS); UAVs 1 and 2 about 112 m from BS 1 and BS 4, all on
    their nearest BS. (prev [3, 2], the ray's unit vector [2], UAV 0's BS)."""
    ray = np.array([-0.6, -0.8])
    bs3 = s.bs_xy[3]
    prev = np.array(
        [bs3 + 150.0 * ray, s.bs_xy[1] + np.array([50.0, -100.0]), s.bs_xy[4] + [50.0, 100.0]]
    )
    return prev, ray, 3


def _walk(
    s: Scenario, inp: SlotInput, kit: SolverKit, plan: SlotPlan, m: int, full_end: np.ndarray
) -> tuple[float, float]:
    """Brute force along UAV m's line prev_m -> full_end (the others at their planned points):
    (the last passing, the first failing) distance from prev_m of LINE_SAMPLES points, m."""
    cons = build_slot_problem(inp, kit).constraints
    prev = inp.prev_xy_m[m]
    length = float(np.linalg.norm(full_end - prev))
    ds = np.linspace(0.0, length, LINE_SAMPLES)
    plans = np.repeat(plan.uav_xy_m[None], len(ds), axis=0)
    plans[:, m] = prev + ds[:, None] * (full_end - prev) / length
    ok = cons.feasible(plans, np.repeat(plan.bandwidth_share[None], len(ds), axis=0))
    first_fail = int(np.flatnonzero(~ok)[0])
    assert ok[:first_fail].all()
    return float(ds[first_fail - 1]), float(ds[first_fail])


@pytest.mark.parametrize("binding", ["14a rate", "14b control range"])
def test_b_a_uav_stops_where_its_link_would_break(paper: Scenario, binding: str) -> None:
    s0 = paper
    prev, ray, bs = _radial_slot(s0)
    e = 1.0  # the link margin of paper.yaml's safety rule (planner.tracking_margin_m)
    assert s0.planner.safety_margin == "covariance" and s0.planner.tracking_margin_m == e
    stop_m = 12.5  # where the link breaks, on UAV 0's ray: half the full step
    if binding == "14a rate":
        # R_th at which the equal share 1/3 of UAV 0 at 162.5 m (+ e) from BS 3 is just R_th.
        r_th = uplink_rate_bps(1 / 3, 150.0 + stop_m + e, s0.trace_config())
        s = s0.with_changes(r_th=r_th)
    else:
        s = s0.with_changes(d_th=150.0 + stop_m + e)
    target = _belief(s, tuple(s.bs_xy[bs] + 450.0 * ray))
    inp = _input(s, prev, (target,))
    kit = SolverKit(s)
    assert build_slot_problem(inp, kit).bs_of_uav[0] == bs
    plan, _ = _plan(s, inp, kit)
    assert plan.report.status == "ok", plan.report.reason
    step = plan.uav_xy_m[0] - prev[0]
    np.testing.assert_allclose(_unit(step), ray, atol=1e-12)
    assert abs(float(np.linalg.norm(step)) - stop_m) < 1e-5
    # The stop passes the exact check; a step 0.1 mm longer along the line fails it, and on
    # the binding constraint.
    cons = build_slot_problem(inp, kit).constraints
    assert cons.describe_violations(plan.uav_xy_m, plan.bandwidth_share) == []
    longer = plan.uav_xy_m.copy()
    longer[0] = prev[0] + step * (1.0 + 1e-4 / np.linalg.norm(step))
    assert cons.describe_violations(longer, plan.bandwidth_share) == [binding]
    # Brute force along the line to the full step: the plan stops in the first failing gap (a
    # sample on the boundary itself may pass by round-off: 1 um).
    passing, failing = _walk(s, inp, kit, plan, 0, prev[0] + s.v_max * s.dt * ray)
    assert passing - 1e-6 <= float(np.linalg.norm(step)) < failing
    # The others, far from breaking, take their full step.
    others = np.linalg.norm(plan.uav_xy_m[1:] - prev[1:], axis=1)
    np.testing.assert_allclose(others, s.v_max * s.dt, rtol=1e-9)


def test_c_shares_are_abas(paper: Scenario) -> None:
    s = paper
    prev = np.array([[900.0, 1900.0], [2100.0, 1300.0], [1300.0, 1600.0]])
    inp = _input(s, prev, (_belief(s, (700.0, 1700.0)), _belief(s, (2300.0, 2000.0))))
    kit = SolverKit(s)
    plan, _ = _plan(s, inp, kit)
    aba = plan_slot(inp, kit, "aba")
    assert plan.report.status == aba.report.status == "ok"
    np.testing.assert_array_equal(plan.bandwidth_share, aba.bandwidth_share)
    np.testing.assert_array_equal(plan.bandwidth_share, np.full(s.M, 1.0 / s.M))
    np.testing.assert_array_equal(plan.bs_of_uav, aba.bs_of_uav)


def test_d_two_uavs_two_targets_both_chase_the_nearer_not_one_each(paper: Scenario) -> None:
    s = paper.with_changes(M=2, uav_start_xy=paper.uav_start_xy[:2])
    a, b = (1500.0, 1500.0), (500.0, 500.0)
    prev = np.array([[1600.0, 1500.0], [1300.0, 1300.0]])
    # A one-to-one assignment by total distance would send UAV 1 to B (100 + 1131 m against
    # 1476 + 283 m); the nearest-track rule sends both to A.
    targets = (_belief(s, b), _belief(s, a))
    assert list(nearest_track(prev, targets)) == [1, 1]
    inp = _input(s, prev, targets)
    plan, kit = _plan(s, inp)
    assert plan.report.status == "ok", plan.report.reason
    assert _passes(s, inp, kit, plan) == []
    step = plan.uav_xy_m - prev
    np.testing.assert_allclose(_unit(step), _unit(np.array([a, a]) - prev), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(step, axis=1), s.v_max * s.dt, rtol=1e-9)


def test_ties_go_to_the_earlier_track() -> None:
    motion = ConstantVelocity(0.5)
    beliefs = tuple(
        TargetBelief(np.array([x, y, 0.0, 0.0]), np.eye(4), motion)
        for x, y in ((0.0, 5.0), (5.0, 0.0), (9.0, 9.0))
    )
    assert list(nearest_track(np.array([[0.0, 0.0], [9.0, 8.0]]), beliefs)) == [0, 2]


def test_the_reach_point_is_the_nearest_point_of_both_disks(rng: np.random.Generator) -> None:
    # Brute force: no point of a fine grid over the two disks' intersection is nearer the goal.
    for _ in range(40):
        prev = rng.uniform(-5, 5, 2)
        coast = prev + rng.uniform(-1, 1, 2) * rng.uniform(0, 25)
        step_m, radius_m = 25.0, float(rng.uniform(0.5, 30.0))
        goal = prev + rng.uniform(-80, 80, 2)
        p = nearest_reachable(goal, prev, step_m, coast, radius_m)
        assert np.linalg.norm(p - prev) <= step_m and np.linalg.norm(p - coast) <= radius_m
        g = np.linspace(-radius_m, radius_m, 401)
        grid = coast + np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
        inside = (np.linalg.norm(grid - prev, axis=1) <= step_m) & (
            np.linalg.norm(grid - coast, axis=1) <= radius_m
        )
        best = float(np.min(np.linalg.norm(grid[inside] - goal, axis=1)))
        assert np.linalg.norm(p - goal) <= best + 1e-9


@pytest.mark.parametrize("vehicle_model", [False, True])
def test_e_every_ok_plan_passes_the_exact_check(
    paper: Scenario, rng: np.random.Generator, vehicle_model: bool
) -> None:
    # Random slots: UAVs and 1-3 moving tracks anywhere in the area, some close (clearances
    # bind), R_th raised so that some links bind; with the vehicle model, random velocities.
    s = paper.with_changes(r_th=40e6)
    if vehicle_model:
        s = s.with_changes(planner=s.planner.model_copy(update={"vehicle_model": True}))
    kit = SolverKit(s)
    statuses = []
    for _ in range(25):
        prev = rng.uniform(200.0, 2800.0, (s.M, 2))
        n = int(rng.integers(1, 4))
        near = prev[rng.integers(0, s.M, n)] + rng.normal(0.0, 60.0, (n, 2))
        targets = tuple(
            _belief(s, tuple(np.clip(xy, 0.0, 3000.0)), tuple(rng.normal(0.0, 10.0, 2)))
            for xy in near
        )
        velocity = rng.normal(0.0, 8.0, (s.M, 2)) if vehicle_model else None
        inp = SlotInput(prev, np.full(s.M, 1 / s.M), None, targets, prev_velocity_mps=velocity)
        plan = Nearest().plan(inp, kit)
        statuses.append(plan.report.status)
        if plan.report.status == "ok":
            assert _passes(s, inp, kit, plan) == []
            np.testing.assert_array_equal(plan.bandwidth_share, np.full(s.M, 1 / s.M))
        else:
            assert plan.report.fallback == "infeasible" and plan.report.reason
    assert statuses.count("ok") >= 10, statuses
