"""The planner's fast paths (docs/performance.md) against the reference code they replace.

- the direct clarabel call for (P1.1.2) against cvxpy + CLARABEL at tight tolerances;
- incremental feasibility / objective for one moving UAV against the full batch versions;
- the association shortcut against the LP, the bandwidth closed form against the LP;
- plan_slot with the default kit against SolverKit(fast=False) on the same inputs.
"""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario, parse_scenario
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.planning.association import AssociationLP, round_association, unique_optimum
from isac_mission.planning.bandwidth import BandwidthSubproblem
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.positions import PositionSubproblem
from isac_mission.planning.slot import SlotInput, plan_slot
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.pcrb import Bound, PlanningObjective, predict_information


def _ring(m: int) -> Scenario:
    angles = np.linspace(0, 2 * np.pi, m, endpoint=False) + 0.3
    start = 1500 + 700 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return parse_scenario({"uavs": {"start_xy_m": start.round(1).tolist()}})


def _prior(s: Scenario) -> np.ndarray:
    F, W = transition_matrix(s.dt), process_noise(s.dt, s.kappa)
    return predict_information(Bound.from_covariance(s.P0), F, W)


def test_direct_clarabel_matches_cvxpy_at_tight_tolerance(paper: Scenario) -> None:
    s = paper
    rng = np.random.default_rng(3)
    direct = PositionSubproblem(s, "CLARABEL")
    ref = PositionSubproblem(s, "CLARABEL", direct=False)
    assert direct.direct and not ref.direct
    for _ in range(20):
        prev = s.uav_start_xy + rng.normal(0, 50, (3, 2))
        tgt = np.array([900.0, 1600.0]) + rng.normal(0, 100, 2)
        cons = SlotConstraints(prev, s.bs_xy[[3, 4, 4]], s.bs_xy, tgt, s)
        grad = rng.normal(size=(3, 2))
        eta = rng.dirichlet(np.ones(3)) * 0.7 + 0.1
        got = direct.solve(grad, prev, cons, eta)
        ref.solve(grad, prev, cons, eta)  # sets the Parameters
        ref.problem.solve(solver="CLARABEL", tol_gap_abs=1e-13, tol_gap_rel=1e-13, max_iter=500)
        assert got is not None and ref.Q.value is not None
        want = ref.Q.value + prev.mean(axis=0)
        scale = np.abs(grad).max()
        # Optimal values agree to 1e-6 (scaled objective); points to a few mm (flat boundary).
        assert np.sum(grad * got) / scale == pytest.approx(np.sum(grad * want) / scale, abs=1e-5)
        assert np.abs(got - want).max() < 5e-3


@pytest.mark.parametrize("m_uavs", [3, 8])
def test_moving_one_equals_full_batch(m_uavs: int) -> None:
    s = _ring(m_uavs)
    rng = np.random.default_rng(m_uavs)
    prev = s.uav_start_xy
    cons = SlotConstraints(prev, s.bs_xy[np.arange(m_uavs) % s.K], s.bs_xy, s.x0[:2], s)
    objective = PlanningObjective(_prior(s), s.x0, SolverKit(s).sensing)
    eta = 0.7 / m_uavs + 0.3 * rng.dirichlet(np.ones(m_uavs))  # above every 14a floor
    for m in range(m_uavs):
        moved = prev[m] + rng.normal(0, 30, (40, 2))
        cands = np.repeat(prev[None], 40, axis=0)
        cands[:, m] = moved
        full = cons.feasible(cands, np.broadcast_to(eta, cands.shape[:2]))
        assert bool(cons.feasible(prev[None], eta[None])[0])
        np.testing.assert_array_equal(cons.feasible_moving_one(prev, eta, m, moved), full)
        np.testing.assert_allclose(
            objective.values_moving_one(prev, eta, m, moved),
            objective.values(cands, eta),
            rtol=1e-12,
        )


def test_association_shortcut_is_the_lp_optimum() -> None:
    rng = np.random.default_rng(4)
    hits = 0
    for _ in range(50):
        M, K, cap = int(rng.integers(2, 7)), int(rng.integers(2, 5)), int(rng.integers(1, 4))
        if M > K * cap:
            continue
        costs = rng.uniform(1.0, 10.0, (M, K))
        quick = unique_optimum(costs, cap)
        if quick is None:
            continue
        hits += 1
        relaxed = AssociationLP(M, K, cap).solve(costs)
        assert relaxed is not None
        np.testing.assert_array_equal(quick, round_association(relaxed, costs, cap))
    assert hits > 5
    assert unique_optimum(np.ones((2, 2)), 2) is None  # ties go to the LP


def test_bandwidth_closed_form_equals_lp() -> None:
    rng = np.random.default_rng(5)
    lp, closed = BandwidthSubproblem(5), BandwidthSubproblem(5, "closed-form")
    for _ in range(10):
        grad, floor = rng.normal(size=5), rng.uniform(0.01, 0.15, 5)
        got, want = closed.solve(grad, floor), lp.solve(grad, floor)
        assert got is not None and want is not None
        np.testing.assert_allclose(got, want, atol=1e-9)
    assert closed.solve(np.ones(5), np.full(5, 0.3)) is None


def test_default_kit_plans_like_reference_kit(paper: Scenario) -> None:
    s = paper
    fast, ref = SolverKit(s), SolverKit(s, fast=False)
    rng = np.random.default_rng(6)
    for _ in range(5):
        x_pred = s.x0 + np.concatenate([rng.normal(0, 100, 2), rng.normal(0, 3, 2)])
        inp = SlotInput(
            s.uav_start_xy, np.full(3, 1 / 3), None, (TargetBelief(x_pred, _prior(s), s.motion),)
        )
        a, b = plan_slot(inp, fast, "proposed"), plan_slot(inp, ref, "proposed")
        assert a.report.status == b.report.status == "ok"
        np.testing.assert_array_equal(a.bs_of_uav, b.bs_of_uav)
        # The reference's SOCP answers are only good to millimetres (default tolerances), and the
        # discrete line search can pick a neighbouring step: objectives agree to 1e-4.
        assert a.pcrb_trace == pytest.approx(b.pcrb_trace, rel=1e-4)
