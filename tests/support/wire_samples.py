"""Representative messages of every bus type (docs/bus.md), for the byte-for-byte test of the
encoder (`tests/unit/test_wire_bytes.py`, fixture `tests/unit/data/wire_bytes.json`).

Each sample is built the way the package builds messages: numpy arrays and numpy scalars, NaN
for a missing number, Python ints where floats go, optional fields set and unset, strings longer
than the wire allows (the encoder cuts them).
"""

from __future__ import annotations

import math

import numpy as np

from isac_mission.types import SlotPlan, SolveReport
from isac_mission.wire import (
    AnyMsg,
    ClockMsg,
    ControlMsg,
    ControlReplyMsg,
    DetectionMsg,
    DetectionSetMsg,
    FleetMsg,
    HealthMsg,
    PlanMsg,
    TelemetryMsg,
    TrackEntry,
    TrackMsg,
    TrackSetMsg,
    TruthMsg,
    TruthSetMsg,
)


def _plans() -> dict[str, PlanMsg]:
    xy = np.array([[100.0, 200.5], [-300.25, 400.0], [1e-7, 123456.789]])
    v = np.array([[1.5, -2.0], [0.0, 0.0], [12.125, 1 / 3]])
    ok = SlotPlan(
        uav_xy_m=xy,
        bs_of_uav=np.array([0, 1, 1], dtype=np.int64),
        bandwidth_share=np.array([0.5, 0.3, 0.2]),
        pcrb_trace=np.float64(12.5),
        report=SolveReport(status="ok", reason="", solve_s=0.0123),
    )
    fallback = SlotPlan(
        uav_xy_m=xy,
        bs_of_uav=np.array([2, -1, 0], dtype=np.int64),
        bandwidth_share=np.array([0.75, 0.0, 0.25]),
        pcrb_trace=math.nan,
        report=SolveReport(status="infeasible", reason="R_th not met: é → fallback", solve_s=1),
        uav_velocity_mps=v,
    )
    return {
        "plan": PlanMsg.from_plan(5, 4.2, ok),
        "plan_fallback": PlanMsg.from_plan(6, 5, fallback),
    }


def samples() -> dict[str, AnyMsg]:
    """Name -> message: at least one of every type, with the variants whose bytes differ."""
    P = np.diag([25.0, 25.0, 4.0, 4.0])
    P[0, 2] = P[2, 0] = -1.5
    J = np.linalg.inv(P) * 1e9
    entries = (
        TrackEntry(
            track_id=1,
            confirmed=True,
            x=np.array([610.5, 1590.25, 29.5, -0.5]),
            P=P,
            pcrb_position_trace=12.75,
        ),
        TrackEntry(
            track_id=np.int64(42),
            confirmed=np.bool_(False),
            x=[1, 2, 3, 4],
            P=np.eye(4, dtype=np.int64),
            pcrb_position_trace=np.float64(1e6 / 3),
        ),
    )
    out: dict[str, AnyMsg] = {
        "detection": DetectionMsg(
            slot=4,
            t_s=4.0,
            uav=1,
            range_m=812.25,
            radial_velocity_mps=-3.5,
            uav_xy_m=np.array([807.0, 1100.0]),
            bandwidth_share=0.25,
        ),
        "detection_missed": DetectionMsg(
            slot=np.int64(7),
            t_s=np.float64(7.000000001),
            uav=np.int64(0),
            range_m=math.nan,
            radial_velocity_mps=np.nan,
            uav_xy_m=[1, -2],
            bandwidth_share=np.float64(1 / 3),
        ),
        "detection_set": DetectionSetMsg(
            slot=4,
            t_s=4.0,
            uav=2,
            measurements=np.array([[812.25, -3.5], [1200.0, 7.25], [95.5, 0.0]]),
            uav_xy_m=np.array([807.0, 1100.0]),
            bandwidth_share=0.25,
        ),
        "detection_set_empty": DetectionSetMsg(
            slot=1,
            t_s=1,
            uav=0,
            measurements=np.zeros((0, 2)),
            uav_xy_m=np.zeros(2),
            bandwidth_share=1,
        ),
        "clock_before": ClockMsg(slot=-1, t_s=0.5, slot_s=1.0, speed=10.0, mission_t0_s=None),
        "clock": ClockMsg(slot=np.int64(7), t_s=37.25, slot_s=2, speed=1e6, mission_t0_s=30),
        "truth": TruthMsg(slot=3, t_s=3.0, target_x=np.array([600.0, 1600.0, 30.0, -0.25])),
        "truth_set": TruthSetMsg(
            slot=4,
            t_s=4.0,
            states=np.array([[600.0, 1600.0, 30.0, -0.25], [np.nan] * 4, [-50, 20, 0, 12.5]]),
            origins=((0, -1, 2), (), (np.int64(-1),)),
        ),
        "truth_set_no_origins": TruthSetMsg(slot=2, t_s=2.0, states=np.zeros((1, 4))),
        "telemetry": TelemetryMsg(
            slot=-1,
            t_s=1.0,
            uav=0,
            position_xy_m=np.array([10.0, 20.0]),
            altitude_m=30,
            velocity_xy_mps=np.array([1.0, 0.0]),
            mode="hold",
            armed=True,
            landed=False,
            link="ok",
        ),
        "telemetry_stamped": TelemetryMsg(
            slot=12,
            t_s=np.float64(12.5),
            uav=np.int64(2),
            position_xy_m=[1.25, -7],
            altitude_m=np.float64(99.75),
            velocity_xy_mps=np.array([-0.5, 3.0]),
            mode="offboard",
            armed=np.bool_(True),
            landed=np.bool_(False),
            link="lost",
            published_wall_s=1.8e9 + 0.25,
            override="operator: HOLD " + "x" * 80,
        ),
        "track": TrackMsg(slot=7, t_s=7.0, x=np.zeros(4), P=np.eye(4), J=np.eye(4), pcrb_trace=1),
        "track_stamped": TrackMsg(
            slot=1076,
            t_s=1076.0,
            x=np.array([1500.0, 1600.0, 15.0, 0.0]),
            P=P,
            J=J,
            pcrb_trace=np.float64(1e-9),
            published_wall_s=np.float64(1.9e9),
        ),
        "track_set": TrackSetMsg(slot=7, t_s=7.0, tracks=entries, published_wall_s=1.9e9 + 0.25),
        "track_set_empty": TrackSetMsg(slot=8, t_s=8.0, tracks=()),
        "health": HealthMsg(
            slot=3,
            t_s=3.0,
            status="running",
            counters={"slots": 3, "rejected detection.uav": 1},
            last_error="detection.uav: 7 is outside [0, 2]",
            vehicles={0: "active", 2: "excluded: " + "lost " * 20},
        ),
        "health_long_error": HealthMsg(
            slot=-1,
            t_s=0.0,
            status="done",
            counters={},
            last_error="ä" * 1200,
        ),
        "control_set": ControlMsg.set_params(-1, 0.5, "r-1", rate_min_mbps=20),
        "control_hold_one": ControlMsg(slot=3, t_s=30.0, request_id="r3", command="hold", uav=1),
        "control_resume_all": ControlMsg(slot=3, t_s=30.0, request_id="r4", command="resume"),
        "control_reply": ControlReplyMsg(
            slot=3,
            t_s=30.0,
            request_id="r1",
            command="hold",
            accepted=True,
            reason="ok",
            effect="held",
            vehicles=(1, np.int64(2)),
        ),
        "control_reply_refused": ControlReplyMsg(
            slot=-1,
            t_s=0.0,
            request_id=None,
            command=None,
            accepted=False,
            reason="payload: not JSON " + "y" * 1100,
            effect="nothing was executed",
        ),
        "control_reply_long_command": ControlReplyMsg(
            slot=0,
            t_s=0.0,
            request_id="r9",
            command="c" * 70,
            accepted=False,
            reason="no",
            effect="nothing was executed",
        ),
        "fleet": FleetMsg(slot=3, t_s=30.0, request_id="r1", command="land", uavs=(0, 2)),
    }
    return {**out, **_plans()}
