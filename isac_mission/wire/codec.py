"""Bus payloads: bytes <-> the domain messages (`wire.messages`), through the wire models.

A decoder checks the size first (`envelope.loads`: size, UTF-8, strict JSON, an object), then
validates the object with its model (`wire.models`) and converts it: lists to numpy float64
arrays (`assoc` int64), null to NaN. Every refusal is a `MessageError` whose message starts with
the field at fault, e.g. ``plan.bandwidth_share: 2 values, expected 3`` (`wire.refusal`). The
encoders write the same JSON as before the models existed (NaN range/velocity/objective as null)
and decode what they wrote, so that a sender cannot publish a payload its receivers would refuse.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any, Final, TypeVar

import numpy as np
from pydantic import BaseModel, TypeAdapter, ValidationError

from isac_mission.errors import MessageError
from isac_mission.types import Detections, FloatArray, SlotPlan, SolveReport
from isac_mission.wire.control_codec import control_msg, control_reply_msg, fleet_msg
from isac_mission.wire.control_models import ControlReplyWire, ControlWire, FleetWire
from isac_mission.wire.envelope import (
    MAX_REASON_CHARS,
    MAX_STATUS_CHARS,
    Payload,
    dumps,
    envelope,
    loads,
)
from isac_mission.wire.messages import (
    AnyMsg,
    ClockMsg,
    DetectionMsg,
    DetectionSetMsg,
    HealthMsg,
    PlanMsg,
    TelemetryMsg,
    TrackEntry,
    TrackMsg,
    TrackSetMsg,
    TruthMsg,
    TruthSetMsg,
)
from isac_mission.wire.models import (
    MODELS,
    ClockWire,
    DetectionSetWire,
    DetectionWire,
    HealthWire,
    PlanWire,
    TelemetryWire,
    TrackSetWire,
    TrackWire,
    TruthSetWire,
    TruthWire,
    WireMessage,
)
from isac_mission.wire.refusal import message_error
from isac_mission.wire.strict_json import finite_floats, finite_or_none

M = TypeVar("M", bound=BaseModel)
_ANY: Final[TypeAdapter[Any]] = TypeAdapter(WireMessage)


def _validate(model: type[M], kind: str, obj: dict[str, Any], context: dict[str, Any]) -> M:
    try:
        return model.model_validate(obj, strict=True, context=context)
    except ValidationError as err:
        raise message_error(err, kind, model) from None


def _nan(x: float | None) -> float:
    return math.nan if x is None else x


# --------------------------------------------------------------------------- detection


def encode_detection(msg: DetectionMsg) -> bytes:
    """Payload of `isac/<mission>/detections/<m>`; NaN range/velocity are sent as null."""
    obj = envelope("detection", msg.slot, msg.t_s)
    obj.update(
        uav=int(msg.uav),
        range_m=finite_or_none(msg.range_m),
        radial_velocity_mps=finite_or_none(msg.radial_velocity_mps),
        uav_xy_m=finite_floats(msg.uav_xy_m, "detection.uav_xy_m"),
        bandwidth_share=float(msg.bandwidth_share),
    )
    data = dumps(obj)
    decode_detection(data)
    return data


def _detection(w: DetectionWire) -> DetectionMsg:
    return DetectionMsg(
        slot=w.slot,
        t_s=w.t,
        uav=w.uav,
        range_m=_nan(w.range_m),
        radial_velocity_mps=_nan(w.radial_velocity_mps),
        uav_xy_m=np.array(w.uav_xy_m, dtype=float),
        bandwidth_share=w.bandwidth_share,
    )


def decode_detection(payload: Payload, *, n_uavs: int | None = None) -> DetectionMsg:
    """Validate a detection payload. n_uavs, when given, bounds the UAV index (< n_uavs)."""
    obj = loads(payload)
    return _detection(_validate(DetectionWire, "detection", obj, {"n_uavs": n_uavs}))


def detection_messages(d: Detections, t_s: float, eta: FloatArray) -> list[DetectionMsg]:
    """Split one slot's `Detections` [M] into per-UAV messages (eta [M]: shares in use)."""
    return [
        DetectionMsg(
            slot=d.slot,
            t_s=t_s,
            uav=m,
            range_m=float(d.range_m[m]),
            radial_velocity_mps=float(d.radial_velocity_mps[m]),
            uav_xy_m=np.asarray(d.uav_xy_m[m], dtype=float),
            bandwidth_share=float(eta[m]),
        )
        for m in range(len(d.range_m))
    ]


def _pairs(values: Any, where: str) -> FloatArray:
    """values as a float array [k, 2] ([0, 2] when empty); MessageError naming `where` if it is
    not one."""
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return np.zeros((0, 2))
    if a.ndim != 2 or a.shape[1] != 2:
        raise MessageError(f"{where}: shape {a.shape}, expected (k, 2)")
    return a


def encode_detection_set(msg: DetectionSetMsg) -> bytes:
    """Payload of `isac/<mission>/detections/<m>` on a multi-target mission: measurements [k, 2]
    as k [range, radial velocity] pairs (k = 0: an empty list)."""
    obj = envelope("detection_set", msg.slot, msg.t_s)
    obj.update(
        uav=int(msg.uav),
        measurements=[
            finite_floats(row, f"detection_set.measurements[{i}]")
            for i, row in enumerate(_pairs(msg.measurements, "detection_set.measurements"))
        ],
        uav_xy_m=finite_floats(msg.uav_xy_m, "detection_set.uav_xy_m"),
        bandwidth_share=float(msg.bandwidth_share),
    )
    data = dumps(obj)
    decode_detection_set(data)
    return data


def _detection_set(w: DetectionSetWire) -> DetectionSetMsg:
    return DetectionSetMsg(
        slot=w.slot,
        t_s=w.t,
        uav=w.uav,
        measurements=np.array(w.measurements, dtype=float).reshape(len(w.measurements), 2),
        uav_xy_m=np.array(w.uav_xy_m, dtype=float),
        bandwidth_share=w.bandwidth_share,
    )


def decode_detection_set(payload: Payload, *, n_uavs: int | None = None) -> DetectionSetMsg:
    """Validate a detection_set payload: at most MAX_MEASUREMENTS [range >= 0, radial velocity]
    pairs (possibly none); n_uavs, when given, bounds the UAV index (< n_uavs)."""
    obj = loads(payload)
    return _detection_set(_validate(DetectionSetWire, "detection_set", obj, {"n_uavs": n_uavs}))


def detection_set_messages(
    slot: int,
    t_s: float,
    measurements_per_uav: Sequence[FloatArray],
    uav_xy_m: FloatArray,
    eta: FloatArray,
) -> list[DetectionSetMsg]:
    """One slot's unlabelled reports as per-UAV messages: measurements_per_uav [M] of [k_m, 2]
    (range m, radial velocity m/s), uav_xy_m [M, 2] where each measured, eta [M] shares in use."""
    return [
        DetectionSetMsg(
            slot=slot,
            t_s=t_s,
            uav=m,
            measurements=_pairs(z, f"detection_set.measurements (uav {m})"),
            uav_xy_m=np.asarray(uav_xy_m[m], dtype=float),
            bandwidth_share=float(eta[m]),
        )
        for m, z in enumerate(measurements_per_uav)
    ]


def collect_detections(slot: int, msgs: Iterable[DetectionMsg], n_uavs: int) -> Detections:
    """Assemble the messages of one slot into `Detections` [M]; absent UAVs get NaN and NaN xy.

    Messages of other slots are ignored; for a UAV sent twice the last message wins.
    """
    rng = np.full(n_uavs, np.nan)
    vel = np.full(n_uavs, np.nan)
    xy = np.full((n_uavs, 2), np.nan)
    for msg in msgs:
        if msg.slot != slot or not 0 <= msg.uav < n_uavs:
            continue
        rng[msg.uav] = msg.range_m
        vel[msg.uav] = msg.radial_velocity_mps
        xy[msg.uav] = msg.uav_xy_m
    return Detections(slot=slot, range_m=rng, radial_velocity_mps=vel, uav_xy_m=xy)


# --------------------------------------------------------------------------- clock, truth


def encode_clock(msg: ClockMsg) -> bytes:
    """Payload of `isac/<mission>/clock`."""
    obj = envelope("clock", msg.slot, msg.t_s)
    obj.update(
        slot_s=float(msg.slot_s),
        speed=float(msg.speed),
        mission_t0=None if msg.mission_t0_s is None else float(msg.mission_t0_s),
    )
    data = dumps(obj)
    decode_clock(data)
    return data


def _clock(w: ClockWire) -> ClockMsg:
    return ClockMsg(slot=w.slot, t_s=w.t, slot_s=w.slot_s, speed=w.speed, mission_t0_s=w.mission_t0)


def decode_clock(payload: Payload) -> ClockMsg:
    """Validate a clock payload (slot may be -1: the mission has not started)."""
    return _clock(_validate(ClockWire, "clock", loads(payload), {}))


def encode_truth(msg: TruthMsg) -> bytes:
    """Payload of `isac/<mission>/truth`."""
    obj = envelope("truth", msg.slot, msg.t_s)
    obj["target_x"] = finite_floats(msg.target_x, "truth.target_x")
    data = dumps(obj)
    decode_truth(data)
    return data


def _truth(w: TruthWire) -> TruthMsg:
    return TruthMsg(slot=w.slot, t_s=w.t, target_x=np.array(w.target_x, dtype=float))


def decode_truth(payload: Payload) -> TruthMsg:
    """Validate a truth payload: target_x is [x, y, vx, vy]."""
    return _truth(_validate(TruthWire, "truth", loads(payload), {}))


def encode_truth_set(msg: TruthSetMsg) -> bytes:
    """Payload of `isac/<mission>/truth` on a multi-target mission: a NaN row of states [T, 4]
    (a target not in the scene) is sent as null; origins as lists of target indices."""
    states = np.asarray(msg.states, dtype=float)
    if states.size == 0:
        states = np.zeros((0, 4))
    if states.ndim != 2 or states.shape[1] != 4:
        raise MessageError(f"truth_set.targets: shape {states.shape}, expected (T, 4)")
    obj = envelope("truth_set", msg.slot, msg.t_s)
    obj.update(
        targets=[
            None if np.isnan(row).all() else finite_floats(row, f"truth_set.targets[{i}]")
            for i, row in enumerate(states)
        ],
        origins=[[int(k) for k in of_uav] for of_uav in msg.origins],
    )
    data = dumps(obj)
    decode_truth_set(data)
    return data


def _truth_set(w: TruthSetWire) -> TruthSetMsg:
    states = np.full((len(w.targets), 4), np.nan)
    for i, x in enumerate(w.targets):
        if x is not None:
            states[i] = x
    return TruthSetMsg(
        slot=w.slot, t_s=w.t, states=states, origins=tuple(tuple(o) for o in w.origins)
    )


def decode_truth_set(payload: Payload) -> TruthSetMsg:
    """Validate a truth_set payload: at most MAX_TARGETS [x, y, vx, vy] or null; origins (optional)
    at most MAX_UAVS lists of -1 (false alarm) to MAX_TARGETS - 1."""
    return _truth_set(_validate(TruthSetWire, "truth_set", loads(payload), {}))


# --------------------------------------------------------------------------- plan


def encode_plan(msg: PlanMsg) -> bytes:
    """Payload of `isac/<mission>/plan` (objective NaN is sent as null)."""
    p = msg.plan
    obj = envelope("plan", msg.slot, msg.t_s)
    obj.update(
        assoc=[int(k) for k in np.asarray(p.bs_of_uav).ravel()],
        bandwidth_share=finite_floats(p.bandwidth_share, "plan.bandwidth_share"),
        waypoints_xy_m=[
            finite_floats(row, f"plan.waypoints_xy_m[{i}]")
            for i, row in enumerate(np.asarray(p.uav_xy_m))
        ],
        objective=finite_or_none(p.pcrb_trace),
        status=p.report.status,
        reason=p.report.reason,
        solve_s=float(p.report.solve_s),
    )
    if p.uav_velocity_mps is not None:
        obj["end_velocity_mps"] = [
            finite_floats(row, f"plan.end_velocity_mps[{i}]")
            for i, row in enumerate(np.asarray(p.uav_velocity_mps))
        ]
    data = dumps(obj)
    decode_plan(data)
    return data


def _plan(w: PlanWire) -> PlanMsg:
    plan = SlotPlan(
        uav_xy_m=np.array(w.waypoints_xy_m, dtype=float).reshape(len(w.assoc), 2),
        bs_of_uav=np.array(w.assoc, dtype=np.int64),
        bandwidth_share=np.array(w.bandwidth_share, dtype=float),
        pcrb_trace=_nan(w.objective),
        report=SolveReport(status=w.status, reason=w.reason, solve_s=w.solve_s),
        uav_velocity_mps=None
        if w.end_velocity_mps is None
        else np.array(w.end_velocity_mps, dtype=float).reshape(len(w.assoc), 2),
    )
    return PlanMsg(slot=w.slot, t_s=w.t, plan=plan)


def decode_plan(payload: Payload, *, n_uavs: int | None = None, n_bs: int | None = None) -> PlanMsg:
    """Validate a plan payload.

    Checks: assoc, bandwidth_share and waypoints_xy_m have the same length M (= n_uavs when
    given, 1 <= M <= MAX_UAVS); assoc entries are BS indices in [0, n_bs), or -1 for a vehicle
    outside the plan (link lost; its share must then be 0); shares lie in [0, 1]
    and sum to 1 within SHARE_SUM_TOL; waypoints are finite [M, 2]; end_velocity_mps, when
    present (optional: older plans have none), finite [M, 2]; objective is >= 0 or null;
    status is a non-empty string; solve_s >= 0. reason is optional ("" when absent).
    """
    obj = loads(payload)
    return _plan(_validate(PlanWire, "plan", obj, {"n_uavs": n_uavs, "n_bs": n_bs}))


# --------------------------------------------------------------------------- telemetry, track


def encode_telemetry(msg: TelemetryMsg) -> bytes:
    """Payload of `isac/<mission>/telemetry/<m>`."""
    obj = envelope("telemetry", msg.slot, msg.t_s)
    obj.update(
        uav=int(msg.uav),
        position_xy_m=finite_floats(msg.position_xy_m, "telemetry.position_xy_m"),
        altitude_m=float(msg.altitude_m),
        velocity_xy_mps=finite_floats(msg.velocity_xy_mps, "telemetry.velocity_xy_mps"),
        mode=msg.mode,
        armed=bool(msg.armed),
        landed=bool(msg.landed),
        link=msg.link,
        override=msg.override[:MAX_STATUS_CHARS],
    )
    if msg.published_wall_s is not None:
        obj["published_wall_s"] = float(msg.published_wall_s)
    data = dumps(obj)
    decode_telemetry(data)
    return data


def _telemetry(w: TelemetryWire) -> TelemetryMsg:
    return TelemetryMsg(
        slot=w.slot,
        t_s=w.t,
        uav=w.uav,
        position_xy_m=np.array(w.position_xy_m, dtype=float),
        altitude_m=w.altitude_m,
        velocity_xy_mps=np.array(w.velocity_xy_mps, dtype=float),
        mode=w.mode,
        armed=w.armed,
        landed=w.landed,
        link=w.link,
        published_wall_s=w.published_wall_s,
        override=w.override,
    )


def decode_telemetry(payload: Payload, *, n_uavs: int | None = None) -> TelemetryMsg:
    """Validate a telemetry payload (uav in [0, n_uavs) when n_uavs is given)."""
    obj = loads(payload)
    return _telemetry(_validate(TelemetryWire, "telemetry", obj, {"n_uavs": n_uavs}))


def encode_track(msg: TrackMsg) -> bytes:
    """Payload of `isac/<mission>/track`."""
    obj = envelope("track", msg.slot, msg.t_s)
    obj.update(
        x=finite_floats(msg.x, "track.x"),
        P=[finite_floats(r, f"track.P[{i}]") for i, r in enumerate(np.asarray(msg.P))],
        J=[finite_floats(r, f"track.J[{i}]") for i, r in enumerate(np.asarray(msg.J))],
        pcrb_trace=float(msg.pcrb_trace),
    )
    if msg.published_wall_s is not None:
        obj["published_wall_s"] = float(msg.published_wall_s)
    data = dumps(obj)
    decode_track(data)
    return data


def _track(w: TrackWire) -> TrackMsg:
    return TrackMsg(
        slot=w.slot,
        t_s=w.t,
        x=np.array(w.x, dtype=float),
        P=np.array(w.P, dtype=float),
        J=np.array(w.J, dtype=float),
        pcrb_trace=w.pcrb_trace,
        published_wall_s=w.published_wall_s,
    )


def decode_track(payload: Payload) -> TrackMsg:
    """Validate a track payload."""
    return _track(_validate(TrackWire, "track", loads(payload), {}))


def encode_track_set(msg: TrackSetMsg) -> bytes:
    """Payload of `isac/<mission>/track` on a multi-target mission."""
    obj = envelope("track_set", msg.slot, msg.t_s)
    obj["tracks"] = [
        {
            "id": int(e.track_id),
            "confirmed": bool(e.confirmed),
            "x": finite_floats(e.x, f"track_set.tracks[{i}].x"),
            "P": [
                finite_floats(r, f"track_set.tracks[{i}].P[{j}]")
                for j, r in enumerate(np.asarray(e.P))
            ],
            "pcrb_position_trace": float(e.pcrb_position_trace),
        }
        for i, e in enumerate(msg.tracks)
    ]
    if msg.published_wall_s is not None:
        obj["published_wall_s"] = float(msg.published_wall_s)
    data = dumps(obj)
    decode_track_set(data)
    return data


def _track_set(w: TrackSetWire) -> TrackSetMsg:
    return TrackSetMsg(
        slot=w.slot,
        t_s=w.t,
        tracks=tuple(
            TrackEntry(
                track_id=e.id,
                confirmed=e.confirmed,
                x=np.array(e.x, dtype=float),
                P=np.array(e.P, dtype=float),
                pcrb_position_trace=e.pcrb_position_trace,
            )
            for e in w.tracks
        ),
        published_wall_s=w.published_wall_s,
    )


def decode_track_set(payload: Payload) -> TrackSetMsg:
    """Validate a track_set payload: at most MAX_TRACKS tracks, ids 1 to 10^9 and distinct."""
    return _track_set(_validate(TrackSetWire, "track_set", loads(payload), {}))


# --------------------------------------------------------------------------- health


def encode_health(msg: HealthMsg) -> bytes:
    """Payload of `isac/<mission>/health`."""
    obj = envelope("health", msg.slot, msg.t_s)
    obj.update(
        status=msg.status,
        counters={str(k): int(v) for k, v in msg.counters.items()},
        last_error=msg.last_error[:MAX_REASON_CHARS],
        vehicles={str(m): state[:MAX_STATUS_CHARS] for m, state in msg.vehicles.items()},
    )
    data = dumps(obj)
    decode_health(data)
    return data


def _health(w: HealthWire) -> HealthMsg:
    return HealthMsg(
        slot=w.slot,
        t_s=w.t,
        status=w.status,
        counters={k[:MAX_STATUS_CHARS]: v for k, v in w.counters.items()},
        last_error=w.last_error,
        vehicles={int(k): v[:MAX_STATUS_CHARS] for k, v in w.vehicles.items()},
    )


def decode_health(payload: Payload) -> HealthMsg:
    """Validate a health payload."""
    return _health(_validate(HealthWire, "health", loads(payload), {}))


# --------------------------------------------------------------------------- dispatch


_CONVERT: Final[dict[type[BaseModel], Any]] = {
    DetectionWire: _detection,
    DetectionSetWire: _detection_set,
    ClockWire: _clock,
    TruthWire: _truth,
    TruthSetWire: _truth_set,
    PlanWire: _plan,
    TelemetryWire: _telemetry,
    TrackWire: _track,
    TrackSetWire: _track_set,
    HealthWire: _health,
    ControlWire: control_msg,
    ControlReplyWire: control_reply_msg,
    FleetWire: fleet_msg,
}


def decode_any(payload: Payload) -> AnyMsg:
    """Decode a payload of any type (`wire.models.WireMessage`), told apart by its "type"."""
    obj = loads(payload)
    kind = obj.get("type")
    if not isinstance(kind, str) or kind not in MODELS:
        raise MessageError(f"type: unknown payload type {kind!r}")
    model = MODELS[kind]
    try:
        wire = _ANY.validate_python(obj, strict=True, context={})
    except ValidationError as err:
        raise message_error(err, kind, model, tagged=True) from None
    result: AnyMsg = _CONVERT[type(wire)](wire)
    return result
