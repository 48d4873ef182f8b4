"""The console's per-page feeds: state topics coalesce to their latest value, events are kept in
order up to a bound, a put never waits for the page; and the MissionView folds bus payloads
into the updates it pushes (bad payloads counted, nothing changed)."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import numpy as np
import pytest

from isac_mission.config import load_scenario
from isac_mission.console.feed import ClientFeed, Hub, batch_text
from isac_mission.console.geometry import ellipse_2sigma, pcrb_parts
from isac_mission.console.state import MissionView
from isac_mission.wire import TelemetryMsg, TrackMsg, encode_telemetry, encode_track


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
    updates = view.ingest("isac/paper/telemetry/1", encode_telemetry(tel))
    assert [t for t, _ in updates] == ["telemetry/1"]
    data = updates[0][1]
    assert data["position_xy_m"] == [10.0, 20.0] and data["published_wall_s"] == 999.5
    assert data["received_wall_s"] == 1000.0
    P = np.diag([4.0, 1.0, 0.1, 0.1])
    J = np.diag([2.0, 4.0, 10.0, 20.0])
    track = TrackMsg(5, 5.0, np.array([1.0, 2.0, 0.0, 0.0]), P, J, 0.9)
    topics = dict(view.ingest("isac/paper/track", encode_track(track)))
    assert topics["track"]["ellipse"] == pytest.approx({"a_m": 4.0, "b_m": 2.0, "angle_rad": 0.0})
    assert topics["series"] == pytest.approx(
        {"slot": 5, "pcrb_trace": 0.9, "pcrb_pos": 0.75, "pcrb_vel": 0.15}
    )
    snap = json.loads(json.dumps(view.snapshot()))
    assert snap["trails"]["1"] == [[10.0, 20.0]]
    assert snap["series"][0]["slot"] == 5


def test_the_view_counts_bad_payloads_and_changes_nothing() -> None:
    view = _view()
    good = encode_telemetry(
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
