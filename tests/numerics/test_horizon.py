"""The receding-horizon planner (method horizon): derivatives, bound recursion, constraints,
fallback, vehicle limits; each checked against something computed independently."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.experiment.closed_loop import draw_run_noise, record_slot_inputs
from isac_mission.experiment.montecarlo import run_monte_carlo, trace_path
from isac_mission.model.channel import full_band_rate, rate, rate_radius
from isac_mission.planning.fleet import KitCache, PlanningJob, prepare_fleet
from isac_mission.planning.horizon import (
    AT_CAP_NOTE,
    CAP_FEASIBILITY_TOL,
    _shares_meeting_rates,
    horizon_bound_traces,
    horizon_nlp,
    horizon_slot_data,
    legs_ok,
    plan_horizon,
    planned_start_velocity,
)
from isac_mission.planning.horizon_nlp import IPOPT_OPTIONS, HorizonNLP, HorizonSlotData
from isac_mission.planning.horizon_problem import horizon_weights
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.per_slot import Proposed, polish_nlp
from isac_mission.planning.polish import PolishNLP
from isac_mission.planning.problem import slot_clearance_m, with_end_velocity
from isac_mission.planning.slot import SlotInput, plan_slot, warm_up
from isac_mission.records import read_trace
from isac_mission.tracking.pcrb import SensingParams
from isac_mission.types import SlotPlan
from tests.support.ground_steps import predictions_of
from tests.support.independent.constraints import check_constraints
from tests.support.independent.pcrb import bound_update, cv_model, jacobian


def _scenario(**horizon: object) -> Scenario:
    s = load_scenario("paper")
    planner = s.planner.model_copy(update={"horizon": s.planner.horizon.model_copy(update=horizon)})
    return s.with_changes(planner=planner)


def _vehicle(s: Scenario) -> Scenario:
    return s.with_changes(planner=s.planner.model_copy(update={"vehicle_model": True}))


def _inputs(s: Scenario, method: str = "horizon", seed: int = 5) -> list[SlotInput]:
    return record_slot_inputs(s, method, draw_run_noise(s, seed), SolverKit(s))[1]  # type: ignore[arg-type]


def _data(s: Scenario, inp: SlotInput, L: int) -> HorizonSlotData:
    nearest = np.argmin(np.linalg.norm(inp.prev_xy_m[:, None] - s.bs_xy[None], axis=-1), axis=1)
    return HorizonSlotData(
        rate_min_bps=s.r_th,
        prev_xy=inp.prev_xy_m,
        prev_velocity=np.zeros((s.M, 2))
        if inp.prev_velocity_mps is None
        else inp.prev_velocity_mps,
        serving_xy=s.bs_xy[nearest],
        control_xy=s.bs_xy[nearest],
        keep_out_xy=np.zeros((0, 2)),
        x_pred=inp.lead.state_pred,
        J_pred=inp.lead.prior_information,
        clearance_m=np.full(L, s.d_safe),
    )


def _random_horizon(
    s: Scenario, inp: SlotInput, L: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    step = np.cumsum(rng.uniform(-15, 15, size=(L, s.M, 2)), axis=0)
    xy = inp.prev_xy_m[None] + step
    velocity = rng.uniform(-20, 20, size=(L, s.M, 2))
    eta = rng.dirichlet(np.ones(s.M), size=L)
    return xy, velocity, eta


def _continued(
    s: Scenario, inp: SlotInput, base: SlotPlan, L: int
) -> tuple[np.ndarray, np.ndarray]:
    """The per-slot plan `base` continued at its constant velocity over L slots (xy [L, M, 2])
    with its shares (eta [L, M]), on the paper's kinematics."""
    v = (base.uav_xy_m - inp.prev_xy_m) / s.dt
    cont = np.array([base.uav_xy_m + h * s.dt * v for h in range(L)])
    return cont, np.repeat(base.bandwidth_share[None], L, axis=0)


def _nlp_and_input(vehicle_model: bool) -> tuple[Scenario, int, HorizonNLP, SlotInput]:
    """paper.yaml (with the vehicle model or not), its horizon length and NLP, and slot 12's
    input of a `proposed` run."""
    s = _scenario()
    if vehicle_model:
        s = _vehicle(s)
    return s, s.planner.horizon.length, horizon_nlp(SolverKit(s)), _inputs(s, "proposed")[12]


@pytest.mark.parametrize("vehicle_model", [False, True])
def test_horizon_gradient_matches_central_finite_differences(vehicle_model: bool) -> None:
    s, L, nlp, inp = _nlp_and_input(vehicle_model)
    rng = np.random.default_rng(4)
    xy, velocity, eta = _random_horizon(s, inp, L, rng)
    x, p = nlp.pack(xy, velocity if vehicle_model else None, eta, _data(s, inp, L))
    grad = np.asarray(nlp.gradient(x, p)).ravel()
    fd = np.empty_like(x)
    for i in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[i]))
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        fd[i] = (float(nlp.objective(up, p)) - float(nlp.objective(down, p))) / (2 * h)
    scale = np.max(np.abs(grad))
    np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-6 * scale)


def test_horizon_objective_is_the_bound_recursion_recomputed_independently() -> None:
    s = _scenario(length=4, discount=0.8, terminal_weight=2.0)
    L = 4
    nlp = horizon_nlp(SolverKit(s))
    inp = _inputs(s, "proposed")[20]
    xy, _, eta = _random_horizon(s, inp, L, np.random.default_rng(9))
    x, p = nlp.pack(xy, None, eta, _data(s, inp, L))
    # Independent: hand-written H, the square-root-information update of tests/support.
    F, W = cv_model(s.dt, s.kappa)
    sensing = SensingParams.from_scenario(s)
    state = np.asarray(inp.lead.state_pred, dtype=float)
    traces = []
    C = None
    for h in range(L):
        d = np.linalg.norm(state[None, :2] - xy[h], axis=1)
        r_diag = sensing.variances(d, eta[h])
        H = jacobian(state, xy[h])
        if h == 0:
            J = inp.lead.prior_information + H.T @ np.diag(1.0 / r_diag) @ H
            C = np.linalg.inv(J)
        else:
            C, _ = bound_update(C, F, W, H, r_diag)
        traces.append(np.trace(C))
        state = F @ state
    expected = float(horizon_weights(L, 0.8, 2.0) @ np.array(traces))
    assert float(nlp.objective(x, p)) == pytest.approx(expected, rel=1e-8)
    ours = horizon_bound_traces(
        s, inp.lead.prior_information, inp.lead.state_pred, xy, eta, sensing
    )
    np.testing.assert_allclose(ours, traces, rtol=1e-8)


@pytest.mark.parametrize("vehicle_model", [False, True])
def test_the_lifted_recursion_is_the_bound_at_the_start_and_at_the_answer(
    vehicle_model: bool,
) -> None:
    s, L, nlp, inp = _nlp_and_input(vehicle_model)
    data = _data(s, inp, L)
    xy, velocity, eta = _random_horizon(s, inp, L, np.random.default_rng(11))
    velocity_or_none = velocity if vehicle_model else None
    x, p = nlp.pack(xy, velocity_or_none, eta, data)
    lift = nlp.lifted(xy, eta, data, p)
    out = nlp.lifted_problem(x=x, lift=lift, p=p)
    # At the start the lifted equalities hold and the lifted objective is the eliminated one,
    # and the independently recomputed bound (the numpy recursion).
    assert np.max(np.abs(np.asarray(out["g"]))) < 1e-9
    sensing = SensingParams.from_scenario(s)
    traces = horizon_bound_traces(
        s, inp.lead.prior_information, inp.lead.state_pred, xy, eta, sensing
    )
    w = horizon_weights(L, s.planner.horizon.discount, s.planner.horizon.terminal_weight)
    assert float(out["f"]) == pytest.approx(float(nlp.objective(x, p)), rel=1e-10)
    assert float(out["f"]) == pytest.approx(float(w @ traces), rel=1e-8)
    # A lift off the recursion breaks the equalities (the rows can fail).
    assert np.max(np.abs(np.asarray(nlp.lifted_problem(x, 1.01 * lift, p)[1]))) > 1e-3
    # Minimising the lifted form lowers the bound itself (recomputed on the answer's plan), from
    # a feasible start: hovering where they are, from rest, equal shares.
    hover = replace(data, prev_velocity=np.zeros((s.M, 2)))
    xy0 = np.repeat(inp.prev_xy_m[None], L, axis=0)
    v0 = np.zeros((L, s.M, 2)) if vehicle_model else None
    eta0 = np.full((L, s.M), 1.0 / s.M)
    assert nlp.satisfies(xy0, v0, eta0, hover)
    sol = nlp.solve(xy0, v0, eta0, hover)
    assert sol.success
    start, answer = (
        w @ horizon_bound_traces(s, inp.lead.prior_information, inp.lead.state_pred, q, e, sensing)
        for q, e in ((xy0, eta0), (sol.uav_xy_m, sol.bandwidth_share))
    )
    assert answer < 0.99 * start


def test_every_horizon_plan_of_a_simulate_trace_passes_the_independent_check(
    tmp_path: Path,
) -> None:
    s = load_scenario("paper")
    run_monte_carlo(s, ["horizon"], runs=2, seed=21, trace_dir=tmp_path)
    for run in range(2):
        assert check_constraints(trace_path(tmp_path, "horizon", run)) == []


def test_horizon_plans_carry_their_horizon_and_beat_the_per_slot_start() -> None:
    s = load_scenario("paper")
    kit = SolverKit(s)
    inputs = _inputs(s)
    kept = compared = 0
    for inp in inputs[1::6]:
        plan = plan_slot(inp, kit, "horizon")
        base = plan_slot(inp, kit, "proposed")
        if plan.horizon is None:  # fell back: the per-slot plan itself, saying why
            assert plan.report.reason.startswith("horizon: ")
            np.testing.assert_array_equal(plan.uav_xy_m, base.uav_xy_m)
            continue
        kept += 1
        L = s.planner.horizon.length
        assert plan.horizon.uav_xy_m.shape == (L, s.M, 2)
        np.testing.assert_array_equal(plan.uav_xy_m, plan.horizon.uav_xy_m[0])
        assert plan.pcrb_trace == pytest.approx(plan.horizon.pcrb_trace[0])
        # The per-slot plan continued at constant velocity is one start where the shifted
        # horizon does not meet the rows (else it is not computed): where it is feasible the
        # horizon's answer is no worse on the horizon objective.
        if plan.report.polish.endswith("from the shifted horizon alone"):
            continue
        cont, eta = _continued(s, inp, base, L)
        cfg = s.planner.horizon
        w = horizon_weights(L, cfg.discount, cfg.terminal_weight)
        assert inp.lead.cov_pred is not None
        assert inp.keep_out_xy_m is None
        data = horizon_slot_data(
            s, inp, np.zeros((s.M, 2)), inp.lead.cov_pred, base.bs_of_uav, base.uav_xy_m, L
        )
        if horizon_nlp(kit).satisfies(cont, None, eta, data):
            compared += 1
            start = w @ horizon_bound_traces(
                s, inp.lead.prior_information, inp.lead.state_pred, cont, eta, kit.sensing
            )
            assert w @ plan.horizon.pcrb_trace <= start * (1 + 1e-6)
    assert kept >= len(inputs[1::6]) // 2
    assert compared >= 1


def test_a_horizon_solve_at_its_iteration_cap_flies_a_better_feasible_iterate_or_falls_back() -> (
    None
):
    # At a cap of 3 iterations IPOPT stops on every one of these slots: its last iterate is
    # flown where it meets every horizon constraint below the start's objective (the note says
    # so), otherwise the per-slot plan is, saying why. Both happen on these slots.
    s = _scenario(max_iterations=3)
    kit = SolverKit(s)
    nlp = horizon_nlp(kit)
    L = s.planner.horizon.length
    cfg = s.planner.horizon
    w = horizon_weights(L, cfg.discount, cfg.terminal_weight)
    inputs = _inputs(s, "proposed")
    kinds = []
    for n in (3, 8, 15, 30):
        inp = replace(inputs[n], prev_plan=None)
        plan = plan_slot(inp, kit, "horizon")
        base = plan_slot(inp, kit, "proposed")
        if plan.horizon is None:
            kinds.append("fallback")
            assert "horizon: IPOPT Maximum_Iterations_Exceeded after 3 it" in plan.report.reason
            assert plan.report.fallback == "horizon: IPOPT Maximum_Iterations_Exceeded"
            np.testing.assert_array_equal(plan.uav_xy_m, base.uav_xy_m)
            np.testing.assert_array_equal(plan.bandwidth_share, base.bandwidth_share)
            continue
        kinds.append("kept")
        assert f"Maximum_Iterations_Exceeded in 3 it, {AT_CAP_NOTE}" in plan.report.polish
        assert inp.lead.cov_pred is not None
        data = horizon_slot_data(
            s, inp, np.zeros((s.M, 2)), inp.lead.cov_pred, base.bs_of_uav, base.uav_xy_m, L
        )
        h = plan.horizon
        assert nlp.satisfies(h.uav_xy_m, None, h.bandwidth_share, data, CAP_FEASIBILITY_TOL)
        # Its only start (no previous horizon): the per-slot plan continued, rates restored.
        cont, eta = _continued(s, inp, base, L)
        eta = _shares_meeting_rates(s, cont, eta, data.serving_xy, nlp.margins.link_m)
        start = w @ horizon_bound_traces(
            s, inp.lead.prior_information, inp.lead.state_pred, cont, eta, kit.sensing
        )
        assert w @ h.pcrb_trace < start
    assert set(kinds) == {"kept", "fallback"}, kinds


def test_the_unscaled_kkt_matrix_plans_what_ipopts_default_scalings_plan(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """MUMPS' scalings of the KKT matrix are off in the horizon (13 of an iteration's 34 ms at
    M = 24): on recorded slots of a vehicle-model mission, from rest to tracking, the plans equal
    those of the problems built with IPOPT's default scalings, to 1e-4 m and in IPOPT's note."""
    s = _vehicle(_scenario())
    assert IPOPT_OPTIONS["mumps_permuting_scaling"] == 0 and IPOPT_OPTIONS["mumps_scaling"] == 0
    inputs = [_inputs(s)[i] for i in (0, 1, 5, 20, 40)]
    kit = SolverKit(s)
    unscaled = [plan_slot(inp, kit, "horizon") for inp in inputs]
    monkeypatch.setitem(IPOPT_OPTIONS, "mumps_permuting_scaling", 7)
    monkeypatch.setitem(IPOPT_OPTIONS, "mumps_scaling", 77)
    kit = SolverKit(s)
    for inp, plan in zip(inputs, unscaled, strict=True):
        default = plan_slot(inp, kit, "horizon")
        np.testing.assert_allclose(plan.uav_xy_m, default.uav_xy_m, atol=1e-4)
        assert (
            plan.report.polish.split(", objective")[0]
            == default.report.polish.split(", objective")[0]
        )


def test_a_uav_more_than_a_slot_outside_the_area_gets_a_plan_or_a_reason_not_an_error() -> None:
    """A UAV 1.5 steps beyond the area's edge cannot return in one slot: the position bounds
    keep to its reach (lbx <= ubx, the box's point nearest to the area) and the plan comes back
    infeasible with the area named, as every method's (before, IPOPT refused the empty bounds
    with an error)."""
    s = load_scenario("paper")
    inp = _inputs(s, "proposed")[12]
    prev = inp.prev_xy_m.copy()
    prev[1, 0] = s.area[0] + 1.5 * s.v_max * s.dt
    outside = replace(inp, prev_xy_m=prev)
    kit = SolverKit(s)
    nlp = horizon_nlp(kit)
    lbx, ubx = nlp.bounds(_data(s, outside, nlp.length))
    assert np.all(lbx <= ubx)
    reach = np.arange(1, nlp.length + 1, dtype=float)  # in steps of V_max dt
    in_steps = lbx[: 2 * s.M * nlp.length].reshape(nlp.length, s.M, 2)[:, 1, 0]
    np.testing.assert_array_equal(in_steps, -reach)
    in_steps = ubx[: 2 * s.M * nlp.length].reshape(nlp.length, s.M, 2)[:, 1, 0]
    np.testing.assert_allclose(in_steps, -np.minimum(reach, 1.5), rtol=1e-12)
    plan = plan_slot(outside, kit, "horizon")
    assert plan.report.status != "ok"
    assert "operating area" in plan.report.reason


def test_capped_iterates_flown_in_a_mission_pass_the_independent_check(tmp_path: Path) -> None:
    s = _scenario(max_iterations=3).with_changes(N=30)
    run_monte_carlo(s, ["horizon"], runs=1, seed=21, trace_dir=tmp_path)
    trace = read_trace(trace_path(tmp_path, "horizon", 0))
    capped = [r for r in trace.slots if r.reason and "Maximum_Iterations_Exceeded" in r.reason]
    assert 0 < len(capped) < len(trace.slots) - 3  # the others (8 of 30) flew capped iterates
    assert check_constraints(trace_path(tmp_path, "horizon", 0)) == []


def test_vehicle_model_horizon_plans_stay_within_a_max_and_v_max() -> None:
    s = _vehicle(load_scenario("paper"))
    kit = SolverKit(s)
    inputs = _inputs(s, seed=8)
    kept = 0
    for inp in inputs[1:40:3]:
        plan = plan_slot(inp, kit, "horizon")
        if plan.horizon is None:
            continue
        kept += 1
        assert plan.uav_velocity_mps is not None
        H = plan.horizon
        assert H.uav_velocity_mps is not None
        prev_xy = np.concatenate([inp.prev_xy_m[None], H.uav_xy_m[:-1]])
        prev_v = np.concatenate([inp.prev_velocity_mps[None], H.uav_velocity_mps[:-1]])
        for h in range(len(H.uav_xy_m)):
            assert legs_ok(s, prev_xy[h], prev_v[h], H.uav_xy_m[h], H.uav_velocity_mps[h])
        # Brute force along the first leg: acceleration and speed sampled densely.
        from isac_mission.model.vehicle import hermite_position

        t = np.linspace(0.0, 1.0, 201)
        path = np.array(
            [
                hermite_position(
                    inp.prev_xy_m,
                    inp.prev_velocity_mps,
                    plan.uav_xy_m,
                    plan.uav_velocity_mps,
                    s.dt,
                    f,
                )
                for f in t
            ]
        )
        speed = np.linalg.norm(np.diff(path, axis=0), axis=-1) / (s.dt * (t[1] - t[0]))
        accel = np.linalg.norm(np.diff(path, 2, axis=0), axis=-1) / (s.dt * (t[1] - t[0])) ** 2
        assert speed.max() <= s.v_max * 1.001
        assert accel.max() <= s.a_max * 1.01
    assert kept >= 7


def test_the_first_legs_start_from_last_plans_end_velocity_where_the_vehicle_is_on_its_plan() -> (
    None
):
    s = _vehicle(load_scenario("paper"))
    kit = SolverKit(s)
    inputs = _inputs(s, seed=8)
    inp = inputs[10]
    assert inp.prev_plan is not None and inp.prev_plan.uav_velocity_mps is not None
    planned = inp.prev_plan.uav_velocity_mps
    measured = planned + np.array([[3.0, -2.0], [0.0, 0.0], [-1.0, 4.0]])
    far = inp.prev_xy_m + np.array([[0.0, 0.0], [0.0, 0.0], [5.0, 0.0]])  # vehicle 2 off its plan
    got = planned_start_velocity(s, far, measured, inp.prev_plan)
    np.testing.assert_array_equal(got[:2], planned[:2])
    np.testing.assert_array_equal(got[2], measured[2])
    plan = plan_slot(replace(inp, prev_velocity_mps=measured), kit, "horizon")
    assert plan.horizon is not None, plan.report.reason


class _CountingLock:
    """A context manager that counts how often it is entered (a stand-in for a lock)."""

    def __init__(self) -> None:
        self.entered = 0
        self.depth = 0

    def __enter__(self) -> None:
        self.entered += 1
        self.depth += 1

    def __exit__(self, *exc: object) -> None:
        self.depth -= 1


def test_every_ipopt_construction_and_solve_holds_the_kits_solve_lock() -> None:
    s = load_scenario("paper")
    lock = _CountingLock()
    kit = SolverKit(s, solve_lock=lock)
    inp = _inputs(s, "proposed")[4]
    plan_slot(inp, kit, "horizon")  # builds both NLPs, polishes and solves the horizon
    assert lock.entered >= 4  # polish built + solved, horizon built + solved
    assert lock.depth == 0
    seen = lock.entered
    calls = []

    class Spy:
        def __init__(self, original: Any) -> None:
            self.original = original

        def __call__(self, **kw: object) -> object:
            calls.append(lock.depth)
            return self.original(**kw)

        def stats(self) -> dict[str, object]:
            return dict(self.original.stats())

    nlp = horizon_nlp(kit)
    nlp.solver = Spy(nlp.solver)
    plan_slot(inp, kit, "horizon")
    assert calls and all(depth == 1 for depth in calls)
    assert lock.entered > seen


def test_a_renewed_kit_shares_the_ipopt_problems_and_plans_the_same() -> None:
    s = load_scenario("paper")
    kit = SolverKit(s)
    inp = _inputs(s, "proposed")[6]
    first = plan_slot(inp, kit, "horizon")
    renewed = kit.renewed()
    assert horizon_nlp(renewed) is horizon_nlp(kit) and polish_nlp(renewed) is polish_nlp(kit)
    assert renewed.positions is not kit.positions  # the convex problems are fresh
    again = plan_slot(inp, renewed, "horizon")
    np.testing.assert_allclose(again.uav_xy_m, first.uav_xy_m, atol=1e-6)


def test_a_kit_renewed_for_a_new_r_th_keeps_its_ipopt_problems_and_meets_the_new_rate() -> None:
    """An operator's new R_th (the service's `set`) renews the kit without building its IPOPT
    problems again: the 14a rows take R_th as their bound (nlp_model.lower_at_rate). The plans
    meet the new rate (recomputed here from eq. 3), as a kit built for it does."""
    s = load_scenario("paper")
    kit = SolverKit(s)
    inp = _inputs(s, "proposed")[6]
    s2 = s.with_changes(r_th=3.0 * s.r_th)
    renewed = kit.renewed(s2)
    assert renewed.scenario is s2
    assert horizon_nlp(renewed) is horizon_nlp(kit) and polish_nlp(renewed) is polish_nlp(kit)

    def rates_bps(plan: SlotPlan) -> np.ndarray:
        d_m = np.linalg.norm(plan.uav_xy_m - s.bs_xy[plan.bs_of_uav], axis=1)
        return np.asarray(rate(plan.bandwidth_share, d_m, s.dH, s.rho0, s.B))

    for method in ("horizon", "proposed"):
        before = plan_slot(inp, kit, method)
        assert (rates_bps(before) < s2.r_th).any(), "the new R_th must bind"
        after = plan_slot(inp, renewed, method)
        fresh = plan_slot(inp, SolverKit(s2), method)
        assert after.report.status == "ok" and not after.report.fallback
        assert np.all(rates_bps(after) >= s2.r_th * (1 - 1e-9)), rates_bps(after) / s2.r_th
        np.testing.assert_allclose(after.uav_xy_m, fresh.uav_xy_m, atol=1e-2)
        np.testing.assert_allclose(after.pcrb_trace, fresh.pcrb_trace, rtol=1e-6)
    with pytest.raises(ValueError, match="d_safe"):
        kit.renewed(s.with_changes(d_safe=2 * s.d_safe))


def test_a_start_whose_uavs_miss_the_rate_gets_shares_that_meet_it() -> None:
    s = _vehicle(load_scenario("paper"))
    L, M = 5, s.M
    serving = s.bs_xy[:M]
    link_m = 10.0
    # UAV 0 drifts from 0.6 to 1.3 times the range where a share 1/M meets R_th; the others stay
    # at 0.3 of it (so that shares meeting every rate exist until late).
    reach_m = float(rate_radius(np.array([1.0 / M]), s.r_th, s.dH, s.rho0, s.B)[0])
    factor = np.full((L, M), 0.3)
    factor[:, 0] = np.linspace(0.6, 1.3, L)
    xy = serving[None] + (factor * reach_m)[..., None] * np.array([0.6, 0.8])
    eta = np.full((L, M), 1.0 / M)
    out = _shares_meeting_rates(s, xy, eta, serving, link_m)
    d_m = np.linalg.norm(xy - serving[None], axis=-1) + link_m
    need = s.r_th / full_band_rate(d_m, s.dH, s.rho0, s.B)  # 20a, recomputed here
    met_before = np.all(eta >= need, axis=1)
    assert not met_before.all(), "the scenario must have slots that miss the rate"
    for h in range(L):
        np.testing.assert_allclose(out[h].sum(), 1.0, rtol=1e-12)
        if met_before[h] or need[h].sum() >= 1.0:
            np.testing.assert_array_equal(out[h], eta[h])  # nothing to repair, or no repair exists
        else:
            assert np.all(rate(out[h], d_m[h], s.dH, s.rho0, s.B) >= s.r_th)
    assert (~met_before & (need.sum(axis=1) < 1.0)).any(), "some slot must have been repaired"


@pytest.mark.parametrize("ahead", [True, False])
@pytest.mark.parametrize("excluded", [(1,), (0, 2)])
def test_a_fleet_size_reached_mid_mission_plans_without_a_build_inside_the_plan(
    ahead: bool, excluded: tuple[int, ...], monkeypatch: pytest.MonkeyPatch
) -> None:
    s = _vehicle(load_scenario("paper"))
    inp = _inputs(s, "proposed")[4]
    kit = SolverKit(s)
    if ahead:
        assert prepare_fleet(kit, "horizon") == [2, 1]  # every smaller fleet, within the budget
    else:
        warm_up(kit, "horizon")  # the full fleet only: the control that this test can fail
    builds: list[str] = []
    for cls in (HorizonNLP, PolishNLP):
        init = cls.__init__

        def counted(self: object, *args: Any, _init: Any = init, **kw: Any) -> None:
            builds.append(type(self).__name__)
            _init(self, *args, **kw)

        monkeypatch.setattr(cls, "__init__", counted)
    job = PlanningJob(
        slot=5,
        method="horizon",
        kits=KitCache(kit, "horizon"),
        uav_xy=inp.prev_xy_m,
        uav_v=inp.prev_velocity_mps,
        prev_eta=inp.prev_bandwidth_share,
        prev_assoc=inp.prev_bs_of_uav,
        predictions=predictions_of(inp.targets),
        excluded=excluded,  # vehicles leave the plan (an operator's HOLD, a lost link)
    )
    plan = job.run()
    assert plan.uav_xy_m.shape == (s.M, 2)
    if ahead:
        assert builds == []
        assert plan.report.status == "ok"
    else:
        assert "HorizonNLP" in builds


def test_the_build_ahead_budget_stops_after_the_one_out_fleet() -> None:
    s = _vehicle(load_scenario("paper"))
    kit = SolverKit(s)
    warm_up(kit, "proposed")
    assert KitCache(kit, "proposed").build_ahead(budget_s=0.0) == [2]  # the one-out fleet always
    assert KitCache(kit, "proposed").build_ahead(budget_s=60.0) == [2, 1]


def test_the_per_slot_plan_is_computed_only_when_the_shifted_horizon_does_not_do() -> None:
    """With last slot's horizon shifted as a start that meets the rows, the slot is planned from
    it alone and the per-slot plan is not computed; the first slot (no horizon yet) and a
    fallback compute it."""
    s = _scenario()
    kit = SolverKit(s)
    inputs = _inputs(s)
    calls: list[int] = []

    def per_slot_counted(inp: SlotInput) -> Callable[[], SlotPlan]:
        def per_slot() -> SlotPlan:
            calls.append(1)
            return with_end_velocity(Proposed().plan(inp, kit), inp, s)

        return per_slot

    first = plan_horizon(inputs[0], per_slot_counted(inputs[0]), kit, time.perf_counter())
    assert len(calls) == 1 and first.report.fallback == ""
    later = [inp for inp in inputs[5:] if inp.prev_plan is not None and inp.prev_plan.horizon]
    plans = [plan_horizon(inp, per_slot_counted(inp), kit, time.perf_counter()) for inp in later]
    alone = [p for p in plans if p.report.polish.endswith("from the shifted horizon alone")]
    assert len(alone) >= len(later) // 2, [p.report.polish for p in plans]
    assert len(calls) == 1 + len(plans) - len(alone)
    # A fallback needs the per-slot plan: a cap of one iteration.
    capped = SolverKit(_scenario(max_iterations=1))
    calls.clear()
    plan = plan_horizon(later[0], per_slot_counted(later[0]), capped, time.perf_counter())
    assert plan.report.fallback.startswith("horizon: IPOPT") and len(calls) == 1


def test_an_infeasible_per_slot_plan_is_still_a_start_for_the_horizon() -> None:
    """Where the per-slot plan comes back infeasible (its best effort), the horizon still solves
    from it (its legs change a velocity by up to a_max dt, the per-slot method's by a_max dt / 4)
    and its answer flies when its first slot passes the exact check; where no plan can, the best
    effort flies, saying why the horizon's answer was not kept."""
    s = _vehicle(_scenario())
    kit = SolverKit(s)
    inp = replace(_inputs(s, "proposed")[12], prev_plan=None)
    real = with_end_velocity(Proposed().plan(inp, kit), inp, s)
    assert real.report.status == "ok"
    # The per-slot plan as a best effort would come back: the same waypoints, marked infeasible.
    best_effort = replace(
        real, report=replace(real.report, status="infeasible", fallback="infeasible")
    )
    plan = plan_horizon(inp, lambda: best_effort, kit, time.perf_counter())
    assert plan.report.status == "ok" and plan.report.fallback == "", plan.report.reason
    assert plan.horizon is not None
    gaps = np.linalg.norm(plan.uav_xy_m - inp.lead.state_pred[None, :2], axis=1)
    assert gaps.min() >= slot_clearance_m(inp, s)
    # The target predicted on top of UAV 0: no plan keeps 14j within a slot's reach.
    x_pred = np.array(inp.lead.state_pred, dtype=float)
    x_pred[:2] = inp.prev_xy_m[0]
    trapped = replace(inp, targets=(replace(inp.lead, state_pred=x_pred),))
    base = with_end_velocity(Proposed().plan(trapped, kit), trapped, s)
    assert base.report.status == "infeasible"
    plan = plan_horizon(trapped, lambda: base, kit, time.perf_counter())
    assert plan.report.status == "infeasible" and plan.report.fallback == "infeasible"
    assert plan.report.reason.startswith("horizon: ") and plan.horizon is None
    np.testing.assert_array_equal(plan.uav_xy_m, base.uav_xy_m)
