"""The planner against independent solvers and brute force.

- the DPP position subproblem re-solved with Parameters equals a freshly built problem (SCS);
- the bandwidth LP (cvxpy) equals its closed-form vertex;
- at M = 1 Algorithm 2 reaches the best point of a fine polar grid over the feasible disk;
- every plan with status ok satisfies 14a-14j (checked here with plain numpy), for random slots.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from isac_mission.config import Scenario, parse_scenario
from isac_mission.model.channel import rate_radius
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.planning.bandwidth import BandwidthSubproblem, lp_vertex
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.positions import SOLVER_MARGIN_M, PositionSubproblem
from isac_mission.planning.slot import METHODS, SlotInput, plan_slot
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.pcrb import Bound, PlanningObjective, predict_information


def _prior(s: Scenario) -> np.ndarray:
    F, W = transition_matrix(s.dt), process_noise(s.dt, s.kappa)
    return predict_information(Bound.from_covariance(s.P0), F, W)


def test_dpp_resolve_equals_fresh_problem_solved_by_scs(paper: Scenario) -> None:
    s = paper
    rng = np.random.default_rng(1)
    sub = PositionSubproblem(s, "CLARABEL")
    for _ in range(3):
        prev = s.uav_start_xy + rng.normal(0, 50, (3, 2))
        tgt = np.array([900.0, 1600.0]) + rng.normal(0, 100, 2)
        serving = s.bs_xy[[3, 4, 4]]
        cons = SlotConstraints(prev, serving, s.bs_xy, tgt, s)
        grad = rng.normal(size=(3, 2))
        eta = np.array([0.3, 0.4, 0.3])
        got = sub.solve(grad, prev, cons, eta)
        assert got is not None
        # The same problem written out directly, without Parameters, solved by another solver.
        mg = SOLVER_MARGIN_M
        Q = cp.Variable((3, 2))
        radius = rate_radius(eta, s.r_th, s.dH, s.rho0, s.B) - mg
        near = s.bs_xy[np.argmin(np.linalg.norm(prev[:, None] - s.bs_xy[None], axis=-1), axis=1)]
        ds2 = (s.d_safe + mg) ** 2
        cons_list = []
        for m in range(3):
            cons_list += [
                cp.norm(Q[m] - serving[m]) <= radius[m],
                cp.norm(Q[m] - near[m]) <= s.d_th - mg,
                cp.norm(Q[m] - prev[m]) <= s.v_max * s.dt - mg,
                np.sum((prev[m] - tgt) ** 2) + 2 * (prev[m] - tgt) @ (Q[m] - prev[m]) >= ds2,
            ]
        for i in range(3):
            for j in range(i + 1, 3):
                d = prev[i] - prev[j]
                cons_list.append(2 * d @ (Q[i] - Q[j]) - d @ d >= ds2)
        cp.Problem(cp.Minimize(cp.sum(cp.multiply(grad, Q))), cons_list).solve(
            solver="SCS", eps=1e-9, max_iters=200_000
        )
        # A linear objective can have a flat edge of optima, so compare optimal values, not
        # points; SCS is first-order, good to millimetres at km coordinates (|grad| ~ 1).
        assert np.sum(grad * got) == pytest.approx(np.sum(grad * Q.value), abs=1e-2)
        assert np.all(np.linalg.norm(got - prev, axis=1) <= s.v_max * s.dt)


def test_bandwidth_lp_equals_closed_form_vertex() -> None:
    rng = np.random.default_rng(2)
    sub = BandwidthSubproblem(4)
    for _ in range(10):
        grad = rng.normal(size=4)
        floor = rng.uniform(0.01, 0.2, 4)
        np.testing.assert_allclose(sub.solve(grad, floor), lp_vertex(grad, floor), atol=1e-9)
    assert sub.solve(np.ones(4), np.full(4, 0.3)) is None


def test_single_uav_plan_reaches_grid_optimum() -> None:
    """M = 1: eta = 1, so f depends on q only; the feasible set is the 25 m disk minus the
    D_s disk around the predicted target. A fine polar grid finds its best point."""
    # The paper's problem (D_s at the slot instant): the grid below is its feasible set.
    s = parse_scenario(
        {"uavs": {"start_xy_m": [[1000.0, 1700.0]]}, "planner": {"safety_margin": "none"}}
    )
    kit = SolverKit(s)
    for x_pred in (np.array([700.0, 1600.0, 30.0, 0.0]), np.array([1030.0, 1650.0, 10.0, 20.0])):
        inp = SlotInput(
            s.uav_start_xy, np.ones(1), None, (TargetBelief(x_pred, _prior(s), s.motion),)
        )
        plan = plan_slot(inp, kit, "proposed")
        assert plan.report.status == "ok", plan.report.reason
        obj = PlanningObjective(inp.lead.prior_information, x_pred, kit.sensing)
        r = np.linspace(0, s.v_max * s.dt, 120)[:, None]
        a = np.linspace(0, 2 * np.pi, 720, endpoint=False)[None, :]
        pts = s.uav_start_xy[0] + np.stack([r * np.cos(a), r * np.sin(a)], -1).reshape(-1, 2)
        pts = pts[np.linalg.norm(pts - x_pred[:2], axis=1) >= s.d_safe]
        best = obj.values(pts[:, None, :], np.ones(1)).min()
        assert plan.pcrb_trace <= best * (1 + 1e-3)


def _independent_violations(
    s: Scenario, inp: SlotInput, xy: np.ndarray, eta: np.ndarray, assoc: np.ndarray
) -> list[str]:
    bad = []
    d_bs = np.linalg.norm(xy - s.bs_xy[assoc], axis=1)
    rates = eta * s.B * np.log2(1 + s.rho0 / (d_bs**2 + s.dH**2))
    if np.any(rates < s.r_th * (1 - 1e-9)):
        bad.append("14a")
    if np.any(np.linalg.norm(xy[:, None] - s.bs_xy[None], axis=-1).min(axis=1) > s.d_th + 1e-6):
        bad.append("14b")
    if abs(eta.sum() - 1) > 1e-9 or np.any(eta < 0) or np.any(eta > 1):
        bad.append("14c/d")
    if np.bincount(assoc, minlength=s.K).max() > s.n_a:
        bad.append("14e")
    if np.any(np.linalg.norm(xy - inp.prev_xy_m, axis=1) > s.v_max * s.dt + 1e-6):
        bad.append("14h")
    for i in range(s.M):
        for j in range(i + 1, s.M):
            if np.linalg.norm(xy[i] - xy[j]) < s.d_safe - 1e-6:
                bad.append("14i")
    if np.any(np.linalg.norm(xy - inp.lead.state_pred[:2], axis=1) < s.d_safe - 1e-6):
        bad.append("14j")
    return bad


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 100_000),
    method=st.sampled_from(METHODS),
    spread=st.floats(20.0, 400.0),
)
def test_ok_plans_satisfy_every_original_constraint(
    paper: Scenario, seed: int, method: str, spread: float
) -> None:
    s = paper
    rng = np.random.default_rng(seed)
    # UAVs close to each other and to the target, so that 14i and 14j are active.
    centre = rng.uniform(500, 2500, 2)
    prev = centre + rng.normal(0, spread, (s.M, 2))
    x_pred = np.array([*(centre + rng.normal(0, spread, 2)), *rng.normal(0, 20, 2)])
    inp = SlotInput(
        prev, rng.dirichlet(np.ones(s.M)), None, (TargetBelief(x_pred, _prior(s), s.motion),)
    )
    plan = plan_slot(inp, _kit(s), method)  # type: ignore[arg-type]
    if plan.report.status == "ok":
        assert (
            _independent_violations(s, inp, plan.uav_xy_m, plan.bandwidth_share, plan.bs_of_uav)
            == []
        )
    else:
        assert plan.report.reason


_KIT: dict[int, SolverKit] = {}


def _kit(s: Scenario) -> SolverKit:
    return _KIT.setdefault(id(s), SolverKit(s))


def test_infeasible_rate_gives_communication_optimal_fallback_with_reason() -> None:
    s = parse_scenario({"radio": {"rate_min_bps": 150e6}})
    kit = SolverKit(s)
    inp = SlotInput(
        s.uav_start_xy, np.full(3, 1 / 3), None, (TargetBelief(s.x0, _prior(s), s.motion),)
    )
    plan = plan_slot(inp, kit, "proposed")
    assert plan.report.status == "infeasible"
    assert "R_c*" in plan.report.reason and "R_th" in plan.report.reason
    step = np.linalg.norm(plan.uav_xy_m - s.uav_start_xy, axis=1)
    assert np.all(step <= s.v_max * s.dt + 1e-9)


def test_proposed_objective_not_worse_than_benchmarks_on_the_same_slot(paper: Scenario) -> None:
    """On the slot's own objective, the proposed plan is at least as good as ABA's and SD's."""
    s = paper
    kit = _kit(s)
    inp = SlotInput(
        s.uav_start_xy,
        np.full(3, 1 / 3),
        None,
        (TargetBelief(s.x0 + np.array([30.0, 0.0, 0.0, 0.0]), _prior(s), s.motion),),
    )
    f = {m: plan_slot(inp, kit, m).pcrb_trace for m in ("proposed", "sd", "aba")}
    assert f["proposed"] <= min(f["sd"], f["aba"]) * (1 + 1e-9)


def test_target_closing_in_gives_evasive_fallback(paper: Scenario) -> None:
    """A target predicted 5 m from UAV 0: no plan keeps D_s (14j), so the slot is infeasible and
    UAV 0 moves straight away from the target at full speed instead of toward its BS."""
    s = paper
    target = s.uav_start_xy[0] + np.array([5.0, 0.0])
    inp = SlotInput(
        s.uav_start_xy,
        np.full(3, 1 / 3),
        None,
        (TargetBelief(np.array([*target, -30.0, 0.0]), _prior(s), s.motion),),
    )
    plan = plan_slot(inp, _kit(s), "proposed")
    assert plan.report.status == "infeasible"
    assert "14j" in plan.report.reason
    moved = plan.uav_xy_m[0] - s.uav_start_xy[0]
    np.testing.assert_allclose(moved, [-s.v_max * s.dt, 0.0], atol=1e-6)


def test_dynamics_aware_plan_stays_reachable_from_the_coasting_point(paper: Scenario) -> None:
    """With planner.accel_limit_mps2 = a, each waypoint is within a dt^2 / 4 of q + v dt (the
    reach of a smooth leg), and still satisfies 14a-14j; without it the same slot moves freely."""
    a = 8.0
    s = paper.with_changes(planner=paper.planner.model_copy(update={"accel_limit_mps2": a}))
    v = np.array([[20.0, 0.0], [0.0, 15.0], [-10.0, -10.0]])
    inp = SlotInput(
        s.uav_start_xy,
        np.full(3, 1 / 3),
        None,
        (TargetBelief(s.x0 + np.array([30.0, 0.0, 0.0, 0.0]), _prior(s), s.motion),),
        v,
    )
    plan = plan_slot(inp, SolverKit(s), "proposed")
    assert plan.report.status == "ok", plan.report.reason
    off = np.linalg.norm(plan.uav_xy_m - (s.uav_start_xy + v * s.dt), axis=1)
    assert np.all(off <= a * s.dt**2 / 4 + 1e-9)
    assert (
        _independent_violations(s, inp, plan.uav_xy_m, plan.bandwidth_share, plan.bs_of_uav) == []
    )
    free = plan_slot(inp, _kit(paper), "proposed")
    assert np.max(np.linalg.norm(free.uav_xy_m - (s.uav_start_xy + v * s.dt), axis=1)) > a / 4
