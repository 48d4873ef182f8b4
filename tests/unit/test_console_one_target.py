"""A single target is a track like the others: the console's view turns a `track` into the
`tracks` a one-entry `track_set` gives (track 1, confirmed) and a `truth` into the `truths` of a
one-state `truth_set`, so that the page draws every mission one way; and a `track_set` of a slot
wins over the `track` (the lead track) of the same or an older slot, which draws nothing more."""

from __future__ import annotations

import copy
import json
from typing import Any

import numpy as np
import pytest

from isac_mission.config import load_scenario
from isac_mission.console.state import MissionView
from isac_mission.wire import TrackEntry, TrackMsg, TrackSetMsg, TruthMsg, TruthSetMsg, encode

P = np.array(
    [[4.0, 0.6, 0.1, 0.0], [0.6, 1.0, 0.0, 0.1], [0.1, 0.0, 0.3, 0.0], [0.0, 0.1, 0.0, 0.2]]
)
J = np.array(
    [[2.0, 0.3, 0.1, 0.0], [0.3, 4.0, 0.0, 0.2], [0.1, 0.0, 10.0, 0.5], [0.0, 0.2, 0.5, 20.0]]
)
POSITION_BOUND = float(np.trace(np.linalg.inv(J)[:2, :2]))
"""tr of the position block of J^-1 (m^2): the one-entry track_set's pcrb_position_trace."""


def _view() -> MissionView:
    return MissionView(load_scenario("paper").trace_config(), clock=lambda: 1000.0)


def _target(n: int) -> np.ndarray:
    return np.array([100.0 + 30.0 * n, 200.0, 30.0, 0.0])


def _estimate(n: int) -> np.ndarray:
    return _target(n) + np.array([0.3, -0.4, 0.1, 0.0])


def _track(n: int) -> bytes:
    msg = TrackMsg(n, float(n), _estimate(n), P, J, 1.5, published_wall_s=990.0 + n)
    return encode(msg)


def _track_set(n: int, track_id: int = 1) -> bytes:
    entry = TrackEntry(track_id, True, _estimate(n), P, POSITION_BOUND)
    return encode(TrackSetMsg(n, float(n), (entry,), published_wall_s=990.0 + n))


def _truth(n: int) -> bytes:
    return encode(TruthMsg(n, float(n), _target(n)))


def _truth_set(n: int) -> bytes:
    return encode(TruthSetMsg(n, float(n), _target(n)[None, :]))


def _drawn(view: MissionView, feed: list[tuple[str, bytes]]) -> list[tuple[str, Any]]:
    """The `tracks` and `truths` updates of a feed, as the pages get them (JSON, copied when
    made: a later truth adds to the same slot's tracks)."""
    out = []
    for key, payload in feed:
        for topic, data in view.ingest(f"isac/paper/{key}", payload):
            if topic in ("tracks", "truths"):
                out.append((topic, json.loads(json.dumps(copy.deepcopy(data), allow_nan=False))))
    return out


def test_a_track_feed_gives_the_tracks_and_truths_of_the_one_entry_track_set_feed() -> None:
    # The truth first in some slots, after the track in others; slot 4 has no truth.
    single: list[tuple[str, bytes]] = []
    multi: list[tuple[str, bytes]] = []
    for n in range(1, 7):
        if n == 4:
            single.append(("track", _track(n)))
            multi.append(("track", _track_set(n)))
        elif n % 2:
            single += [("truth", _truth(n)), ("track", _track(n))]
            multi += [("truth", _truth_set(n)), ("track", _track_set(n))]
        else:
            single += [("track", _track(n)), ("truth", _truth(n))]
            multi += [("track", _track_set(n)), ("truth", _truth_set(n))]
    one, several = _view(), _view()
    from_track, from_track_set = _drawn(one, single), _drawn(several, multi)
    assert [t for t, _ in from_track] == [t for t, _ in from_track_set]
    assert len(from_track) == 13  # a truths per truth, a tracks per track and per later truth
    assert from_track == from_track_set
    # What they hold: track 1, confirmed, its ellipse, the bound of J's position block, its
    # error to the truth, the per-track series.
    last = one.latest["tracks"]
    (entry,) = last["tracks"]
    assert entry["id"] == 1 and entry["confirmed"] is True and entry["target"] == 0
    assert entry["x"] == _estimate(6).tolist()
    assert entry["pcrb_position_trace"] == POSITION_BOUND
    assert entry["error_m"] == pytest.approx(0.5)
    assert entry["ellipse"] is not None and entry["ellipse"]["a_m"] > entry["ellipse"]["b_m"]
    assert last["series_rows"][-1] == {
        "slot": 6,
        "pcrb/1": POSITION_BOUND,
        "error/1": entry["error_m"],
    }
    assert one.latest["truths"]["present"] == [{"index": 0, "x": _target(6).tolist()}]
    snap_one, snap_several = one.snapshot(), several.snapshot()
    assert snap_one["track_series"] == snap_several["track_series"]
    assert [r["slot"] for r in snap_one["track_series"]] == [1, 2, 3, 4, 5, 6]
    assert "error/1" not in snap_one["track_series"][3]  # slot 4: no truth
    for topic in ("tracks", "truths"):
        assert snap_one["latest"][topic] == snap_several["latest"][topic]


def test_a_track_and_a_track_set_of_the_same_slot_draw_one_track() -> None:
    # The track_set first: the track of its slot (the lead track) and of an older one add
    # nothing to draw; its own topic and the slot series are kept.
    view = _view()
    assert [t for t, _ in view.ingest("isac/paper/track", _track_set(5, track_id=4))] == ["tracks"]
    for n in (5, 4):
        assert [t for t, _ in view.ingest("isac/paper/track", _track(n))] == ["track", "series"]
    assert [tr["id"] for tr in view.latest["tracks"]["tracks"]] == [4]
    assert view.latest["tracks"]["slot"] == 5
    assert sorted(k for row in view.track_series.values() for k in row) == ["pcrb/4", "slot"]
    # The track first: the track_set of its slot replaces it, and its series.
    view.ingest("isac/paper/truth", _truth(6))
    (_, _, (topic, first)) = view.ingest("isac/paper/track", _track(6))
    assert topic == "tracks" and [tr["id"] for tr in first["tracks"]] == [1]
    assert set(view.track_series[6]) == {"slot", "pcrb/1", "error/1"}
    ((topic, data),) = view.ingest("isac/paper/track", _track_set(6, track_id=4))
    assert [tr["id"] for tr in data["tracks"]] == [4] and view.latest["tracks"] is data
    assert set(view.track_series[6]) == {"slot", "pcrb/4", "error/4"}
    assert data["series_rows"][-1]["slot"] == 6 and "pcrb/1" not in data["series_rows"][-1]
    # A truth_set of a slot wins over the truth of it in the same way.
    view.ingest("isac/paper/truth", _truth_set(7))
    assert [t for t, _ in view.ingest("isac/paper/truth", _truth(7))] == ["truth"]
    assert view.latest["truths"]["type"] == "truth_set" and view.truth_set_slot == 7


def test_a_track_after_the_last_track_set_draws_until_its_slots_track_set_comes() -> None:
    """A `track` of a slot no `track_set` has reached yet is drawn; its slot's `track_set`
    then replaces it (a page sees the lead track as T1 at most until then)."""
    view = _view()
    view.ingest("isac/paper/track", _track_set(5, track_id=4))
    updates = view.ingest("isac/paper/track", _track(6))
    assert [t for t, _ in updates] == ["track", "series", "tracks"]
    assert [tr["id"] for tr in view.latest["tracks"]["tracks"]] == [1]
    view.ingest("isac/paper/track", _track_set(6, track_id=4))
    assert [tr["id"] for tr in view.latest["tracks"]["tracks"]] == [4]
    assert set(view.track_series[6]) == {"slot", "pcrb/4"}
