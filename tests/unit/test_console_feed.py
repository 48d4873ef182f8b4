"""The console's per-page feeds: state topics coalesce to their latest value, events are kept in
order up to a bound, a put never waits for the page; and the MissionView folds bus payloads
into the updates it pushes (bad payloads counted, nothing changed), a multi-target mission's
`track_set`, `truth_set` and `detection_set` as well as the single-target types."""

from __future__ import annotations

import asyncio
import json
import math
from typing import Any

import numpy as np
import pytest

from isac_mission.config import load_scenario
from isac_mission.console.feed import ClientFeed, Hub, batch_text
from isac_mission.console.geometry import ellipse_2sigma, pcrb_parts
from isac_mission.console.state import MissionView
from isac_mission.wire import (
    DetectionMsg,
    DetectionSetMsg,
    TelemetryMsg,
    TrackEntry,
    TrackMsg,
    TrackSetMsg,
    TruthMsg,
    TruthSetMsg,
    encode,
)


def _offer(feed: ClientFeed, topic: str, data: object) -> None:
    feed.put(topic, json.dumps({"topic": topic, "data": data}))


def _take(feed: ClientFeed) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = json.loads(batch_text(feed.take()))
    return out


def test_state_topics_keep_only_their_latest_value_in_arrival_order() -> None:
    feed = ClientFeed()
    for i in range(100):
        _offer(feed, "telemetry/0", {"i": i})
        _offer(feed, "telemetry/1", {"i": i})
    _offer(feed, "plan", {"slot": 3})
    _offer(feed, "telemetry/0", {"i": 100})
    batch = _take(feed)
    assert [u["topic"] for u in batch] == ["telemetry/1", "plan", "telemetry/0"]
    assert batch[-1]["data"] == {"i": 100}
    assert feed.counters.coalesced == 100 + 99
    assert feed.take() == [] and feed.pending == 0


def test_events_are_kept_in_order_and_bounded() -> None:
    feed = ClientFeed(max_events=10)
    for n in range(25):
        _offer(feed, "series", {"slot": n})
    _offer(feed, "reply", {"id": "a"})
    batch = _take(feed)
    assert [u["data"].get("slot") for u in batch[:-1]] == list(range(16, 25))
    assert batch[-1] == {"topic": "reply", "data": {"id": "a"}}
    assert feed.counters.dropped == 16


def test_a_page_that_never_takes_costs_bounded_memory_and_never_blocks_the_others() -> None:
    async def scenario() -> tuple[int, int]:
        hub, stalled, live = Hub(), ClientFeed(max_events=50), ClientFeed()
        hub.add(stalled)
        hub.add(live)
        got = 0
        for n in range(10_000):
            hub.broadcast("telemetry/0", {"n": n})
            hub.broadcast("series", {"slot": n})
            if n % 100 == 0:
                await asyncio.wait_for(live.wait(), 1.0)
                got += len(_take(live))
        return stalled.pending, got

    pending, got = asyncio.run(scenario())
    assert pending == 1 + 50  # the latest telemetry and the newest 50 events
    assert got > 100


def test_the_hub_encodes_once_and_never_sends_a_non_finite_number() -> None:
    hub, a, b = Hub(), ClientFeed(), ClientFeed()
    hub.add(a)
    hub.add(b)
    hub.broadcast("plan", {"objective": 1.5})
    hub.broadcast("track", {"x": [float("nan")]})
    assert a.take() == b.take() == ['{"topic":"plan","data":{"objective":1.5}}']


def test_wait_returns_at_once_when_something_is_pending_and_wakes_on_put() -> None:
    async def scenario() -> list[str]:
        feed = ClientFeed()
        _offer(feed, "plan", {})
        await asyncio.wait_for(feed.wait(), 0.5)
        feed.take()
        waiter = asyncio.create_task(feed.wait())
        await asyncio.sleep(0)
        assert not waiter.done()
        _offer(feed, "health", {})
        await asyncio.wait_for(waiter, 0.5)
        return [u["topic"] for u in _take(feed)]

    assert asyncio.run(scenario()) == ["health"]


def _view() -> MissionView:
    s = load_scenario("paper")
    return MissionView(s.trace_config(), clock=lambda: 1000.0)


def test_the_view_folds_telemetry_and_tracks_into_updates_and_series() -> None:
    view = _view()
    tel = TelemetryMsg(
        5,
        5.0,
        1,
        np.array([10.0, 20.0]),
        100.0,
        np.zeros(2),
        "offboard",
        True,
        False,
        "ok",
        published_wall_s=999.5,
    )
    updates = view.ingest("isac/paper/telemetry/1", encode(tel))
    assert [t for t, _ in updates] == ["telemetry/1"]
    data = updates[0][1]
    assert data["position_xy_m"] == [10.0, 20.0] and data["published_wall_s"] == 999.5
    assert data["received_wall_s"] == 1000.0
    P = np.diag([4.0, 1.0, 0.1, 0.1])
    J = np.diag([2.0, 4.0, 10.0, 20.0])
    track = TrackMsg(5, 5.0, np.array([1.0, 2.0, 0.0, 0.0]), P, J, 0.9)
    topics = dict(view.ingest("isac/paper/track", encode(track)))
    assert topics["track"]["ellipse"] == pytest.approx({"a_m": 4.0, "b_m": 2.0, "angle_rad": 0.0})
    assert topics["series"] == pytest.approx(
        {"slot": 5, "pcrb_trace": 0.9, "pcrb_pos": 0.75, "pcrb_vel": 0.15}
    )
    snap = json.loads(json.dumps(view.snapshot()))
    assert snap["trails"]["1"] == [[10.0, 20.0]]
    assert snap["series"][0]["slot"] == 5


def test_the_view_counts_bad_payloads_and_changes_nothing() -> None:
    view = _view()
    good = encode(
        TelemetryMsg(1, 1.0, 0, np.zeros(2), 100.0, np.zeros(2), "offboard", True, False, "ok")
    )
    bad_uav = good.replace(b'"uav":0', b'"uav":7')
    for payload in (b"{nope", bad_uav, b'{"schema":"isac/1","type":"nonsense","slot":0,"t":0}'):
        assert view.ingest("isac/paper/telemetry/0", payload) == []
    assert view.latest == {}
    assert view.rejected["payload not JSON"] == 1
    assert view.rejected["telemetry.uav"] == 1
    assert view.rejected["type"] == 1
    assert "nonsense" in view.last_rejection


def test_ellipse_and_bound_parts_of_degenerate_inputs() -> None:
    rot = np.array([[0.0, -1.0], [1.0, 0.0]])
    P = np.eye(4)
    P[:2, :2] = rot @ np.diag([9.0, 1.0]) @ rot.T
    e = ellipse_2sigma(P)
    assert e is not None and e["a_m"] == pytest.approx(6.0) and e["b_m"] == pytest.approx(2.0)
    assert abs(abs(e["angle_rad"]) - np.pi / 2) < 1e-9
    assert ellipse_2sigma(np.diag([np.nan, 1.0, 1.0, 1.0])) is None
    assert ellipse_2sigma(np.diag([-5.0, 1.0, 1.0, 1.0])) is None
    assert pcrb_parts(np.zeros((4, 4))) is None


# ---------------------------------------------------------------- multi-target missions

P_TRACK = np.diag([4.0, 1.0, 0.1, 0.1])
"""A track covariance whose 2-sigma ellipse has semi-axes 4 m (along x) and 2 m."""
TRUTHS = np.array(
    [[100.0, 200.0, 1.0, 0.0], [np.nan] * 4, [300.0, 50.0, 0.0, -1.0]]
)  # target 1 is not in the scene
TRACKS = (  # id, confirmed, x
    (3, True, [103.0, 204.0, 1.0, 0.0]),
    (7, False, [300.0, 50.0, 0.0, 0.0]),  # tentative: on target 2, but never its error
    (9, True, [310.0, 60.0, 0.0, 0.0]),
)


def _truth_set(slot: int) -> bytes:
    return encode(TruthSetMsg(slot, float(slot), TRUTHS, ((0, -1), (), (2,))))


def _track_set(slot: int) -> bytes:
    entries = tuple(TrackEntry(i, c, np.array(x), P_TRACK, 0.25 * i) for i, c, x in TRACKS)
    return encode(TrackSetMsg(slot, float(slot), entries, published_wall_s=999.0))


def _expected_errors() -> list[dict[str, Any]]:
    """Per present target, the distance to the nearest confirmed track, computed here."""
    out = []
    for t in (0, 2):
        tx, ty = TRUTHS[t, :2]
        dist = [math.hypot(x[0] - tx, x[1] - ty) for _, c, x in TRACKS if c]
        out.append({"index": t, "error_m": min(dist)})
    return out


def _check_tracks(data: dict[str, Any]) -> None:
    assert [t["id"] for t in data["tracks"]] == [3, 7, 9]
    assert [t["confirmed"] for t in data["tracks"]] == [True, False, True]
    for t, (i, _, x) in zip(data["tracks"], TRACKS, strict=True):
        assert t["x"] == x
        assert t["P"] == P_TRACK.tolist()
        assert t["pcrb_position_trace"] == 0.25 * i
        assert t["ellipse"] == pytest.approx({"a_m": 4.0, "b_m": 2.0, "angle_rad": 0.0})
    assert data["slot"] == 6 and data["received_wall_s"] == 1000.0
    assert data["published_wall_s"] == 999.0


def test_the_view_shows_every_track_and_each_targets_error_to_the_nearest_confirmed_track() -> None:
    view = _view()
    truths = view.ingest("isac/paper/truth", _truth_set(6))
    assert [t for t, _ in truths] == ["truths"]
    assert truths[0][1]["present"] == [
        {"index": 0, "x": TRUTHS[0].tolist()},
        {"index": 2, "x": TRUTHS[2].tolist()},
    ]
    assert "origins" not in truths[0][1] and "targets" not in truths[0][1]
    updates = view.ingest("isac/paper/track", _track_set(6))
    assert [t for t, _ in updates] == ["tracks"]  # no single-target topic, no series point
    data = updates[0][1]
    _check_tracks(data)
    errors = data["target_errors"]
    assert [e["index"] for e in errors] == [0, 2]
    assert [e["error_m"] for e in errors] == pytest.approx(
        [e["error_m"] for e in _expected_errors()]
    )
    assert errors[0]["error_m"] == pytest.approx(5.0)  # (3, 4) from track 3
    snap = json.loads(json.dumps(view.snapshot(), allow_nan=False))
    assert sorted(snap["latest"]) == ["tracks", "truths"]
    _check_tracks(snap["latest"]["tracks"])
    assert snap["latest"]["truths"]["present"][1]["index"] == 2
    assert snap["series"] == []
    assert view.received == {"truth_set": 1, "track_set": 1}


def test_a_truth_after_its_slots_tracks_adds_the_errors_and_another_slots_does_not() -> None:
    view = _view()
    first = dict(view.ingest("isac/paper/track", _track_set(6)))
    assert "target_errors" not in first["tracks"]  # the truth of slot 6 is not known yet
    assert [t for t, _ in view.ingest("isac/paper/truth", _truth_set(5))] == ["truths"]
    assert "target_errors" not in view.latest["tracks"]
    updates = view.ingest("isac/paper/truth", _truth_set(6))
    assert [t for t, _ in updates] == ["truths", "tracks"]
    _check_tracks(updates[1][1])
    assert [e["error_m"] for e in updates[1][1]["target_errors"]] == pytest.approx(
        [e["error_m"] for e in _expected_errors()]
    )


def test_without_a_confirmed_track_each_present_target_has_no_error() -> None:
    view = _view()
    view.ingest("isac/paper/truth", _truth_set(2))
    tentative = TrackEntry(4, False, np.array([100.0, 200.0, 0.0, 0.0]), P_TRACK, 1.0)
    ((topic, data),) = view.ingest("isac/paper/track", encode(TrackSetMsg(2, 2.0, (tentative,))))
    assert topic == "tracks" and data["published_wall_s"] is None
    assert data["target_errors"] == [{"index": 0, "error_m": None}, {"index": 2, "error_m": None}]
    ((_, empty),) = view.ingest("isac/paper/track", encode(TrackSetMsg(3, 3.0, ())))
    assert empty["tracks"] == [] and "target_errors" not in empty


def test_a_detection_set_is_taken_as_a_detection_is() -> None:
    view = _view()
    for m, k in ((0, 3), (2, 0)):  # a UAV that detected nothing still reports
        msg = DetectionSetMsg(8, 8.0, m, np.full((k, 2), 50.0), np.zeros(2), 1 / 3)
        assert view.ingest(f"isac/paper/detections/{m}", encode(msg)) == []
    assert view.received == {"detection_set": 2}
    assert view.detection_wall_s == {8: 1000.0}
    assert view.latest == {}


def test_bad_multi_target_payloads_are_counted_and_change_nothing() -> None:
    view = _view()
    twice = json.loads(_track_set(6))
    twice["tracks"][2]["id"] = 3
    bad_uav = encode(DetectionSetMsg(8, 8.0, 0, np.zeros((0, 2)), np.zeros(2), 0.5)).replace(
        b'"uav":0', b'"uav":3'
    )
    no_targets = json.loads(_truth_set(6))
    del no_targets["targets"]
    for key, payload in (
        ("track", json.dumps(twice).encode()),
        ("detections/0", bad_uav),
        ("truth", json.dumps(no_targets).encode()),
    ):
        assert view.ingest(f"isac/paper/{key}", payload) == []
    assert view.latest == {} and view.received == {}
    assert view.detection_wall_s == {} and view.truths_by_slot == {}
    assert view.rejected == {
        "track_set.tracks[2].id": 1,
        "detection_set.uav": 1,
        "truth_set.targets": 1,
    }
    assert view.last_rejection.startswith("isac/paper/truth: truth_set.targets")


def test_a_single_target_mission_keeps_its_track_truth_and_series_updates() -> None:
    """`track` and `truth` keep their own topics and slot series (the lead track's numbers),
    followed by the `tracks` and `truths` every mission is drawn from."""
    view = _view()
    det = DetectionMsg(6, 6.0, 0, 120.0, 1.5, np.zeros(2), 1 / 3)
    assert view.ingest("isac/paper/detections/0", encode(det)) == []
    truth = TruthMsg(6, 6.0, np.array([100.0, 200.0, 1.0, 0.0]))
    updates = view.ingest("isac/paper/truth", encode(truth))
    assert updates[0] == ("truth", json.loads(encode(truth)))
    assert [t for t, _ in updates] == ["truth", "truths"]
    J = np.diag([2.0, 4.0, 10.0, 20.0])
    track = TrackMsg(6, 6.0, np.array([103.0, 204.0, 1.0, 0.0]), P_TRACK, J, 0.9)
    updates = view.ingest("isac/paper/track", encode(track))
    assert [t for t, _ in updates] == ["track", "series", "tracks"]
    assert updates[1][1] == pytest.approx(
        {"slot": 6, "pcrb_trace": 0.9, "pcrb_pos": 0.75, "pcrb_vel": 0.15, "error_m": 5.0}
    )
    assert sorted(view.latest) == ["track", "tracks", "truth", "truths"]
    assert view.detection_wall_s == {6: 1000.0}
    assert view.received == {"detection": 1, "truth": 1, "track": 1}
