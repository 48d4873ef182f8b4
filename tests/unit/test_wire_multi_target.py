"""isac_mission/wire: the multi-target messages `detection_set`, `truth_set` and `track_set`
(docs/bus.md): round trips, every malformed kind refused with its field, their JSON Schemas."""

from __future__ import annotations

import json
from functools import partial
from typing import Any

import numpy as np
import pytest

from isac_mission import wire
from isac_mission.errors import MessageError
from isac_mission.wire import (
    MAX_MEASUREMENTS,
    MAX_PAYLOAD_BYTES,
    MAX_TARGETS,
    MAX_TRACKS,
    DetectionSetMsg,
    TrackEntry,
    TrackSetMsg,
    TruthSetMsg,
    decode,
    decode_any,
    detection_set_messages,
    encode,
)
from isac_mission.wire.schema import message_schemas


def _detection_set(**kw: Any) -> DetectionSetMsg:
    base: dict[str, Any] = dict(
        slot=4,
        t_s=4.0,
        uav=1,
        measurements=np.array([[812.25, -3.5], [1200.0, 7.25], [95.5, 0.0]]),
        uav_xy_m=np.array([807.0, 1100.0]),
        bandwidth_share=0.25,
    )
    base.update(kw)
    return DetectionSetMsg(**base)


def _truth_set(**kw: Any) -> TruthSetMsg:
    base: dict[str, Any] = dict(
        slot=4,
        t_s=4.0,
        states=np.array([[600.0, 1600.0, 30.0, -0.25], [np.nan] * 4, [-50.0, 20.0, 0.0, 12.5]]),
        origins=((0, -1, 2), (), (-1,)),
    )
    base.update(kw)
    return TruthSetMsg(**base)


def _entry(track_id: int, confirmed: bool = True, scale: float = 1.0) -> TrackEntry:
    P = np.diag([25.0, 25.0, 4.0, 4.0]) * scale
    P[0, 2] = P[2, 0] = -1.5 * scale
    return TrackEntry(
        track_id=track_id,
        confirmed=confirmed,
        x=np.array([610.5, 1590.25, 29.5, -0.5]) + track_id,
        P=P,
        pcrb_position_trace=12.75 * scale,
    )


def _track_set(**kw: Any) -> TrackSetMsg:
    base: dict[str, Any] = dict(
        slot=7, t_s=7.0, tracks=(_entry(1), _entry(4, confirmed=False, scale=1e6))
    )
    base.update(kw)
    return TrackSetMsg(**base)


def _obj(data: bytes) -> dict[str, Any]:
    out: dict[str, Any] = json.loads(data)
    return out


def _bytes(obj: dict[str, Any]) -> bytes:
    return json.dumps(obj).encode()


def _expect(payload: bytes | str, field: str, decode: Any, **kw: Any) -> str:
    with pytest.raises(MessageError) as info:
        decode(payload, **kw)
    reason = str(info.value)
    assert reason.startswith(field), f"reason {reason!r} does not name {field!r}"
    return reason


def _assert_same_tracks(a: TrackSetMsg, b: TrackSetMsg) -> None:
    assert (a.slot, a.t_s, a.published_wall_s) == (b.slot, b.t_s, b.published_wall_s)
    assert len(a.tracks) == len(b.tracks)
    for ea, eb in zip(a.tracks, b.tracks, strict=True):
        assert (ea.track_id, ea.confirmed) == (eb.track_id, eb.confirmed)
        assert ea.pcrb_position_trace == eb.pcrb_position_trace
        np.testing.assert_array_equal(ea.x, eb.x)
        np.testing.assert_array_equal(ea.P, eb.P)


# ----------------------------------------------------------------------------- round trips


def test_detection_set_round_trip() -> None:
    msg = _detection_set()
    data = encode(msg)
    obj = _obj(data)
    assert obj["schema"] == "isac/1" and obj["type"] == "detection_set"
    assert obj["measurements"] == [[812.25, -3.5], [1200.0, 7.25], [95.5, 0.0]]
    back = decode(DetectionSetMsg, data, n_uavs=3)
    assert (back.slot, back.t_s, back.uav, back.bandwidth_share) == (4, 4.0, 1, 0.25)
    assert back.measurements.dtype == np.float64
    np.testing.assert_array_equal(back.measurements, msg.measurements)
    np.testing.assert_array_equal(back.uav_xy_m, msg.uav_xy_m)


def test_an_empty_detection_set_is_sent_and_decodes_to_zero_rows() -> None:
    for empty in (np.zeros((0, 2)), np.array([])):
        data = encode(_detection_set(measurements=empty))
        assert _obj(data)["measurements"] == []
        assert decode(DetectionSetMsg, data).measurements.shape == (0, 2)


def test_detection_set_messages_split_a_slot_per_uav() -> None:
    reports = [np.array([[100.0, 1.0], [250.0, -2.0]]), np.zeros((0, 2)), np.array([[3.0, 0.5]])]
    xy = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
    msgs = detection_set_messages(2, 2.5, reports, xy, np.array([0.5, 0.25, 0.25]))
    assert [m.uav for m in msgs] == [0, 1, 2]
    for m, msg in enumerate(msgs):
        back = decode(DetectionSetMsg, encode(msg), n_uavs=3)
        assert (back.slot, back.t_s, back.bandwidth_share) == (2, 2.5, [0.5, 0.25, 0.25][m])
        np.testing.assert_array_equal(back.measurements, reports[m].reshape(-1, 2))
        np.testing.assert_array_equal(back.uav_xy_m, xy[m])


def test_truth_set_round_trip_with_null_targets_and_origins() -> None:
    msg = _truth_set()
    data = encode(msg)
    obj = _obj(data)
    assert obj["type"] == "truth_set"
    assert obj["targets"][1] is None  # a target not in the scene
    assert obj["origins"] == [[0, -1, 2], [], [-1]]
    back = decode(TruthSetMsg, data)
    assert (back.slot, back.t_s) == (4, 4.0)
    assert back.states.shape == (3, 4)
    np.testing.assert_array_equal(back.states, msg.states)  # NaN rows compare equal
    assert np.isnan(back.states[1]).all() and np.isfinite(back.states[[0, 2]]).all()
    assert back.origins == ((0, -1, 2), (), (-1,))


def test_truth_set_origins_are_optional() -> None:
    obj = _obj(encode(_truth_set(origins=())))
    assert obj["origins"] == []
    del obj["origins"]
    assert decode(TruthSetMsg, _bytes(obj)).origins == ()


def test_track_set_round_trip() -> None:
    for msg in (_track_set(), _track_set(published_wall_s=1.9e9 + 0.25), _track_set(tracks=())):
        data = encode(msg)
        obj = _obj(data)
        assert obj["type"] == "track_set"
        assert ("published_wall_s" in obj) == (msg.published_wall_s is not None)
        _assert_same_tracks(decode(TrackSetMsg, data), msg)
    first = _obj(encode(_track_set()))["tracks"][0]
    assert set(first) == {"id", "confirmed", "x", "P", "pcrb_position_trace"}
    assert first["id"] == 1 and first["confirmed"] is True


def test_decode_any_returns_the_multi_target_classes() -> None:
    back = decode_any(encode(_detection_set()))
    assert isinstance(back, DetectionSetMsg)
    np.testing.assert_array_equal(back.measurements, _detection_set().measurements)
    assert isinstance(decode_any(encode(_truth_set())), TruthSetMsg)
    track_set = decode_any(encode(_track_set()))
    assert isinstance(track_set, TrackSetMsg)
    _assert_same_tracks(track_set, _track_set())
    # The single-target messages on the same keys still decode as before.
    assert isinstance(decode_any(wire.encode(wire.TruthMsg(1, 1.0, np.zeros(4)))), wire.TruthMsg)


def test_the_largest_messages_fit_the_payload_limit() -> None:
    """64 tracks and 512 measurements with full-precision numbers fit in MAX_PAYLOAD_BYTES."""
    rng = np.random.default_rng(7)
    tracks = []
    for i in range(MAX_TRACKS):
        a = rng.normal(size=(4, 4)) * rng.uniform(1e-3, 1e3)
        tracks.append(
            TrackEntry(
                track_id=999_999_000 + i,
                confirmed=bool(i % 2),
                x=-rng.uniform(1e3, 1e4, 4) - 1 / 3,
                P=-(a @ a.T) * 1e-7,
                pcrb_position_trace=123456.78901234567,
            )
        )
    big = TrackSetMsg(10**9, 1e9 - 1 / 3, tuple(tracks), 1.8e9 + 1 / 3)
    data = encode(big)
    assert len(data) < 0.6 * MAX_PAYLOAD_BYTES
    _assert_same_tracks(decode(TrackSetMsg, data), big)
    z = np.column_stack(
        [rng.uniform(100.0, 99_999.0, MAX_MEASUREMENTS) + 1 / 3, -rng.uniform(0.0, 100.0, 512)]
    )
    data = encode(_detection_set(measurements=z, uav=255, bandwidth_share=1 / 3))
    assert len(data) < 0.4 * MAX_PAYLOAD_BYTES
    np.testing.assert_array_equal(decode(DetectionSetMsg, data).measurements, z)
    states = -rng.uniform(1e3, 1e4, (MAX_TARGETS, 4)) - 1 / 3
    data = encode(_truth_set(states=states, origins=((-1,) * 20,) * 6))
    np.testing.assert_array_equal(decode(TruthSetMsg, data).states, states)


# ----------------------------------------------------------------------------- malformed


def test_detection_set_refusals_name_the_field() -> None:
    obj = _obj(encode(_detection_set()))
    decode = partial(wire.decode, DetectionSetMsg)
    reason = _expect(
        _bytes({**obj, "measurements": [[1.0, 2.0], [-1.0, 0.5]]}),
        "detection_set.measurements[1][0]",
        decode,
    )
    assert reason == "detection_set.measurements[1][0]: -1 is below 0"
    reason = _expect(
        _bytes({**obj, "measurements": [[1.0, 2.0, 3.0]]}), "detection_set.measurements[0]", decode
    )
    assert reason == "detection_set.measurements[0]: 3 values, expected 2"
    _expect(_bytes({**obj, "measurements": [[1.0]]}), "detection_set.measurements[0]", decode)
    _expect(_bytes({**obj, "measurements": [5.0]}), "detection_set.measurements[0]", decode)
    _expect(_bytes({**obj, "measurements": 5.0}), "detection_set.measurements", decode)
    _expect(
        _bytes({**obj, "measurements": [[1.0, "2"]]}), "detection_set.measurements[0][1]", decode
    )
    _expect(
        _bytes({**obj, "measurements": [[1.0, 2e9]]}), "detection_set.measurements[0][1]", decode
    )
    reason = _expect(
        _bytes({**obj, "measurements": [[1.0, 0.0]] * (MAX_MEASUREMENTS + 1)}),
        "detection_set.measurements",
        decode,
    )
    assert reason == "detection_set.measurements: 513 values, expected at most 512"
    reason = _expect(_bytes({**obj, "uav": 3}), "detection_set.uav", decode, n_uavs=3)
    assert reason == "detection_set.uav: 3 is outside [0, 2]"
    _expect(_bytes({**obj, "uav": 256}), "detection_set.uav", decode)
    _expect(_bytes({**obj, "uav_xy_m": [1.0]}), "detection_set.uav_xy_m", decode)
    _expect(_bytes({**obj, "bandwidth_share": 1.5}), "detection_set.bandwidth_share", decode)
    missing = dict(obj)
    del missing["measurements"]
    assert "missing" in _expect(_bytes(missing), "detection_set.measurements", decode)


def test_truth_set_refusals_name_the_field() -> None:
    obj = _obj(encode(_truth_set()))
    decode = partial(wire.decode, TruthSetMsg)
    reason = _expect(_bytes({**obj, "origins": [[0, -2]]}), "truth_set.origins[0][1]", decode)
    assert reason == "truth_set.origins[0][1]: -2 is outside [-1, 63]"
    _expect(_bytes({**obj, "origins": [[], [MAX_TARGETS]]}), "truth_set.origins[1][0]", decode)
    _expect(_bytes({**obj, "origins": [[1.0]]}), "truth_set.origins[0][0]", decode)
    _expect(_bytes({**obj, "origins": [[0]] * 257}), "truth_set.origins", decode)
    _expect(
        _bytes({**obj, "origins": [[], [0] * (MAX_MEASUREMENTS + 1)]}),
        "truth_set.origins[1]",
        decode,
    )
    _expect(_bytes({**obj, "targets": [[0.0, 1.0, 2.0]]}), "truth_set.targets[0]", decode)
    _expect(_bytes({**obj, "targets": [None, [0, 1, 2, "x"]]}), "truth_set.targets[1][3]", decode)
    reason = _expect(
        _bytes({**obj, "targets": [None] * (MAX_TARGETS + 1)}), "truth_set.targets", decode
    )
    assert reason == "truth_set.targets: 65 values, expected at most 64"


def test_track_set_refusals_name_the_field() -> None:
    obj = _obj(encode(_track_set()))
    one, two = obj["tracks"]
    decode = partial(wire.decode, TrackSetMsg)
    reason = _expect(
        _bytes({**obj, "tracks": [{**one, "id": 0}]}), "track_set.tracks[0].id", decode
    )
    assert reason == "track_set.tracks[0].id: 0 is outside [1, 1000000000]"
    reason = _expect(
        _bytes({**obj, "tracks": [one, {**two, "id": 1}]}), "track_set.tracks[1].id", decode
    )
    assert reason == "track_set.tracks[1].id: 1 repeats tracks[0].id"
    reason = _expect(
        _bytes({**obj, "tracks": [one, {**two, "P": [[1.0] * 4] * 3}]}),
        "track_set.tracks[1].P",
        decode,
    )
    assert reason == "track_set.tracks[1].P: 3 values, expected 4"
    _expect(
        _bytes({**obj, "tracks": [{**one, "P": [[1.0] * 3] * 4}]}),
        "track_set.tracks[0].P[0]",
        decode,
    )
    reason = _expect(
        _bytes({**obj, "tracks": [{**one, "P": [[1e200] * 4] * 4}]}),
        "track_set.tracks[0].P[0][0]",
        decode,
    )
    assert reason.endswith("(limit 1e+150)")
    _expect(
        _bytes({**obj, "tracks": [{**one, "x": [2e9, 0, 0, 0]}]}),
        "track_set.tracks[0].x[0]",
        decode,
    )
    _expect(
        _bytes({**obj, "tracks": [{**one, "pcrb_position_trace": -1.0}]}),
        "track_set.tracks[0].pcrb_position_trace",
        decode,
    )
    _expect(
        _bytes({**obj, "tracks": [{**one, "confirmed": 1}]}),
        "track_set.tracks[0].confirmed",
        decode,
    )
    no_x = {k: v for k, v in one.items() if k != "x"}
    assert "missing" in _expect(_bytes({**obj, "tracks": [no_x]}), "track_set.tracks[0].x", decode)
    _expect(_bytes({**obj, "tracks": [one, 5]}), "track_set.tracks[1]", decode)
    reason = _expect(
        _bytes({**obj, "tracks": [{**one, "id": i + 1} for i in range(MAX_TRACKS + 1)]}),
        "track_set.tracks",
        decode,
    )
    assert reason == "track_set.tracks: 65 values, expected at most 64"
    _expect(_bytes({**obj, "published_wall_s": -1.0}), "track_set.published_wall_s", decode)


@pytest.mark.parametrize(
    ("encode", "decode", "msg"),
    [
        (encode, partial(wire.decode, DetectionSetMsg), _detection_set()),
        (encode, partial(wire.decode, TruthSetMsg), _truth_set()),
        (encode, partial(wire.decode, TrackSetMsg), _track_set()),
    ],
)
def test_a_nan_token_in_the_json_text_is_refused(encode: Any, decode: Any, msg: Any) -> None:
    text = encode(msg).decode()
    t_field = f'"t":{msg.t_s!r}'
    assert text.count(t_field) == 1
    for token in ("NaN", "Infinity", "-Infinity"):
        bad = text.replace(t_field, f'"t":{token}')
        _expect(bad, f"payload: {token} is not allowed", decode)
        _expect(bad, "payload: ", decode_any)


def test_decode_any_names_the_field_of_the_multi_target_message() -> None:
    det = _obj(encode(_detection_set()))
    _expect(
        _bytes({**det, "measurements": [[-1.0, 0.0]]}),
        "detection_set.measurements[0][0]",
        decode_any,
    )
    truth = _obj(encode(_truth_set()))
    _expect(_bytes({**truth, "origins": [[-5]]}), "truth_set.origins[0][0]", decode_any)
    tracks = _obj(encode(_track_set()))
    one = tracks["tracks"][0]
    _expect(_bytes({**tracks, "tracks": [one, one]}), "track_set.tracks[1].id", decode_any)


def test_encoders_refuse_what_decoders_would_refuse() -> None:
    with pytest.raises(MessageError, match=r"detection_set\.measurements\[1\]"):
        encode(_detection_set(measurements=np.array([[1.0, 0.0], [-2.0, 0.0]])))
    with pytest.raises(MessageError, match=r"detection_set\.measurements"):
        encode(_detection_set(measurements=np.zeros((3, 3))))
    with pytest.raises(MessageError, match=r"detection_set\.measurements\[0\]"):
        encode(_detection_set(measurements=np.array([[np.nan, 1.0]])))
    with pytest.raises(MessageError, match=r"truth_set\.targets\[0\]"):
        encode(_truth_set(states=np.array([[1.0, np.nan, 0.0, 0.0]])))
    with pytest.raises(MessageError, match=r"truth_set\.origins"):
        encode(_truth_set(origins=((0, -3),)))
    with pytest.raises(MessageError, match=r"track_set\.tracks\[1\]\.id"):
        encode(_track_set(tracks=(_entry(2), _entry(2))))
    with pytest.raises(MessageError, match=r"track_set\.tracks\[0\]\.P"):
        encode(_track_set(tracks=(TrackEntry(1, True, np.zeros(4), np.eye(3), 1.0),)))


# ----------------------------------------------------------------------------- schemas


def test_the_schemas_carry_the_bounds_the_decoders_enforce() -> None:
    schemas = message_schemas()
    det = schemas["detection_set"]["properties"]
    assert det["measurements"]["maxItems"] == MAX_MEASUREMENTS
    pair = det["measurements"]["items"]
    assert pair["minItems"] == pair["maxItems"] == 2
    assert pair["prefixItems"][0]["minimum"] == 0.0  # a range is >= 0
    assert det["uav"]["maximum"] == wire.MAX_UAVS - 1
    assert "measurements" in schemas["detection_set"]["required"]
    truth = schemas["truth_set"]
    assert truth["properties"]["targets"]["maxItems"] == MAX_TARGETS
    assert {"type": "null"} in truth["properties"]["targets"]["items"]["anyOf"]
    origin = truth["properties"]["origins"]["items"]["items"]
    assert (origin["minimum"], origin["maximum"]) == (-1, MAX_TARGETS - 1)
    assert "origins" not in truth["required"]  # optional on the wire
    tracks = schemas["track_set"]
    assert tracks["properties"]["tracks"]["maxItems"] == MAX_TRACKS
    entry = tracks["$defs"]["TrackEntryWire"]["properties"]
    assert (entry["id"]["minimum"], entry["id"]["maximum"]) == (1, 10**9)
    assert entry["P"]["items"]["items"]["maximum"] == wire.MAX_ABS_COVARIANCE
    assert "published_wall_s" not in tracks["required"]


def test_an_encoded_payload_has_exactly_the_fields_the_schema_names() -> None:
    schemas = message_schemas()
    for kind, data in (
        ("detection_set", encode(_detection_set())),
        ("truth_set", encode(_truth_set())),
        ("track_set", encode(_track_set(published_wall_s=1.9e9))),
    ):
        assert set(_obj(data)) == set(schemas[kind]["properties"]), kind
    prioritised = _entry(1).model_copy(update={"priority": 2.0})  # the default is not written
    entry = _obj(encode(_track_set(tracks=(prioritised,))))["tracks"][0]
    assert set(entry) == set(schemas["track_set"]["$defs"]["TrackEntryWire"]["properties"])
