"""The per-slot planner with planner.vehicle_model: plans the vehicle model can fly.

Each waypoint is checked against the leg it makes (model/vehicle.py's end accelerations, sampled
independently along the leg here), not against the planner's own constraint.
"""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.experiment.closed_loop import draw_run_noise, run_closed_loop
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.model.vehicle import VehicleModel, hermite_position
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import SlotInput, plan_slot
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.pcrb import Bound, predict_information


def _with_model(s: Scenario, **planner: object) -> Scenario:
    return s.with_changes(planner=s.planner.model_copy(update={"vehicle_model": True, **planner}))


def _sampled_peak_accel(model: VehicleModel, p0, v0, p1, v1) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Largest acceleration norm along each leg [M], by second differences of the position."""
    s = np.linspace(0.0, 1.0, 1001)
    xy = np.array([hermite_position(p0, v0, p1, v1, model.dt_s, x) for x in s])
    acc = np.diff(xy, 2, axis=0) / (model.dt_s * (s[1] - s[0])) ** 2
    return np.asarray(np.linalg.norm(acc, axis=-1).max(axis=0))


def _input(s: Scenario, velocity: np.ndarray) -> SlotInput:
    F, W = transition_matrix(s.dt), process_noise(s.dt, s.kappa)
    prior = predict_information(Bound.from_covariance(s.P0), F, W)
    return SlotInput(
        s.uav_start_xy,
        np.full(s.M, 1 / s.M),
        None,
        (TargetBelief(s.x0 + np.array([30.0, 0.0, 0.0, 0.0]), prior, s.motion),),
        velocity,
    )


@pytest.mark.parametrize("accel_limit", [None, 2.0])
def test_a_vehicle_model_plan_is_a_flyable_mean_velocity_leg(
    paper: Scenario, accel_limit: float | None
) -> None:
    """Waypoints within a_max dt^2 / 4 of the coasting point (the older accel_limit_mps2, when
    also set, does not shrink it), the plan's end velocity the leg's mean velocity, and each leg
    within a_max when sampled."""
    s = _with_model(paper, accel_limit_mps2=accel_limit)
    model = VehicleModel.of(s)
    v = np.array([[20.0, 0.0], [0.0, 15.0], [-10.0, -10.0]])
    inp = _input(s, v)
    plan = plan_slot(inp, SolverKit(s), "proposed")
    assert plan.report.status == "ok", plan.report.reason
    assert plan.uav_velocity_mps is not None
    np.testing.assert_allclose(plan.uav_velocity_mps, (plan.uav_xy_m - inp.prev_xy_m) / s.dt)
    off = np.linalg.norm(plan.uav_xy_m - (inp.prev_xy_m + v * s.dt), axis=1)
    assert np.all(off <= s.a_max * s.dt**2 / 4 + 1e-9)
    assert off.max() > 2.0 * s.dt**2 / 4 + 0.1, "the reach is a_max's, not accel_limit's"
    peak = _sampled_peak_accel(model, inp.prev_xy_m, v, plan.uav_xy_m, plan.uav_velocity_mps)
    assert np.all(peak <= s.a_max * (1 + 1e-9))
    assert bool(
        np.all(model.check_leg(inp.prev_xy_m, v, plan.uav_xy_m).accel_mps2 <= s.a_max + 1e-9)
    )


def test_without_the_vehicle_model_plans_carry_no_velocity(paper: Scenario) -> None:
    plan = plan_slot(_input(paper, np.zeros((3, 2))), SolverKit(paper), "proposed")
    assert plan.uav_velocity_mps is None


@pytest.mark.parametrize("method", ["proposed", "sd"])
def test_simulate_with_the_vehicle_model_flies_legs_within_a_max(
    paper: Scenario, method: str
) -> None:
    """A whole closed-loop mission: every slot's leg, from the last waypoint and planned velocity
    to the next, is within a_max (sampled along it); the paper's kinematics break it at once."""
    s = _with_model(paper)
    model = VehicleModel.of(s)
    plans = []
    run_closed_loop(s, method, draw_run_noise(s, 7), SolverKit(s), lambda o: plans.append(o))  # type: ignore[arg-type]
    xy = np.array([s.uav_start_xy] + [o.plan.uav_xy_m for o in plans])
    v = np.array([np.zeros((s.M, 2))] + [o.plan.uav_velocity_mps for o in plans])
    assert all(o.plan.report.status == "ok" for o in plans)
    peaks = np.array(
        [_sampled_peak_accel(model, xy[n], v[n], xy[n + 1], v[n + 1]) for n in range(len(plans))]
    )
    assert peaks.max() <= s.a_max * (1 + 1e-9)
    if method == "proposed":
        assert peaks.max() > 0.5 * s.a_max, "the planner uses the reach"
        paper_plans = []
        run_closed_loop(
            paper, "proposed", draw_run_noise(paper, 7), SolverKit(paper), paper_plans.append
        )
        q = np.array([paper.uav_start_xy] + [o.plan.uav_xy_m for o in paper_plans])
        check = model.check_leg(q[1:-1], (q[1:-1] - q[:-2]) / s.dt, q[2:])
        assert check.accel_mps2.max() > s.a_max, "the paper's kinematics are not flyable"
