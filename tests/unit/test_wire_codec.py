"""isac_mission/wire (codec, models, refusal): round trips, and every malformed kind refused with its field."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from isac_mission import wire
from isac_mission.errors import MessageError
from isac_mission.types import Detections, SlotPlan, SolveReport
from isac_mission.wire import (
    ClockMsg,
    DetectionMsg,
    PlanMsg,
    TrackMsg,
    TruthMsg,
    collect_detections,
    decode,
    decode_any,
    detection_messages,
    encode,
)


def _detection(**kw: Any) -> DetectionMsg:
    base: dict[str, Any] = dict(
        slot=4,
        t_s=4.0,
        uav=1,
        range_m=812.25,
        radial_velocity_mps=-3.5,
        uav_xy_m=np.array([807.0, 1100.0]),
        bandwidth_share=0.25,
    )
    base.update(kw)
    return DetectionMsg(**base)


def _plan(m: int = 3, **kw: Any) -> PlanMsg:
    shares = np.array([0.5, 0.3, 0.2])[:m] if m == 3 else np.full(m, 1.0 / m)
    plan = SlotPlan(
        uav_xy_m=np.arange(2 * m, dtype=float).reshape(m, 2) * 100.0,
        bs_of_uav=np.arange(m, dtype=np.int64),
        bandwidth_share=shares,
        pcrb_trace=12.5,
        report=SolveReport(status="ok", reason="", solve_s=0.012),
    )
    base: dict[str, Any] = dict(slot=5, t_s=4.2, plan=plan)
    base.update(kw)
    return PlanMsg.from_plan(**base)


def _obj(data: bytes) -> dict[str, Any]:
    out: dict[str, Any] = json.loads(data)
    return out


def _bytes(obj: dict[str, Any]) -> bytes:
    return json.dumps(obj).encode()


# ----------------------------------------------------------------------------- round trips


def test_detection_round_trip() -> None:
    msg = _detection()
    data = encode(msg)
    obj = _obj(data)
    assert obj["schema"] == "isac/1" and obj["type"] == "detection"
    assert obj["slot"] == 4 and obj["t"] == 4.0
    back = decode(DetectionMsg, data, n_uavs=3)
    assert (back.slot, back.t_s, back.uav) == (4, 4.0, 1)
    assert back.range_m == msg.range_m and back.radial_velocity_mps == msg.radial_velocity_mps
    np.testing.assert_array_equal(back.uav_xy_m, msg.uav_xy_m)
    assert back.bandwidth_share == 0.25 and back.detected


def test_missed_detection_round_trips_as_null() -> None:
    data = encode(_detection(range_m=math.nan, radial_velocity_mps=math.nan))
    assert _obj(data)["range_m"] is None
    back = decode(DetectionMsg, data)
    assert math.isnan(back.range_m) and math.isnan(back.radial_velocity_mps)
    assert not back.detected


def test_clock_round_trip_before_and_after_mission_start() -> None:
    for msg in (
        ClockMsg(slot=-1, t_s=0.5, slot_s=1.0, speed=10.0, mission_t0_s=None),
        ClockMsg(slot=7, t_s=37.25, slot_s=1.0, speed=1.0, mission_t0_s=30.0),
    ):
        assert decode(ClockMsg, encode(msg)) == msg


def test_truth_round_trip() -> None:
    x = np.array([600.0, 1600.0, 30.0, -0.25])
    back = decode(TruthMsg, encode(TruthMsg(slot=3, t_s=3.0, target_x=x)))
    assert (back.slot, back.t_s) == (3, 3.0)
    np.testing.assert_array_equal(back.target_x, x)


def test_plan_round_trip() -> None:
    msg = _plan()
    back = decode(PlanMsg, encode(msg), n_uavs=3, n_bs=5)
    assert (back.slot, back.t_s) == (5, 4.2)
    np.testing.assert_array_equal(back.plan.uav_xy_m, msg.plan.uav_xy_m)
    np.testing.assert_array_equal(back.plan.bs_of_uav, msg.plan.bs_of_uav)
    np.testing.assert_array_equal(back.plan.bandwidth_share, msg.plan.bandwidth_share)
    assert back.plan.pcrb_trace == 12.5
    assert back.plan.report.status == "ok" and back.plan.report.solve_s == 0.012


def test_decode_any_dispatches_on_type() -> None:
    assert isinstance(decode_any(encode(_plan())), PlanMsg)
    assert isinstance(decode_any(encode(_detection())), DetectionMsg)


def test_slot_detections_split_and_reassemble() -> None:
    d = Detections(
        slot=2,
        range_m=np.array([100.0, np.nan, 300.0]),
        radial_velocity_mps=np.array([1.0, np.nan, -1.0]),
        uav_xy_m=np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]),
    )
    msgs = [decode(DetectionMsg, encode(m)) for m in detection_messages(d, 2.0, np.full(3, 1 / 3))]
    back = collect_detections(2, msgs[::2], 3)  # UAV 1's message did not arrive
    np.testing.assert_array_equal(back.received, [True, False, True])
    np.testing.assert_array_equal(back.range_m[[0, 2]], [100.0, 300.0])


# ----------------------------------------------------------------------------- malformed


def _expect(payload: bytes | str, field: str, kind: Any = DetectionMsg, **kw: Any) -> str:
    """The refusal of `payload` decoded as `kind` (a message model, or decode_any)."""
    with pytest.raises(MessageError) as info:
        decode(kind, payload, **kw) if isinstance(kind, type) else kind(payload, **kw)
    reason = str(info.value)
    assert reason.startswith(field), f"reason {reason!r} does not name {field!r}"
    return reason


def test_not_json_is_refused() -> None:
    _expect(b"{not json", "payload: not JSON")
    _expect(b"\xff\xfe", "payload: not UTF-8")
    _expect(b"[1, 2]", "payload: expected a JSON object")


def test_wrong_schema_or_version_is_refused() -> None:
    obj = _obj(encode(_detection()))
    assert "version" in _expect(_bytes({**obj, "schema": "isac/2"}), "schema")
    _expect(_bytes({**obj, "schema": "other"}), "schema")
    del obj["schema"]
    _expect(_bytes(obj), "schema")


def test_wrong_type_is_refused() -> None:
    _expect(encode(TruthMsg(1, 1.0, np.zeros(4))), "type", DetectionMsg)
    _expect(b'{"schema": "isac/1", "type": "bogus", "slot": 0, "t": 0}', "type", decode_any)


@pytest.mark.parametrize(
    ("raw", "field"),
    [
        ('"range_m": NaN', "payload"),  # NaN literal
        ('"range_m": Infinity', "payload"),
        ('"range_m": -Infinity', "payload"),
        ('"range_m": 1e400', "detection.range_m"),  # overflows to inf
        ('"range_m": 1e12', "detection.range_m"),  # finite but absurd
        ('"range_m": ' + "9" * 40, "detection.range_m"),  # huge integer
        ('"range_m": ' + "9" * 5000, "payload"),  # beyond Python's int parsing limit
        ('"range_m": true', "detection.range_m"),  # a bool is not a number
        ('"range_m": "812"', "detection.range_m"),
        ('"range_m": -1.0', "detection.range_m"),  # ranges are >= 0
        ('"bandwidth_share": 1.5', "detection.bandwidth_share"),
        ('"uav": 1.0', "detection.uav"),
        ('"uav": 7', "detection.uav"),  # n_uavs = 3
        ('"slot": -1', "detection.slot"),
        ('"t": NaN', "payload"),
    ],
)
def test_bad_numbers_are_refused(raw: str, field: str) -> None:
    text = encode(_detection()).decode()
    key = raw.split(":")[0]
    obj = _obj(text.encode())
    start = text.index(key)
    end = text.index(",", start) if text.find(",", start) != -1 else text.index("}", start)
    old = f"{key}:{json.dumps(obj[key.strip(chr(34))])}"
    assert text[start:end] == old
    bad = text[:start] + raw + text[end:]
    _expect(bad.encode(), field, n_uavs=3)


def test_wrong_sizes_are_refused() -> None:
    det = _obj(encode(_detection()))
    _expect(_bytes({**det, "uav_xy_m": [1.0, 2.0, 3.0]}), "detection.uav_xy_m")
    _expect(_bytes({**det, "uav_xy_m": 5.0}), "detection.uav_xy_m")
    truth = _obj(encode(TruthMsg(1, 1.0, np.zeros(4))))
    _expect(_bytes({**truth, "target_x": [0.0] * 3}), "truth.target_x", TruthMsg)
    plan = _obj(encode(_plan()))
    _expect(_bytes({**plan, "bandwidth_share": [0.5, 0.5]}), "plan.bandwidth_share", PlanMsg)
    _expect(
        _bytes({**plan, "waypoints_xy_m": [[0.0, 0.0], [1.0, 1.0]]}),
        "plan.waypoints_xy_m",
        PlanMsg,
    )
    _expect(
        _bytes({**plan, "waypoints_xy_m": [[0.0, 0.0, 0.0]] * 3}),
        "plan.waypoints_xy_m[0]",
        PlanMsg,
    )
    _expect(encode(_plan()), "plan.assoc", PlanMsg, n_uavs=4)
    _expect(_bytes({**plan, "assoc": []}), "plan.assoc", PlanMsg)


def test_plan_contents_are_checked() -> None:
    plan = _obj(encode(_plan()))
    assert "sums to" in _expect(
        _bytes({**plan, "bandwidth_share": [0.5, 0.5, 0.5]}), "plan.bandwidth_share", PlanMsg
    )
    _expect(
        _bytes({**plan, "bandwidth_share": [1.2, -0.1, -0.1]}),
        "plan.bandwidth_share[0]",
        PlanMsg,
    )
    _expect(encode(_plan()), "plan.assoc[2]", PlanMsg, n_bs=2)
    _expect(_bytes({**plan, "status": ""}), "plan.status", PlanMsg)
    _expect(_bytes({**plan, "status": 3}), "plan.status", PlanMsg)
    _expect(_bytes({**plan, "solve_s": -1}), "plan.solve_s", PlanMsg)
    _expect(_bytes({**plan, "objective": -2.0}), "plan.objective", PlanMsg)
    missing = dict(plan)
    del missing["waypoints_xy_m"]
    assert "missing" in _expect(_bytes(missing), "plan.waypoints_xy_m", PlanMsg)


def test_too_long_payload_is_refused() -> None:
    det = _obj(encode(_detection()))
    det["padding"] = "x" * wire.MAX_PAYLOAD_BYTES
    assert "bytes" in _expect(_bytes(det), "payload")


def test_encoders_refuse_what_decoders_would_refuse() -> None:
    with pytest.raises(MessageError, match="bandwidth_share"):
        encode(_detection(bandwidth_share=2.0))
    with pytest.raises(MessageError, match="target_x"):
        encode(TruthMsg(1, 1.0, np.array([0.0, np.inf, 0.0, 0.0])))


def test_track_carries_information_far_beyond_the_position_bound() -> None:
    """PCRB information reaches 1e9 m^-2 with a UAV near the target (found by the 3600-slot
    soak, where it ended the run) and 1e20 with the literal eq. 8: a track must carry it."""
    for scale in (2.7e9, 1e20):
        J = np.diag([scale, scale, 1.0, 1.0])
        msg = TrackMsg(7, 7.0, np.zeros(4), np.linalg.inv(J), J, 2.0 / scale)
        back = decode(TrackMsg, encode(msg))
        np.testing.assert_array_equal(back.J, J)
    bad = encode(TrackMsg(7, 7.0, np.zeros(4), np.eye(4), np.eye(4), 1.0))
    with pytest.raises(MessageError, match=r"track\.J"):
        decode(TrackMsg, bad.replace(b'"J":[[1.0', b'"J":[[1e300', 1))
    with pytest.raises(MessageError, match=r"track\.x"):
        decode(TrackMsg, bad.replace(b'"x":[0.0', b'"x":[2e9', 1))


# ----------------------------------------------------------------------------- models


def test_an_array_of_the_wrong_length_is_refused_as_such_whatever_it_holds() -> None:
    truth = _obj(encode(TruthMsg(1, 1.0, np.zeros(4))))
    reason = _expect(_bytes({**truth, "target_x": [True, "x"]}), "truth.target_x", TruthMsg)
    assert reason == "truth.target_x: 2 values, expected 4"
    track = _obj(encode(TrackMsg(7, 7.0, np.zeros(4), np.eye(4), np.eye(4), 1.0)))
    reason = _expect(_bytes({**track, "P": [[1.0] * 4] * 3}), "track.P", TrackMsg)
    assert reason == "track.P: 3 values, expected 4"


def test_the_receivers_sizes_bound_the_indices_with_the_old_texts() -> None:
    det = _obj(encode(_detection()))
    reason = _expect(_bytes({**det, "uav": -5}), "detection.uav", n_uavs=3)
    assert reason == "detection.uav: -5 is outside [0, 2]"
    reason = _expect(_bytes({**det, "range_m": -1e10}), "detection.range_m")
    assert reason == "detection.range_m: -1e+10 is too large (limit 1e+09)"
    plan = _obj(encode(_plan()))
    reason = _expect(_bytes({**plan, "assoc": [0, 1, 9]}), "plan.assoc[2]", PlanMsg, n_bs=5)
    assert reason == "plan.assoc[2]: 9 is outside [-1, 4]"


def test_health_and_control_round_trip_and_are_checked() -> None:
    health = wire.HealthMsg(3, 3.0, "ok", {"slots": 3}, "", {0: "active", 2: "excluded: lost"})
    assert wire.decode(wire.HealthMsg, wire.encode(health)) == health
    obj = _obj(wire.encode(health))
    _expect(_bytes({**obj, "counters": {"x": -1}}), "health.counters.x", wire.HealthMsg)
    _expect(_bytes({**obj, "vehicles": {"a": "active"}}), "health.vehicles.a", wire.HealthMsg)
    control = wire.ControlMsg.set_params(-1, 0.5, "r-1", rate_min_mbps=2.0)
    assert wire.decode(wire.ControlMsg, wire.encode(control)) == control
    assert wire.decode_any(wire.encode(control)) == control
    obj = _obj(wire.encode(control))
    reason = _expect(_bytes({**obj, "command": "go"}), "control.command", wire.ControlMsg)
    assert reason.startswith("control.command: 'go' is not a command (expected one of [")
    _expect(_bytes({**obj, "params": {"x": 1}}), "control.params.x", wire.ControlMsg)
    _expect(_bytes({**obj, "params": {"rate_min_mbps": 0}}), "control.params", wire.ControlMsg)


def test_decode_any_names_the_field_of_the_message_it_recognised() -> None:
    plan = _obj(encode(_plan()))
    _expect(_bytes({**plan, "solve_s": -1}), "plan.solve_s", decode_any)
    _expect(_bytes({**plan, "schema": "isac/2"}), "schema", decode_any)
    telemetry = _obj(
        wire.encode(
            wire.TelemetryMsg(-1, 1.0, 0, np.zeros(2), 5.0, np.zeros(2), "hold", True, False, "ok")
        )
    )
    reason = _expect(_bytes({**telemetry, "mode": "flying"}), "telemetry.mode", decode_any)
    assert "'flying' is not one of" in reason


def test_telemetry_and_track_carry_an_optional_wall_clock_publish_stamp() -> None:
    """published_wall_s (Unix time, s) round-trips, may be absent, and is checked like a field."""
    tel = wire.TelemetryMsg(
        4, 4.0, 1, np.array([1.0, 2.0]), 30.0, np.array([0.5, 0.0]), "offboard", True, False, "ok"
    )
    assert "published_wall_s" not in _obj(wire.encode(tel))
    assert wire.decode(wire.TelemetryMsg, wire.encode(tel)).published_wall_s is None
    stamped = wire.TelemetryMsg(**{**tel.__dict__, "published_wall_s": 1.8e9 + 0.25})
    assert wire.decode(wire.TelemetryMsg, wire.encode(stamped)).published_wall_s == 1.8e9 + 0.25
    obj = _obj(wire.encode(stamped))
    for bad in ("now", -1.0, True, 1e12):
        _expect(
            _bytes({**obj, "published_wall_s": bad}),
            "telemetry.published_wall_s",
            wire.TelemetryMsg,
        )
    track = TrackMsg(7, 7.0, np.zeros(4), np.eye(4), np.eye(4), 1.0, published_wall_s=1.9e9)
    assert decode(TrackMsg, encode(track)).published_wall_s == 1.9e9
    assert (
        decode(
            TrackMsg, encode(TrackMsg(7, 7.0, np.zeros(4), np.eye(4), np.eye(4), 1.0))
        ).published_wall_s
        is None
    )


# ----------------------------------------------------------------------------- the messages


def test_a_message_built_in_code_holds_what_it_is_given_and_encode_checks_it() -> None:
    """Building never fails (a loop must be able to count a message it cannot publish); the
    encoder refuses it by field."""
    bad = TrackMsg(7, 7.0, np.array([np.nan, 0.0, 0.0, 0.0]), np.eye(4), np.eye(4), -1.0)
    assert math.isnan(bad.x[0]) and bad.pcrb_trace == -1.0
    with pytest.raises(MessageError, match=r"^track\.x\[0\]: nan is not finite$"):
        encode(bad)
    with pytest.raises(MessageError, match=r"^track\.pcrb_trace: -1 is below 0$"):
        encode(TrackMsg(7, 7.0, np.zeros(4), np.eye(4), np.eye(4), -1.0))
    with pytest.raises(MessageError, match=r"^detection: cannot encode"):
        encode(_detection(uav=math.nan))


def test_positional_and_keyword_construction_as_a_dataclass() -> None:
    assert TruthMsg(3, 3.0, np.zeros(4)).kind() == "truth"
    assert TruthMsg(3, 3.0, np.zeros(4)).slot == TruthMsg(slot=3, t_s=3.0, target_x=[]).slot
    for args, kw in (((3, 3.0), {}), ((3, 3.0, np.zeros(4)), {"slot": 4}), ((), {"t": 1.0})):
        with pytest.raises(TypeError):
            TruthMsg(*args, **kw)
    with pytest.raises(ValueError, match="frozen"):
        TruthMsg(3, 3.0, np.zeros(4)).slot = 4  # type: ignore[misc]


def test_a_payload_is_validated_by_its_wire_names_only() -> None:
    obj = _obj(encode(_detection()))
    obj["t_s"] = obj.pop("t")
    assert _expect(_bytes(obj), "detection.t") == "detection.t: missing"
    assert DetectionMsg.model_validate(_obj(encode(_detection())), strict=True).t_s == 4.0


def test_decode_takes_a_model_or_its_type_name() -> None:
    data = encode(_plan())
    by_name, by_model = decode("plan", data, n_uavs=3), decode(PlanMsg, data, n_uavs=3)
    assert isinstance(by_name, PlanMsg) and encode(by_name) == encode(by_model) == data
    _expect(data, "type: expected 'detection', got 'plan'", DetectionMsg)


def test_a_plan_message_is_made_of_and_gives_a_slot_plan() -> None:
    msg = _plan()
    back = decode(PlanMsg, encode(msg)).plan
    np.testing.assert_array_equal(back.uav_xy_m, msg.waypoints_xy_m)
    assert back.bs_of_uav.dtype == np.int64 and back.report.status == "ok"
    assert back.uav_velocity_mps is None and back.pcrb_trace == 12.5


def test_the_readme_operator_calls_still_work_with_a_deprecation_warning() -> None:
    msg = wire.ControlMsg(-1, 0.0, "op-1", "hold", uav=1)
    with pytest.warns(DeprecationWarning, match="encode_control is deprecated"):
        assert wire.encode_control(msg) == encode(msg)
    reply = wire.ControlReplyMsg(0, 1.0, "op-1", "hold", True, "ok", "held", (1,))
    with pytest.warns(DeprecationWarning, match="decode_control_reply is deprecated"):
        assert wire.decode_control_reply(encode(reply)) == reply
