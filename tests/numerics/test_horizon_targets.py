"""The receding horizon for several targets (docs/model.md, "Receding horizon", "Several
targets"): its NLP's objective is the weighted sum of each target's single-target horizon
objective, its gradient is the objective's finite differences, a target of weight 0 is a clearance only, its plans keep every target's clearance
along every leg, and a target count that changes between slots starts cold without failure.
Each checked against something computed independently (the hand-written bound recursion of
tests/support, the one-target NLP, fine sampling of the legs)."""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import casadi as ca
import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.config.live_settings import LIVE_SETTINGS
from isac_mission.experiment.runs import fly_outcomes, kit_for
from isac_mission.model.vehicle import hermite_position
from isac_mission.planning.horizon import (
    belief_cov_pred,
    horizon_nlp,
    nlp_targets,
    predicted_clearances,
)
from isac_mission.planning.horizon_nlp import HorizonNLP, HorizonSlotData
from isac_mission.planning.horizon_problem import horizon_weights
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.nlp_model import NlpSolver, plain_ipopt
from isac_mission.planning.problem import belief_clearance_m
from isac_mission.planning.slot import SlotInput, plan_slot
from isac_mission.tracking.pcrb import SensingParams
from isac_mission.types import SlotPlan
from tests.support.independent.pcrb import bound_update, cv_model, jacobian

TARGETS = np.array(
    [
        [600.0, 1600.0, 30.0, 0.0],
        [1900.0, 1500.0, -10.0, 20.0],
        [1300.0, 700.0, 5.0, -25.0],
    ]
)
"""Three targets' predicted states (m, m/s) in paper.yaml's area."""


def _priors(s: Scenario) -> np.ndarray:
    """Three targets' prior information [3, 4, 4]: P0 scaled differently for each."""
    P0 = np.asarray(s.P0, dtype=float)
    return np.array([np.linalg.inv(P0 * k) for k in (1.0, 4.0, 0.25)])


def _data(
    s: Scenario, x_pred: np.ndarray, J_pred: np.ndarray, weight: np.ndarray | None
) -> HorizonSlotData:
    """The fleet at its start, each UAV served and controlled by its nearest BS; x_pred [T, 4]
    (or [4]), J_pred [T, 4, 4] (or [4, 4]), clearance D_s everywhere."""
    L = s.planner.horizon.length
    nearest = np.argmin(np.linalg.norm(s.uav_start_xy[:, None] - s.bs_xy[None], axis=-1), axis=1)
    T = 1 if np.ndim(x_pred) == 1 else len(x_pred)
    return HorizonSlotData(
        rate_min_bps=s.r_th,
        prev_xy=s.uav_start_xy,
        prev_velocity=np.zeros((s.M, 2)),
        serving_xy=s.bs_xy[nearest],
        control_xy=s.bs_xy[nearest],
        keep_out_xy=np.zeros((0, 2)),
        x_pred=x_pred,
        J_pred=J_pred,
        clearance_m=np.full(L, s.d_safe) if T == 1 else np.full((T, L), s.d_safe),
        target_weight=weight,
    )


def _independent_objective(
    s: Scenario, x_pred: np.ndarray, J_pred: np.ndarray, xy: np.ndarray, eta: np.ndarray
) -> float:
    """sum_l w_l tr(C_l) of one target by the hand-written recursion of tests/support."""
    L = s.planner.horizon.length
    cfg = s.planner.horizon
    F, W = cv_model(s.dt, s.kappa)
    sensing = SensingParams.from_scenario(s)
    state = np.asarray(x_pred, dtype=float)
    traces = []
    C: np.ndarray = np.zeros((4, 4))
    for h in range(L):
        d = np.linalg.norm(state[None, :2] - xy[h], axis=1)
        r_diag = sensing.variances(d, eta[h])
        H = jacobian(state, xy[h])
        if h == 0:
            C = np.linalg.inv(J_pred + H.T @ np.diag(1.0 / r_diag) @ H)
        else:
            C, _ = bound_update(C, F, W, H, r_diag)
        traces.append(np.trace(C))
        state = F @ state
    return float(horizon_weights(L, cfg.discount, cfg.terminal_weight) @ np.array(traces))


@cache
def _nlp(vehicle_model: bool, n_targets: int) -> tuple[Scenario, HorizonNLP]:
    s = load_scenario("paper")
    if vehicle_model:
        s = LIVE_SETTINGS.apply(s)
    return s, HorizonNLP(s, 0, None, plain_ipopt, None, n_targets)


@pytest.mark.parametrize(("vehicle_model", "n_targets"), [(False, 2), (False, 3), (True, 3)])
def test_the_objective_is_the_weighted_sum_of_each_targets_horizon_objective(
    vehicle_model: bool, n_targets: int
) -> None:
    """At random plans around the fleet's start: the T-target NLP's objective (eliminated and
    lifted) equals sum_i a_i of target i's objective by the one-target NLP and by the
    hand-written recursion; its rows are the union of the one-target NLPs' rows (its
    violation the largest of theirs)."""
    s, nlp = _nlp(vehicle_model, n_targets)
    _, one = _nlp(vehicle_model, 1)
    L = nlp.length
    x_pred, J_pred = TARGETS[:n_targets], _priors(s)[:n_targets]
    rng = np.random.default_rng(n_targets)
    weight = rng.uniform(0.2, 3.0, size=n_targets)
    data = _data(s, x_pred, J_pred, weight)
    for _ in range(3):
        xy = s.uav_start_xy[None] + np.cumsum(rng.uniform(-20, 20, size=(L, s.M, 2)), axis=0)
        velocity = rng.uniform(-20, 20, size=(L, s.M, 2)) if vehicle_model else None
        eta = rng.dirichlet(np.ones(s.M), size=L)
        x, p = nlp.pack(xy, velocity, eta, data)
        got = float(nlp.objective(x, p))
        parts_nlp, parts_numpy, misses = [], [], []
        for i in range(n_targets):
            one_data = _data(s, x_pred[i], J_pred[i], None)
            x1, p1 = one.pack(xy, velocity, eta, one_data)
            np.testing.assert_array_equal(x1, x)
            parts_nlp.append(float(one.objective(x1, p1)))
            parts_numpy.append(_independent_objective(s, x_pred[i], J_pred[i], xy, eta))
            misses.append(one.violation(xy, velocity, eta, one_data))
        assert got == pytest.approx(float(weight @ parts_nlp), rel=1e-12)
        assert got == pytest.approx(float(weight @ parts_numpy), rel=1e-8)
        lift = nlp.lifted(xy, eta, data, p)
        lifted = nlp.lifted_problem(x=x, lift=lift, p=p)
        assert float(lifted["f"]) == pytest.approx(got, rel=1e-10)
        assert np.max(np.abs(np.asarray(lifted["g"]))) < 1e-9
        assert nlp.violation(xy, velocity, eta, data) == pytest.approx(max(misses), rel=1e-12)


@pytest.mark.parametrize("vehicle_model", [False, True])
def test_the_gradient_of_several_targets_is_the_objectives_finite_differences(
    vehicle_model: bool,
) -> None:
    """Three targets of different weights: the NLP's gradient (what IPOPT steps along) against
    central differences of its objective, at random plans around the fleet's start, in every
    coordinate (positions, velocities and shares)."""
    s, nlp = _nlp(vehicle_model, 3)
    L = nlp.length
    data = _data(s, TARGETS, _priors(s), np.array([1.4, 0.3, 2.2]))
    rng = np.random.default_rng(11)
    xy = s.uav_start_xy[None] + np.cumsum(rng.uniform(-20, 20, size=(L, s.M, 2)), axis=0)
    velocity = rng.uniform(-20, 20, size=(L, s.M, 2)) if vehicle_model else None
    eta = rng.dirichlet(np.ones(s.M), size=L)
    x, p = nlp.pack(xy, velocity, eta, data)
    grad = np.asarray(ca.DM(nlp.gradient(x, p)).full()).ravel()
    numeric = np.empty_like(grad)
    for k in range(len(x)):
        h = 1e-4 * max(1.0, abs(float(x[k])))
        up, down = x.copy(), x.copy()
        up[k] += h
        down[k] -= h
        numeric[k] = (float(nlp.objective(up, p)) - float(nlp.objective(down, p))) / (2 * h)
    scale = np.abs(grad).max()
    assert scale > 0
    np.testing.assert_allclose(grad, numeric, rtol=1e-5, atol=1e-6 * scale)


def test_the_hessian_of_several_targets_is_casadis_automatic_hessian() -> None:
    """Two targets on the vehicle model: the Hessian assembled through each target's
    information equals CasADi's automatic Hessian of the same Lagrangian."""
    s = LIVE_SETTINGS.apply(load_scenario("paper"))
    got: dict[str, object] = {}

    def factory(
        name: str, nlp: dict[str, object], options: dict[str, object], like: NlpSolver | None = None
    ) -> NlpSolver:
        got.setdefault("nlp", nlp)
        got.setdefault("options", options)
        return plain_ipopt(name, nlp, options, like)

    nlp_object = HorizonNLP(s, 0, None, factory, None, 2)
    nlp = got["nlp"]
    hess = got["options"]["hess_lag"]  # type: ignore[index]
    assert isinstance(nlp, dict) and isinstance(hess, ca.Function)
    x, p = nlp["x"], nlp["p"]
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", nlp["g"].numel())
    lagrangian = lam_f * nlp["f"] + ca.dot(lam_g, nlp["g"])
    automatic = ca.Function("auto", [x, p, lam_f, lam_g], [ca.triu(ca.hessian(lagrangian, x)[0])])
    L = nlp_object.length
    data = _data(s, TARGETS[:2], _priors(s)[:2], np.array([1.0, 0.6]))
    rng = np.random.default_rng(5)
    for _ in range(2):
        xy = s.uav_start_xy[None] + np.cumsum(rng.uniform(-15, 15, size=(L, s.M, 2)), axis=0)
        velocity = rng.uniform(-20, 20, size=(L, s.M, 2))
        eta = rng.dirichlet(np.ones(s.M), size=L)
        x_plan, p_value = nlp_object.pack(xy, velocity, eta, data, f_scale=0.7)
        lift = nlp_object.lifted(xy, eta, data, p_value)
        lift = lift * rng.uniform(0.9, 1.1, len(lift))
        args = [
            np.concatenate([x_plan, lift]),
            p_value,
            np.array([rng.uniform(0.5, 2.0)]),
            rng.normal(0.0, 1.0, size=lam_g.numel()),
        ]
        want = np.asarray(ca.DM(automatic.call(args)[0]).full())
        mine = np.asarray(ca.DM(hess.call(args)[0]).full())
        # 1e-7: two entries in 41209 (eta against the second target's lifted covariance, its
        # prior four times P0's) differ by 3e-8 relative, the rest to 1e-9 as for one target.
        np.testing.assert_allclose(mine, want, rtol=1e-7, atol=1e-12 * np.abs(want).max())


def _solve(nlp: HorizonNLP, s: Scenario, data: HorizonSlotData) -> tuple[np.ndarray, np.ndarray]:
    """The NLP solved from the fleet holding its start with equal shares: the plan (xy
    [L, M, 2], eta [L, M])."""
    L = nlp.length
    xy0 = np.repeat(s.uav_start_xy[None], L, axis=0)
    eta0 = np.full((L, s.M), 1.0 / s.M)
    sol = nlp.solve(xy0, None, eta0, data)
    assert sol.success, sol.status
    return sol.uav_xy_m, sol.bandwidth_share


def test_a_target_of_weight_zero_is_a_clearance_only() -> None:
    """Weights (1, 0): the plan is the one-target NLP's plan for the first target when the
    second is far from the fleet (its rows then inactive), and does not depend on the second
    target's prior information (its objective does not count) when it is near; near, it keeps
    that target's clearance. "The plan" to the solver's tolerance: the horizon objective is flat
    along some directions (IPOPT stops at the barrier problem of mu = 3e-5), so the same
    objective to 1e-5 relative and waypoints within 1 m (measured: 3.3e-6 and 0.68 m, 25 and
    32 iterations)."""
    s, two = _nlp(False, 2)
    _, one = _nlp(False, 1)
    J = _priors(s)
    far = np.array([TARGETS[0], [2900.0, 100.0, 0.0, 0.0]])
    alone_data = _data(s, far[0], J[0], None)

    def value(plan: tuple[np.ndarray, np.ndarray]) -> float:
        """The first target's one-target horizon objective of the plan."""
        return float(one.objective(*one.pack(plan[0], None, plan[1], alone_data)))

    alone = _solve(one, s, alone_data)
    with_far = _solve(two, s, _data(s, far, J[:2], np.array([1.0, 0.0])))
    assert value(with_far) == pytest.approx(value(alone), rel=1e-5)
    np.testing.assert_allclose(with_far[0], alone[0], atol=1.0)
    np.testing.assert_allclose(with_far[1], alone[1], atol=1e-3)
    # Near the fleet: the plan does not change with the target's prior.
    near = np.array([TARGETS[0], [*(s.uav_start_xy[0] + [60.0, 0.0]), 0.0, 0.0]])
    a = _solve(two, s, _data(s, near, J[:2], np.array([1.0, 0.0])))
    b = _solve(two, s, _data(s, near, np.array([J[0], 100.0 * J[1]]), np.array([1.0, 0.0])))
    assert value(a) == pytest.approx(value(b), rel=1e-5)
    np.testing.assert_allclose(a[0], b[0], atol=1.0)
    # ... and it keeps that target's clearance along the legs (40 points each).
    for h in range(two.length):
        for frac in np.linspace(0.0, 1.0, 41)[1:]:
            target = near[1, :2] + (h - 1 + frac) * s.dt * near[1, 2:]
            prev = s.uav_start_xy if h == 0 else a[0][h - 1]
            uav = prev + frac * (a[0][h] - prev)
            assert np.min(np.linalg.norm(uav - target, axis=1)) >= s.d_safe - 1e-6


@cache
def _multi_target_run() -> tuple[Scenario, SolverKit, list[SlotInput]]:
    """config/multi-target.yaml's first 30 slots flown by `proposed` (seed 1): the slot inputs,
    where the entering target's track is confirmed partway."""
    s = load_scenario("multi-target")
    s = s.with_changes(N=30)
    kit = kit_for(s)
    outcomes = fly_outcomes(s, "proposed", 1, kit)
    return s, kit, [o.slot_input for o in outcomes if o.slot_input is not None]


def _fine_distance_to_targets(
    s: Scenario, inp: SlotInput, plan: SlotPlan, samples: int = 400
) -> list[float]:
    """For each target of inp: the least over the first slot's legs (finely sampled) of the
    distance from a UAV to the target moving by its own motion model, minus its clearance."""
    t = np.linspace(0.0, 1.0, samples + 1)
    if plan.uav_velocity_mps is not None and inp.prev_velocity_mps is not None:
        legs = np.array(
            [
                hermite_position(
                    inp.prev_xy_m,
                    inp.prev_velocity_mps,
                    plan.uav_xy_m,
                    plan.uav_velocity_mps,
                    s.dt,
                    float(f),
                )
                for f in t
            ]
        )
    else:
        legs = inp.prev_xy_m[None] + t[:, None, None] * (plan.uav_xy_m - inp.prev_xy_m)[None]
    out = []
    for belief in inp.targets:
        where = np.array([belief.position_at((f - 1.0) * s.dt) for f in t])
        gap = np.linalg.norm(legs - where[:, None], axis=-1)
        out.append(float(np.min(gap)) - belief_clearance_m(belief, s))
    return out


def test_the_plans_keep_every_targets_clearance_along_finely_sampled_legs() -> None:
    """On the multi-target scenario, at slots with two or three confirmed tracks: every plan
    that flies the horizon's answer keeps every target's clearance along its legs (400 points
    each, each target on its own predicted path), and its whole horizon keeps each target's
    horizon clearances at 40 points of every leg."""
    s, kit, inputs = _multi_target_run()
    several = [inp for inp in inputs if len(inp.targets) >= 2]
    assert several, "no slot with several confirmed tracks"
    flown = 0
    for inp in several[:: max(1, len(several) // 4)][:4]:
        inp = replace(inp, prev_plan=None)
        plan = plan_slot(inp, kit, "horizon")
        assert plan.report.status == "ok", plan.report.reason
        for miss in _fine_distance_to_targets(s, inp, plan):
            assert miss >= -1e-6
        if plan.horizon is None:
            continue
        flown += 1
        nlp = horizon_nlp(kit, n_targets=len(inp.targets))
        h_xy = plan.horizon.uav_xy_m
        targets = nlp_targets(inp)
        for belief in targets:
            c = predicted_clearances(s, belief_cov_pred(belief), nlp.length)
            for h in range(nlp.length):
                prev = inp.prev_xy_m if h == 0 else h_xy[h - 1]
                for frac in np.linspace(0.0, 1.0, 41)[1:]:
                    uav = prev + frac * (h_xy[h] - prev)
                    target = belief.position_at((h - 1 + frac) * s.dt)
                    gap = np.min(np.linalg.norm(uav - target, axis=1))
                    assert gap >= c[h] - 1e-6
    assert flown >= 1


def test_a_target_count_that_changes_between_slots_starts_cold_without_failure() -> None:
    """Slot n planned with its tracks, slot n + 1 with its own tracks and slot n's plan as
    prev_plan, where the count of confirmed tracks changes: the multipliers of the other count
    are refused (a cold start), the plan flies the horizon's answer or its per-slot fallback
    with status ok; where it stays the same, the multipliers are taken."""
    _, kit, inputs = _multi_target_run()
    changes = [
        n for n in range(len(inputs) - 1) if len(inputs[n].targets) != len(inputs[n + 1].targets)
    ]
    same = [
        n
        for n in range(len(inputs) - 1)
        if len(inputs[n].targets) == len(inputs[n + 1].targets) >= 2
    ]
    assert changes, "no change of the target count in these slots"
    for n in [*changes[:2], *same[:1]]:
        first = plan_slot(replace(inputs[n], prev_plan=None), kit, "horizon")
        nxt = replace(inputs[n + 1], prev_plan=first)
        plan = plan_slot(nxt, kit, "horizon")
        assert plan.report.status == "ok", plan.report.reason
        assert not plan.report.reason.startswith("horizon: IPOPT"), plan.report.reason
        if first.horizon is None or first.horizon.duals is None:
            continue
        nlp = horizon_nlp(kit, n_targets=len(nxt.targets))
        warm = nlp.warm_duals(first.horizon.duals, 1.0)
        if n in changes:
            assert warm is None
        else:
            assert warm is not None
