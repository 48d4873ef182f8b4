"""The ground plans each vehicle that follows its plan from the plan's end state, the state the
bridge's next leg starts from (service/ground/mission.py, `leg_start_state`), and the others
from where they are."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.planning.kit import SolverKit
from isac_mission.service.ground.mission import LEG_CHAIN_WITHIN_M, MissionState, leg_start_state
from isac_mission.types import Detections, Gaussian, SlotPlan, SolveReport
from isac_mission.wire import detection_messages

PLAN_XY = np.array([[100.0, 100.0], [200.0, 100.0], [300.0, 100.0]])
PLAN_V = np.array([[10.0, 0.0], [0.0, 10.0], [-5.0, 5.0]])


def plan(velocity: np.ndarray | None = PLAN_V, fallback: str = "") -> SlotPlan:
    return SlotPlan(
        PLAN_XY.copy(),
        np.array([0, 1, 2]),
        np.full(3, 1 / 3),
        1.0,
        SolveReport("ok", fallback=fallback),
        None if velocity is None else velocity.copy(),
    )


def test_a_vehicle_on_its_plan_starts_from_the_plans_end_state() -> None:
    lag = np.array([[-1.5, 0.0], [0.0, -(LEG_CHAIN_WITHIN_M + 0.5)], [0.3, 0.3]])
    measured_v = np.full((3, 2), 7.0)
    xy, v = leg_start_state(PLAN_XY + lag, measured_v, plan(), followed=[0, 1, 2])
    # Vehicles 0 and 2 are within the chain distance: the plan's waypoint and end velocity.
    np.testing.assert_array_equal(xy[[0, 2]], PLAN_XY[[0, 2]])
    np.testing.assert_array_equal(v[[0, 2]], PLAN_V[[0, 2]])
    # Vehicle 1 is off its plan: where it is, as it moves.
    np.testing.assert_array_equal(xy[1], PLAN_XY[1] + lag[1])
    np.testing.assert_array_equal(v[1], measured_v[1])


def test_only_followed_vehicles_chain() -> None:
    xy, v = leg_start_state(PLAN_XY + 0.5, np.zeros((3, 2)), plan(), followed=[1])
    np.testing.assert_array_equal(xy[[0, 2]], PLAN_XY[[0, 2]] + 0.5)
    np.testing.assert_array_equal(xy[1], PLAN_XY[1])
    np.testing.assert_array_equal(v[0], [0.0, 0.0])


@pytest.mark.parametrize(
    ("last", "why"),
    [(plan(velocity=None), "no end velocity"), (plan(fallback="late"), "never flown (late)")],
)
def test_a_plan_the_bridge_did_not_fly_as_a_chain_is_not_a_start(last: SlotPlan, why: str) -> None:
    measured = PLAN_XY + 0.5
    xy, v = leg_start_state(measured, np.ones((3, 2)), last, followed=[0, 1, 2])
    np.testing.assert_array_equal(xy, measured, err_msg=why)
    np.testing.assert_array_equal(v, np.ones((3, 2)), err_msg=why)


def test_on_plan_is_judged_where_the_vehicle_was_at_the_boundary() -> None:
    """A telemetry sample 0.2 s after the boundary at 22 m/s is 4.4 m ahead of the waypoint the
    vehicle passed on time: the boundary position (the detections') decides."""
    telemetry = PLAN_XY + np.array([4.4, 0.0])
    boundary = PLAN_XY + np.array([0.2, 0.0])
    xy, _ = leg_start_state(telemetry, np.zeros((3, 2)), plan(), [0, 1, 2])
    np.testing.assert_array_equal(xy, telemetry)  # judged on telemetry alone: off its plan
    boundary[2] = np.nan  # vehicle 2's detection did not arrive: its telemetry decides
    xy, _ = leg_start_state(telemetry, np.zeros((3, 2)), plan(), [0, 1, 2], boundary)
    np.testing.assert_array_equal(xy[:2], PLAN_XY[:2])
    np.testing.assert_array_equal(xy[2], telemetry[2])


def test_the_ground_plans_the_next_slot_from_the_committed_plans_end_state(
    paper: Scenario,
) -> None:
    s = dataclasses.replace(
        paper, N=5, planner=paper.planner.model_copy(update={"vehicle_model": True})
    )
    state = MissionState.from_prior(s, SolverKit(s), "proposed", Gaussian(s.x0.copy(), s.P0.copy()))
    first = state.plan_next(s.uav_start_xy, np.zeros((s.M, 2)))
    assert first.plan.uav_velocity_mps is not None
    behind = first.plan.uav_xy_m - 1.0  # each vehicle 1.4 m short of its waypoint
    det = Detections(
        slot=1,
        uav_xy_m=behind,
        range_m=np.linalg.norm(behind - s.x0[:2], axis=1),
        radial_velocity_mps=np.zeros(s.M),
    )
    msgs = {msg.uav: msg for msg in detection_messages(det, 1.0, first.plan.bandwidth_share)}
    state.process(1, msgs, None, behind)
    job = state.next_job(behind, np.zeros((s.M, 2)), boundary_xy=behind)
    np.testing.assert_array_equal(job.uav_xy, first.plan.uav_xy_m)
    np.testing.assert_array_equal(job.uav_v, first.plan.uav_velocity_mps)
    # After a slot the loop did not plan (a hold, a restart) nothing chains.
    state.last_plan = None
    job = state.next_job(behind, np.zeros((s.M, 2)), boundary_xy=behind)
    np.testing.assert_array_equal(job.uav_xy, behind)
