"""Planning around a vehicle outside the plan (a lost link): keep-out points in the SCA
subproblem and the exact checks, and the plan widened back to all M vehicles."""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.errors import MessageError
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.fleet import NO_BS, KitCache, PlanningJob
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.positions import PositionSubproblem
from isac_mission.planning.slot import SlotInput, plan_slot
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.wire import PlanMsg, decode, encode
from tests.support.ground_steps import predictions_of


def _two_uav(paper: Scenario) -> Scenario:
    return paper.with_changes(M=2, uav_start_xy=paper.uav_start_xy[:2])


def test_keep_out_rows_match_between_clarabel_and_cvxpy(paper: Scenario) -> None:
    """The direct conic form and the cvxpy problem give the same point with keep-out rows."""
    s = _two_uav(paper)
    prev = np.array([[1000.0, 1600.0], [800.0, 1200.0]])
    keep_out = np.array([[1020.0, 1625.0]])  # 32 m from UAV 0: the constraint binds
    cons = SlotConstraints(
        prev, s.bs_xy[[0, 1]], s.bs_xy, np.array([600.0, 1600.0]), s, keep_out_xy=keep_out
    )
    grad = np.array([[-1.0, -1.6], [0.3, -0.4]])  # UAV 0 is pushed towards the keep-out
    eta = np.array([0.5, 0.5])
    direct = PositionSubproblem(s, "CLARABEL", direct=True, n_keep_out=1).solve(
        grad, prev, cons, eta
    )
    # The cvxpy formulation of the same problem (a separate code path), solved by cvxpy.
    via_cvxpy = PositionSubproblem(s, "CLARABEL", direct=False, n_keep_out=1).solve(
        grad, prev, cons, eta
    )
    assert direct is not None and via_cvxpy is not None
    np.testing.assert_allclose(direct, via_cvxpy, atol=1e-3)
    unconstrained = PositionSubproblem(s, "CLARABEL", direct=True).solve(
        grad, prev, SlotConstraints(prev, s.bs_xy[[0, 1]], s.bs_xy, cons.target_xy, s), eta
    )
    assert unconstrained is not None
    assert np.linalg.norm(unconstrained[0] - keep_out[0]) < s.d_safe  # so the rows bind
    # The linearised keep-out (eq. 23 form) is an inner approximation: the point keeps D_s.
    assert np.linalg.norm(direct[0] - keep_out[0]) >= s.d_safe - 1e-6


def test_planner_keeps_d_safe_from_an_unplanned_vehicle_it_would_otherwise_approach(
    paper: Scenario,
) -> None:
    s = _two_uav(paper)
    x_pred = np.array([900.0, 1600.0, 20.0, 0.0])
    prev = np.array([[1000.0, 1700.0], [1300.0, 1300.0]])
    J = np.linalg.inv(np.diag([25.0, 25.0, 1.0, 1.0]))
    free = plan_slot(
        SlotInput(prev, np.full(2, 0.5), None, (TargetBelief(x_pred, J, s.motion),)), SolverKit(s)
    )
    # Put the keep-out point where UAV 0 went without it.
    keep_out = free.uav_xy_m[[0]].copy()
    kit = SolverKit(s, n_keep_out=1)
    plan = plan_slot(
        SlotInput(
            prev,
            np.full(2, 0.5),
            None,
            (TargetBelief(x_pred, J, s.motion),),
            keep_out_xy_m=keep_out,
        ),
        kit,
    )
    assert plan.report.status == "ok"
    gaps = np.linalg.norm(plan.uav_xy_m - keep_out, axis=1)
    assert np.all(gaps >= s.d_safe)
    assert plan.pcrb_trace >= free.pcrb_trace - 1e-9  # a constraint more cannot help
    with pytest.raises(ValueError, match="keep-out"):
        plan_slot(SlotInput(prev, np.full(2, 0.5), None, (TargetBelief(x_pred, J, s.motion),)), kit)


def test_a_job_without_a_vehicle_widens_to_all_and_round_trips_the_codec(
    paper: Scenario,
) -> None:
    s = paper
    kits = KitCache(SolverKit(s))
    job = PlanningJob(
        slot=7,
        method="proposed",
        kits=kits,
        uav_xy=s.uav_start_xy.copy(),
        uav_v=None,
        prev_eta=np.full(s.M, 1 / 3),
        prev_assoc=None,
        predictions=predictions_of(
            (TargetBelief(s.x0.copy(), np.linalg.inv(s.P0), s.motion, s.P0.copy()),)
        ),
        excluded=(1,),
    )
    plan = job.run()
    assert plan.report.status == "ok"
    assert plan.bandwidth_share[1] == 0.0 and plan.bs_of_uav[1] == NO_BS
    np.testing.assert_allclose(plan.bandwidth_share.sum(), 1.0)
    np.testing.assert_array_equal(plan.uav_xy_m[1], s.uav_start_xy[1])  # holds
    assert "excluded" in plan.report.reason
    for m in (0, 2):
        assert np.linalg.norm(plan.uav_xy_m[m] - s.uav_start_xy[1]) >= s.d_safe
    # The sub-fleet's plan equals planning the two alone with the third as keep-out point.
    sub = s.with_changes(M=2, uav_start_xy=s.uav_start_xy[[0, 2]])
    alone = plan_slot(
        SlotInput(
            s.uav_start_xy[[0, 2]],
            np.full(2, 0.5),
            None,
            (TargetBelief(s.x0, np.linalg.inv(s.P0), s.motion),),
            keep_out_xy_m=s.uav_start_xy[[1]],
        ),
        SolverKit(sub, n_keep_out=1),
    )
    np.testing.assert_allclose(plan.uav_xy_m[[0, 2]], alone.uav_xy_m, atol=1e-9)
    # On the wire: -1 with a zero share is valid, -1 with a share is not.
    back = decode(PlanMsg, encode(PlanMsg.from_plan(7, 7.0, plan)), n_uavs=s.M, n_bs=s.K)
    np.testing.assert_array_equal(back.plan.bs_of_uav, plan.bs_of_uav)
    bad = encode(PlanMsg.from_plan(7, 7.0, plan)).replace(b'"assoc":[', b'"assoc":[-1,', 1)
    with pytest.raises(MessageError):
        decode(PlanMsg, bad)


def test_hold_needs_no_solver_and_keeps_everyone_in_place(paper: Scenario) -> None:
    s = paper
    job = PlanningJob(
        slot=2,
        method="proposed",
        kits=KitCache(SolverKit(s)),
        uav_xy=s.uav_start_xy.copy(),
        uav_v=None,
        prev_eta=np.array([0.2, 0.3, 0.5]),
        prev_assoc=np.array([0, 1, 2]),
        predictions=predictions_of(
            (TargetBelief(s.x0.copy(), np.linalg.inv(s.P0), s.motion, s.P0.copy()),)
        ),
        excluded=(2,),
    )
    plan = job.hold("timeout: test", "timeout")
    np.testing.assert_array_equal(plan.uav_xy_m, s.uav_start_xy)
    np.testing.assert_allclose(plan.bandwidth_share, [0.4, 0.6, 0.0])
    assert plan.report.status == "timeout" and np.isfinite(plan.pcrb_trace)


def test_waypoints_stay_in_the_operating_area_when_the_gradient_points_out(
    paper: Scenario,
) -> None:
    """A UAV 10 m inside the west edge, pushed west: the direct conic form and cvxpy agree on a
    point on the edge; with keep_in_area off it leaves the area."""
    s = _two_uav(paper)
    prev = np.array([[10.0, 1500.0], [800.0, 1200.0]])
    cons = SlotConstraints(prev, s.bs_xy[[0, 1]], s.bs_xy, np.array([600.0, 2600.0]), s)
    grad = np.array([[1.0, 0.05], [0.3, -0.4]])  # minimising: UAV 0 moves to -x
    eta = np.array([0.5, 0.5])
    direct = PositionSubproblem(s, "CLARABEL", direct=True).solve(grad, prev, cons, eta)
    via_cvxpy = PositionSubproblem(s, "CLARABEL", direct=False).solve(grad, prev, cons, eta)
    assert direct is not None and via_cvxpy is not None
    np.testing.assert_allclose(direct, via_cvxpy, atol=1e-3)
    assert direct[0, 0] == pytest.approx(0.0, abs=1e-3)
    assert not cons.position_violations(direct[None] + [[1e-3, 0.0], [0.0, 0.0]])["operating area"][
        0
    ]
    off = s.with_changes(planner=s.planner.model_copy(update={"keep_in_area": False}))
    free_cons = SlotConstraints(prev, s.bs_xy[[0, 1]], s.bs_xy, cons.target_xy, off)
    free = PositionSubproblem(off, "CLARABEL", direct=True).solve(grad, prev, free_cons, eta)
    assert free is not None and free[0, 0] < -5.0
    assert cons.position_violations(free[None])["operating area"][0]
