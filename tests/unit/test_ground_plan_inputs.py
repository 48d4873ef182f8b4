"""What the ground loop hands the planner besides positions (ground/mission.py, planning/fleet.py):
the tracker's predicted covariance (target_cov_pred) and last slot's plan (prev_plan) when the
active vehicles are unchanged, over those vehicles only (the inverse of the plan's widening)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.planning.association import associate
from isac_mission.planning.fleet import NO_BS, active_part
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method, SlotInput, plan_slot
from isac_mission.service.ground.mission import MissionState
from isac_mission.tracking.cycle import TrackState
from isac_mission.types import Detections, Gaussian, HorizonPlan, SlotPlan
from isac_mission.wire import detection_messages


class Recorder:
    """The real per-slot planner, recording its inputs; its plans carry a planned end velocity
    and a two-slot horizon (as the vehicle model and `horizon` do), so that the widening of
    every field can be checked."""

    def __init__(self) -> None:
        self.inputs: list[SlotInput] = []

    def __call__(self, inp: SlotInput, kit: SolverKit, method: Method) -> SlotPlan:
        self.inputs.append(inp)
        plan = plan_slot(inp, kit, method)
        M = len(plan.bandwidth_share)
        v = np.arange(2.0 * M).reshape(M, 2) + 1.0
        xy2 = np.stack([plan.uav_xy_m, plan.uav_xy_m + v])
        horizon = HorizonPlan(
            xy2, np.stack([v, v]), np.stack([plan.bandwidth_share] * 2), np.ones(2)
        )
        return replace(plan, uav_velocity_mps=v, horizon=horizon)


def _detections(s: Scenario, n: int, plan: SlotPlan, x_true: np.ndarray) -> Detections:
    """Noise-free detections of x_true from the plan's waypoints (excluded UAVs: none)."""
    d = np.linalg.norm(plan.uav_xy_m - x_true[:2], axis=1)
    u = (x_true[:2] - plan.uav_xy_m) / d[:, None]
    rv = u @ x_true[2:]
    sensed = plan.bandwidth_share > 0
    return Detections(
        n, np.where(sensed, d, np.nan), np.where(sensed, rv, np.nan), plan.uav_xy_m.copy()
    )


def _belief_cov(state: MissionState) -> np.ndarray:
    """The covariance of the mission's one track."""
    saved = state.tracker.saved()
    assert isinstance(saved, TrackState)
    return saved.belief.P.copy()


def _fly(
    s: Scenario, excluded_by_slot: list[tuple[int, ...]]
) -> tuple[Recorder, list[SlotPlan], list[np.ndarray]]:
    """Plan and process len(excluded_by_slot) slots; the P of every belief before each plan."""
    state = MissionState.from_prior(s, SolverKit(s), "proposed", Gaussian(s.x0.copy(), s.P0.copy()))
    rec = Recorder()
    plans: list[SlotPlan] = []
    beliefs_P: list[np.ndarray] = []
    xy = s.uav_start_xy.copy()
    F = transition_matrix(s.dt)
    for n, excluded in enumerate(excluded_by_slot, start=1):
        beliefs_P.append(_belief_cov(state))
        job = state.next_job(xy, np.zeros((s.M, 2)), excluded)
        plan = job.run(rec)
        state.commit(job, plan)
        plans.append(plan)
        x_true = np.linalg.matrix_power(F, n) @ s.x0
        det = _detections(s, n, plan, x_true)
        msgs = {m.uav: m for m in detection_messages(det, float(n), plan.bandwidth_share)}
        state.process(n, msgs, None, plan.uav_xy_m)
        xy = plan.uav_xy_m
    return rec, plans, beliefs_P


def test_the_planner_gets_the_predicted_covariance_and_last_slots_plan(paper: Scenario) -> None:
    rec, plans, beliefs_P = _fly(paper, [(), (), ()])
    F, W = transition_matrix(paper.dt), process_noise(paper.dt, paper.kappa)
    for n, inp in enumerate(rec.inputs):
        assert inp.lead.cov_pred is not None
        np.testing.assert_allclose(inp.lead.cov_pred, F @ beliefs_P[n] @ F.T + W, rtol=1e-12)
    assert rec.inputs[0].prev_plan is None  # slot 1 has no previous plan
    for n in (1, 2):
        prev = rec.inputs[n].prev_plan
        assert prev is plans[n - 1]  # the whole fleet: the plan as committed


def test_prev_plan_is_none_after_a_change_of_the_active_fleet_and_over_it_after(
    paper: Scenario,
) -> None:
    rec, plans, _ = _fly(paper, [(), (1,), (1,), ()])
    assert rec.inputs[1].prev_plan is None  # vehicle 1 left the plan
    assert rec.inputs[3].prev_plan is None  # and came back
    prev = rec.inputs[2].prev_plan
    assert prev is not None
    # Over the active vehicles 0 and 2 only: exactly what the planner returned for them.
    sub = plans[1]
    assert sub.bs_of_uav[1] == NO_BS and sub.bandwidth_share[1] == 0.0
    np.testing.assert_array_equal(prev.uav_xy_m, sub.uav_xy_m[[0, 2]])
    np.testing.assert_array_equal(prev.bandwidth_share, sub.bandwidth_share[[0, 2]])
    np.testing.assert_array_equal(prev.bs_of_uav, sub.bs_of_uav[[0, 2]])
    assert prev.uav_velocity_mps is not None and prev.horizon is not None
    # The recorder's sub-fleet plan had velocities 1..4 for the two planned vehicles.
    np.testing.assert_array_equal(prev.uav_velocity_mps, [[1.0, 2.0], [3.0, 4.0]])
    assert prev.horizon.uav_xy_m.shape == (2, 2, 2)
    np.testing.assert_array_equal(prev.horizon.uav_xy_m[0], prev.uav_xy_m)
    assert prev.horizon.uav_velocity_mps is not None
    np.testing.assert_array_equal(prev.horizon.uav_velocity_mps[1], prev.uav_velocity_mps)
    np.testing.assert_allclose(prev.horizon.bandwidth_share.sum(axis=1), 1.0)
    assert prev.uav_xy_m.shape == (2, 2) and len(rec.inputs[2].prev_xy_m) == 2


def test_widened_plan_holds_the_excluded_vehicle_in_every_field(paper: Scenario) -> None:
    _, plans, _ = _fly(paper, [(1,)])
    plan = plans[0]
    assert plan.uav_velocity_mps is not None and plan.horizon is not None
    np.testing.assert_array_equal(plan.uav_velocity_mps[1], [0.0, 0.0])
    np.testing.assert_array_equal(plan.horizon.uav_xy_m[:, 1], [paper.uav_start_xy[1]] * 2)
    np.testing.assert_array_equal(plan.horizon.bandwidth_share[:, 1], [0.0, 0.0])
    assert active_part(plan, (0, 1, 2)) is plan


def test_a_skipped_slot_leaves_no_previous_plan(paper: Scenario) -> None:
    s = paper
    state = MissionState.from_prior(s, SolverKit(s), "proposed", Gaussian(s.x0.copy(), s.P0.copy()))
    job = state.next_job(s.uav_start_xy, None)
    state.commit(job, job.run())
    assert state.last_plan is not None
    state.skip(1, {}, None, s.uav_start_xy.copy(), "test")
    assert state.next_job(s.uav_start_xy, None).prev_plan is None


@pytest.mark.parametrize("active", [(0, 2), (1,), (0, 1, 2)])
def test_active_part_inverts_the_widening_on_any_active_set(
    paper: Scenario, active: tuple[int, ...]
) -> None:
    excluded = tuple(m for m in range(paper.M) if m not in active)
    _, plans, _ = _fly(paper, [excluded])
    part = active_part(plans[0], active)
    assert part.uav_xy_m.shape == (len(active), 2)
    assert part.bs_of_uav.min() >= 0  # no held vehicle left in it
    np.testing.assert_allclose(part.bandwidth_share.sum(), 1.0)


@pytest.mark.parametrize("excluded", [(), (2,)])
def test_a_hold_at_the_first_slot_serves_every_planned_vehicle(
    paper: Scenario, excluded: tuple[int, ...]
) -> None:
    """A plan timed out at slot 1 (no last association): each vehicle that measures (share > 0)
    has a BS (14f/g), as the planner's own association would give from the same positions."""
    s = paper
    state = MissionState.from_prior(s, SolverKit(s), "proposed", Gaussian(s.x0.copy(), s.P0.copy()))
    job = state.next_job(s.uav_start_xy, None, excluded)
    plan = job.hold("timeout: test", "timeout")
    kit = SolverKit(s)
    want = associate(
        s.uav_start_xy, s.bs_xy, capacity=s.n_a, dH=s.dH, rho0=s.rho0, B=s.B, lp=kit.association
    )
    for m in range(s.M):
        if m in excluded:
            assert plan.bs_of_uav[m] == NO_BS and plan.bandwidth_share[m] == 0.0
        else:
            assert plan.bandwidth_share[m] > 0 and plan.bs_of_uav[m] == want[m]
