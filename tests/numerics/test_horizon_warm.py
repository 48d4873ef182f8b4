"""The horizon's warm start from one slot to the next: last slot's multipliers shifted with its
plan, and the terminal row that lets the shifted plan continue (docs/model.md, "The
terminal row", "Start points"); each checked against something computed
independently."""

from __future__ import annotations

import re
import time
from dataclasses import replace
from typing import Any

import numpy as np

from isac_mission.config import Scenario, load_scenario
from isac_mission.experiment.closed_loop import draw_run_noise, record_slot_inputs
from isac_mission.planning.horizon import horizon_nlp, plan_horizon
from isac_mission.planning.horizon_nlp import HorizonNLP, HorizonSlotData
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.nlp_model import NlpSolver, plain_ipopt, shared_derivatives
from isac_mission.planning.per_slot import Proposed
from isac_mission.planning.problem import with_end_velocity
from isac_mission.planning.slot import SlotInput
from isac_mission.types import HorizonDuals


def _vehicle_scenario(**horizon: object) -> Scenario:
    s = load_scenario("paper")
    cfg = s.planner.horizon.model_copy(update=horizon)
    return s.with_changes(
        planner=s.planner.model_copy(update={"vehicle_model": True, "horizon": cfg})
    )


def _slot_data(s: Scenario, x_pred: np.ndarray, clearance_m: float) -> HorizonSlotData:
    L = s.planner.horizon.length
    return HorizonSlotData(
        rate_min_bps=s.r_th,
        prev_xy=s.uav_start_xy,
        prev_velocity=np.zeros((s.M, 2)),
        serving_xy=s.bs_xy[: s.M],
        control_xy=s.bs_xy[: s.M],
        keep_out_xy=np.zeros((0, 2)),
        x_pred=x_pred,
        J_pred=np.eye(4),
        clearance_m=np.full(L, clearance_m),
    )


def _warm_started(inputs: list[SlotInput]) -> list[SlotInput]:
    """The slots whose last plan carries a horizon with its multipliers."""
    return [
        inp
        for inp in inputs
        if inp.prev_plan is not None
        and inp.prev_plan.horizon is not None
        and inp.prev_plan.horizon.duals is not None
    ]


def test_last_slots_multipliers_shift_with_its_plan() -> None:
    """Each horizon slot's block of multipliers takes the next slot's, the last keeps its own, the
    terminal rows keep theirs, all rescaled to the new objective's divisor; multipliers of
    another problem are refused."""
    s = _vehicle_scenario()
    nlp = horizon_nlp(SolverKit(s))
    L, M = nlp.length, s.M
    n_rows, n_term, n_lift = len(nlp.lbg), nlp.n_terminal, nlp.n_lift
    assert n_term == M
    # Independently of the NLP's bookkeeping: x is z [L, M, 2], u [L, M, 2], eta [L, M], then the
    # lifted covariances [L - 1, 16]; each entry holds 100 x block + its horizon slot.
    x_parts = [np.repeat(100.0 * b + np.arange(L), w) for b, w in enumerate((2 * M, 2 * M, M))]
    lam_x = np.concatenate([*x_parts, np.repeat(300.0 + np.arange(L - 1), 16)])
    per_slot_rows = (n_rows - n_term) // L
    lam_g = np.concatenate(
        [
            np.repeat(np.arange(L, dtype=float), per_slot_rows),
            np.full(n_term, 77.0),
            np.repeat(500.0 + np.arange(L - 1), 16),
        ]
    )
    assert len(lam_x) == nlp.n_x + n_lift and len(lam_g) == n_rows + n_lift
    duals = HorizonDuals(lam_x, lam_g, 2.0, nlp.pair_band, np.arange(M))
    warm = nlp.warm_duals(duals, 4.0)
    assert warm is not None
    x0, g0 = warm

    def shifted(values: np.ndarray, n: int) -> np.ndarray:
        return np.minimum(values + 1, n - 1)

    want_x = np.concatenate(
        [
            *[
                np.repeat(100.0 * b + shifted(np.arange(L), L), w)
                for b, w in enumerate((2 * M, 2 * M, M))
            ],
            np.repeat(300.0 + shifted(np.arange(L - 1), L - 1), 16),
        ]
    )
    want_g = np.concatenate(
        [
            np.repeat(shifted(np.arange(L), L).astype(float), per_slot_rows),
            np.full(n_term, 77.0),
            np.repeat(500.0 + shifted(np.arange(L - 1), L - 1), 16),
        ]
    )
    np.testing.assert_array_equal(x0, 0.5 * want_x)
    np.testing.assert_array_equal(g0, 0.5 * want_g)
    assert nlp.warm_duals(replace(duals, pair_band=nlp.pair_band + 1), 4.0) is None
    assert nlp.warm_duals(replace(duals, lam_g=lam_g[:-1]), 4.0) is None


def test_the_terminal_row_is_the_braking_distance_and_braking_keeps_the_clearance() -> None:
    """The terminal row, evaluated by the NLP, is |r| - |w|^2 / (2 a_max) - c_L (r, w: the offset
    from and velocity relative to the predicted target at the horizon's end), recomputed here;
    and from every sampled end state that meets it, braking the relative velocity to 0 at a_max
    (the target on its prediction) never comes closer than c_L (Monte Carlo)."""
    s = _vehicle_scenario()
    nlp = horizon_nlp(SolverKit(s))
    L, M, dt, a_max = nlp.length, s.M, s.dt, s.a_max
    clearance = 40.0
    x_pred = np.array([1500.0, 1500.0, 12.0, -5.0])
    data = _slot_data(s, x_pred, clearance)
    target_end = x_pred[:2] + (L - 1) * dt * x_pred[2:]
    rng = np.random.default_rng(3)
    met = 0
    for _ in range(400):
        xy = np.repeat(s.uav_start_xy[None], L, axis=0).astype(float)
        v = rng.uniform(-20, 20, size=(L, M, 2))
        xy[-1] = target_end + rng.uniform(-120, 120, size=(M, 2))
        eta = np.full((L, M), 1.0 / M)
        x, p = nlp.pack(xy, v, eta, data)
        rows = np.asarray(nlp.constraints(x, p), dtype=float).ravel()[-nlp.n_terminal :]
        offset = xy[-1] - target_end
        relative = v[-1] - x_pred[2:]
        want = (
            np.linalg.norm(offset, axis=1) - np.sum(relative**2, axis=1) / (2 * a_max) - clearance
        ) / nlp.step_m
        np.testing.assert_allclose(rows, want, rtol=1e-9, atol=1e-9)
        for m in np.flatnonzero(rows >= 0):
            met += 1
            speed = np.linalg.norm(relative[m])
            t = np.linspace(0.0, speed / a_max, 200)
            brake = relative[m] / max(speed, 1e-12)
            path = offset[m][None] + relative[m][None] * t[:, None]
            path -= 0.5 * a_max * brake[None] * t[:, None] ** 2
            assert np.linalg.norm(path, axis=1).min() >= clearance - 1e-9
    assert met >= 50


def _soak_like_inputs(s: Scenario) -> list[SlotInput]:
    return record_slot_inputs(s, "horizon", draw_run_noise(s, 2), SolverKit(s))[1]  # type: ignore[arg-type]


def test_the_multipliers_warm_start_reaches_the_same_plans_in_fewer_iterations() -> None:
    """Over a mission's tracking slots (vehicle model), each planned from last slot's horizon
    shifted with its multipliers and again with them dropped: the plans' horizon objectives
    agree, and the warm solves take fewer IPOPT iterations in all."""
    s = _vehicle_scenario()
    kit = SolverKit(s)
    inputs = _warm_started(_soak_like_inputs(s)[12:40])
    assert len(inputs) >= 10
    iterations = {"warm": 0, "cold": 0}
    objectives: dict[str, list[float]] = {"warm": [], "cold": []}
    for inp in inputs:
        assert inp.prev_plan is not None and inp.prev_plan.horizon is not None
        cold_prev = replace(inp.prev_plan, horizon=replace(inp.prev_plan.horizon, duals=None))
        for kind, case in (("warm", inp), ("cold", replace(inp, prev_plan=cold_prev))):

            def per_slot(case: SlotInput = case) -> object:
                return with_end_velocity(Proposed().plan(case, kit), case, s)

            plan = plan_horizon(case, per_slot, kit, time.perf_counter())  # type: ignore[arg-type]
            assert plan.horizon is not None, plan.report.reason
            solved = re.search(r"IPOPT \w+ in (\d+) it", plan.report.polish)
            assert solved is not None, plan.report.polish
            iterations[kind] += int(solved.group(1))
            objectives[kind].append(float(plan.horizon.pcrb_trace.sum()))
    assert iterations["warm"] < iterations["cold"], iterations
    np.testing.assert_allclose(objectives["warm"], objectives["cold"], rtol=0.05)


def test_the_warm_instance_takes_the_cold_ones_derivatives_and_plans_the_same() -> None:
    """The warm-start IPOPT instance is built with the cold one's derivative functions
    (nlp_model.shared_derivatives; they are most of its build); over warm-started tracking slots
    its plans equal, bit for bit, those of a warm instance that generated its own."""
    s = _vehicle_scenario()
    likes: dict[str, object] = {}

    def sharing(
        name: str, nlp: dict[str, Any], options: dict[str, Any], like: NlpSolver | None = None
    ) -> NlpSolver:
        likes[name] = like
        return plain_ipopt(name, nlp, options, like)

    def own(
        name: str, nlp: dict[str, Any], options: dict[str, Any], like: NlpSolver | None = None
    ) -> NlpSolver:
        return plain_ipopt(name, nlp, options)

    kits = {"shared": SolverKit(s, ipopt=sharing), "own": SolverKit(s, ipopt=own)}
    nlp = horizon_nlp(kits["shared"])
    assert likes["horizon_warm"] is nlp.solver and likes["horizon"] is None
    assert shared_derivatives(nlp.solver).keys() == {"grad_f", "jac_g", "hess_lag"}
    inputs = _warm_started(_soak_like_inputs(s)[12:24])
    assert len(inputs) >= 5
    for inp in inputs:
        plans = {}
        for which, kit in kits.items():

            def per_slot(case: SlotInput = inp, kit: SolverKit = kit) -> object:
                return with_end_velocity(Proposed().plan(case, kit), case, s)

            plans[which] = plan_horizon(inp, per_slot, kit, time.perf_counter())  # type: ignore[arg-type]
        assert "IPOPT" in plans["shared"].report.polish
        np.testing.assert_array_equal(plans["shared"].uav_xy_m, plans["own"].uav_xy_m)
        np.testing.assert_array_equal(plans["shared"].bandwidth_share, plans["own"].bandwidth_share)


def test_an_nlp_without_the_vehicle_model_has_no_terminal_row() -> None:
    s = load_scenario("paper")
    assert not s.planner.vehicle_model
    nlp: HorizonNLP = horizon_nlp(SolverKit(s))
    assert nlp.n_terminal == 0
    off = horizon_nlp(SolverKit(_vehicle_scenario(terminal_braking=False)))
    assert off.n_terminal == 0


def test_a_horizon_of_one_slot_keeps_its_multipliers() -> None:
    """With L = 1 there is no later slot to shift in (and no lifted covariance): the multipliers
    come back as they were, rescaled."""
    s = _vehicle_scenario(length=1)
    nlp = horizon_nlp(SolverKit(s))
    assert nlp.n_lift == 0
    rng = np.random.default_rng(1)
    lam_x, lam_g = rng.normal(size=nlp.n_x), rng.normal(size=len(nlp.lbg))
    warm = nlp.warm_duals(HorizonDuals(lam_x, lam_g, 3.0, nlp.pair_band, np.arange(s.M)), 1.0)
    assert warm is not None
    np.testing.assert_array_equal(warm[0], 3.0 * lam_x)
    np.testing.assert_array_equal(warm[1], 3.0 * lam_g)
