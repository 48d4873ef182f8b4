"""The planned end velocity from the planner to the vehicle: the plan message (optional field,
old plans still decode), the bridge's Hermite leg (model/vehicle.py's formulas, the planned end
velocity, the coast past the deadline), the setpoint stream's chain of legs, and the trace."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from isac_mission.errors import MessageError
from isac_mission.model.vehicle import VehicleModel, hermite_position, hermite_velocity
from isac_mission.records.slot import SlotRecord
from isac_mission.service.bridge.counters import BridgeCounters
from isac_mission.service.bridge.legs import HermiteLeg, hermite_leg
from isac_mission.service.bridge.setpoints import SetpointStream
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.timebase import FuncTime
from isac_mission.types import SlotPlan, SolveReport
from isac_mission.wire import PlanMsg, decode, encode

V = np.array([[12.5, -3.0], [0.0, 0.0], [-20.0, 7.25]])


def _plan(velocity: np.ndarray | None) -> PlanMsg:
    plan = SlotPlan(
        uav_xy_m=np.array([[100.0, 200.0], [300.0, 400.0], [500.0, 600.0]]),
        bs_of_uav=np.array([0, 1, 2]),
        bandwidth_share=np.array([0.5, 0.3, 0.2]),
        pcrb_trace=1.5,
        report=SolveReport("ok", "", solve_s=0.01),
        uav_velocity_mps=velocity,
    )
    return PlanMsg.from_plan(4, 3.0, plan)


def _obj(payload: bytes) -> dict[str, Any]:
    out: dict[str, Any] = json.loads(payload)
    return out


def test_the_plan_carries_the_planned_velocity_and_old_plans_still_decode() -> None:
    back = decode(PlanMsg, encode(_plan(V)), n_uavs=3, n_bs=5)
    assert back.plan.uav_velocity_mps is not None
    np.testing.assert_array_equal(back.plan.uav_velocity_mps, V)
    # A plan without the field (the paper's kinematics, or an older ground loop): None.
    without = encode(_plan(None))
    assert "end_velocity_mps" not in _obj(without)
    assert decode(PlanMsg, without, n_uavs=3).plan.uav_velocity_mps is None
    null = json.dumps(_obj(without) | {"end_velocity_mps": None}).encode()
    assert decode(PlanMsg, null, n_uavs=3).plan.uav_velocity_mps is None


def test_a_bad_planned_velocity_is_refused_with_its_field() -> None:
    obj = _obj(encode(_plan(V)))
    for bad, field in (
        ({"end_velocity_mps": V[:2].tolist()}, "plan.end_velocity_mps: 2 values, expected 3"),
        ({"end_velocity_mps": [[1.0], [2.0, 3.0], [4.0, 5.0]]}, "plan.end_velocity_mps[0]"),
        ({"end_velocity_mps": [["a", 1.0], [2.0, 3.0], [4.0, 5.0]]}, "plan.end_velocity_mps[0]"),
    ):
        with pytest.raises(MessageError, match=field.replace("[", r"\[").replace("]", r"\]")):
            decode(PlanMsg, json.dumps(obj | bad).encode(), n_uavs=3)
    with pytest.raises(MessageError, match="end_velocity_mps"):
        encode(_plan(np.where(V == 0.0, np.nan, V)))


def test_the_hermite_leg_is_the_vehicle_models_leg_and_ends_at_the_planned_velocity() -> None:
    p0, v0, p1, v1 = np.array([0.0, 0.0]), np.array([10.0, 2.0]), np.array([14.0, 1.0]), V[0]
    leg = hermite_leg(p0, v0, p1, now_s=5.0, arrive_by_s=6.0, max_speed_mps=25.0, goal_v_mps=v1)
    for s in (0.0, 0.25, 0.6, 1.0 - 1e-12):
        xy, v = leg.sample(5.0 + s)
        np.testing.assert_allclose(xy, hermite_position(p0, v0, p1, v1, 1.0, s), atol=1e-9)
        np.testing.assert_allclose(v, hermite_velocity(p0, v0, p1, v1, 1.0, s), atol=1e-9)
    # Independently: central differences of the sampled position give the sampled velocity.
    h = 1e-5
    for t in (5.1, 5.5, 5.9):
        fd = (leg.sample(t + h)[0] - leg.sample(t - h)[0]) / (2 * h)
        np.testing.assert_allclose(leg.sample(t)[1], fd, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(leg.sample(6.0 - 1e-9)[1], v1, atol=1e-6)
    # Without a planned velocity: the mean velocity (p1 - p0) / T, as before.
    mean = hermite_leg(p0, v0, p1, now_s=5.0, arrive_by_s=7.0, max_speed_mps=25.0)
    np.testing.assert_allclose(mean.goal_v_mps, (p1 - p0) / 2.0)
    # Capped at V_max either way.
    capped = hermite_leg(p0, v0, p1, 5.0, 6.0, max_speed_mps=5.0, goal_v_mps=np.array([30.0, 40.0]))
    np.testing.assert_allclose(capped.goal_v_mps, [3.0, 4.0])


def test_past_its_deadline_the_leg_coasts_at_its_end_velocity_then_rests() -> None:
    leg = HermiteLeg(
        np.zeros(2), np.zeros(2), np.array([10.0, 0.0]), np.array([8.0, 6.0]), 0.0, 1.0, 0.5
    )
    xy, v = leg.sample(1.2)
    np.testing.assert_allclose(xy, [10.0 + 1.6, 1.2])
    np.testing.assert_allclose(v, [8.0, 6.0])
    xy, v = leg.sample(3.0)
    np.testing.assert_allclose(xy, [14.0, 3.0])  # where the coast ended
    np.testing.assert_allclose(v, [0.0, 0.0])
    no_coast = HermiteLeg(np.zeros(2), np.zeros(2), np.array([10.0, 0.0]), np.ones(2), 0.0, 1.0)
    np.testing.assert_allclose(no_coast.sample(1.01)[0], [10.0, 0.0])


@pytest.mark.parametrize("late_s", [0.0, 0.2, 0.4])
def test_a_chain_of_planned_legs_is_flown_on_the_plans_timeline_across_late_plans(
    late_s: float,
) -> None:
    """Setpoint stream: each plan arrives `late_s` after its slot boundary (in lockstep the
    bridge's clock runs on up to 0.2 s while the world holds there), and the setpoint is
    sampled setpoint_lead_s ahead. Until the plan comes the setpoint coasts at the planned
    velocity; from then on it is the planned leg (q_n, v_n) -> (q_n+1, v_n+1) of the slot, on
    the slot's own timeline, ending at the planned waypoint and velocity."""
    model = VehicleModel(22.5, 10.0, 1.0)
    now = [0.0]
    settings = BridgeSettings()  # setpoint_lead_s 0.025, leg_coast_s 0.5
    lead = settings.setpoint_lead_s
    stream = SetpointStream(settings, FuncTime(lambda: now[0]), None, BridgeCounters())  # type: ignore[arg-type]
    xy, v = np.array([0.0, 0.0]), np.array([20.0, 0.0])
    stream.hover(xy)
    stream.set_goal(xy + v, 1.0, 22.5, v)  # a steady start: the leg from rest is not planned
    rng = np.random.default_rng(3)
    q, qv = xy + v, v
    for n in range(2, 8):
        now[0] = n - 1.0 + late_s - lead  # the plan comes now (carrot time n - 1 + late_s)
        sp_xy, sp_v = stream.setpoint()  # type: ignore[misc]
        np.testing.assert_allclose(sp_v, qv, atol=1e-9)  # coasting at the planned velocity
        np.testing.assert_allclose(sp_xy, q + qv * late_s, atol=1e-9)
        d = rng.normal(size=2)
        d *= 0.9 * model.reach_radius_m / np.linalg.norm(d)
        q_next = model.coasting_point(q, qv) + d
        v_next = model.end_velocity(q, q_next)
        stream.set_goal(q_next, float(n), 1e3, v_next)  # the cap is tested above
        for s in (late_s, 0.5, 0.9):
            now[0] = n - 1.0 + s - lead
            sp_xy, sp_v = stream.setpoint()  # type: ignore[misc]
            want = (q, qv, q_next, v_next, 1.0, s)
            np.testing.assert_allclose(sp_xy, hermite_position(*want), atol=1e-9)
            np.testing.assert_allclose(sp_v, hermite_velocity(*want), atol=1e-9)
        now[0] = n - 1e-9 - lead
        end_xy, end_v = stream.setpoint()  # type: ignore[misc]
        np.testing.assert_allclose(end_xy, q_next, atol=1e-6)
        np.testing.assert_allclose(end_v, v_next, atol=1e-6)
        q, qv = q_next, v_next
    assert math.isclose(settings.leg_coast_s, 0.5)


def test_the_trace_records_the_planned_velocity_per_slot() -> None:
    base = dict(
        slot=1,
        method="proposed",
        status="ok",
        uav_xy_m=np.zeros((3, 2)),
        bandwidth_share=np.full(3, 1 / 3),
        assoc=np.array([0, 1, 2]),
        target_true=None,
        target_est=np.zeros(4),
        target_pred=np.zeros(4),
        r_diag=np.ones(6),
        pcrb_trace=1.0,
        solve_ms=2.0,
        P=np.eye(4),
        J=np.eye(4),
        plan_xy=np.ones((3, 2)),
    )
    rec = SlotRecord(**base, plan_velocity=V)  # type: ignore[arg-type]
    line = rec.to_dict()
    assert line["plan_velocity"] == V.tolist()
    back = SlotRecord.from_dict(json.loads(json.dumps(line)))
    np.testing.assert_array_equal(back.plan_velocity, V)  # type: ignore[arg-type]
    assert "plan_velocity" not in SlotRecord(**base).to_dict()  # type: ignore[arg-type]
    with pytest.raises(MessageError, match="plan_velocity"):
        SlotRecord(**base, plan_velocity=np.zeros((2, 2)))  # type: ignore[arg-type]
