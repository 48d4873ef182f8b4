"""What the console's view adds for the page beyond the bus messages themselves: the truth of an
estimate's own slot (the world's next truth may come first, and the page keeps only the latest),
and on a multi-target mission the target each confirmed track follows, its error, and the
per-track series its charts draw."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from isac_mission.config import load_scenario
from isac_mission.console.state import DEFAULT_FOLLOW_GATE_M, TRACK_ROWS_SENT, MissionView
from isac_mission.wire import TrackEntry, TrackMsg, TrackSetMsg, TruthMsg, TruthSetMsg, encode

P = np.diag([4.0, 1.0, 0.1, 0.1])
J = np.diag([2.0, 4.0, 10.0, 20.0])


def _truth(slot: int, x_m: float) -> bytes:
    return encode(TruthMsg(slot, float(slot), np.array([x_m, 200.0, 30.0, 0.0])))


def _track(slot: int, x_m: float) -> bytes:
    return encode(TrackMsg(slot, float(slot), np.array([x_m, 200.0, 30.0, 0.0]), P, J, 0.9))


def test_a_track_carries_the_truth_of_its_own_slot_not_the_latest() -> None:
    view = MissionView(load_scenario("paper").trace_config(), clock=lambda: 1000.0)
    view.ingest("isac/paper/truth", _truth(12, 100.0))
    view.ingest("isac/paper/truth", _truth(13, 130.0))  # the next slot's, 30 m on, first
    (_, track), *_ = view.ingest("isac/paper/track", _track(12, 100.5))
    assert track["truth_of_slot"] == [100.0, 200.0, 30.0, 0.0]
    # A track whose slot's truth is not known yet carries none, and gets it when it comes.
    (_, later), *_ = view.ingest("isac/paper/track", _track(14, 160.0))
    assert later["truth_of_slot"] is None
    updates = view.ingest("isac/paper/truth", _truth(14, 160.4))
    assert [t for t, _ in updates] == ["truth", "track", "series", "truths", "tracks"]
    assert updates[1][1]["slot"] == 14
    assert updates[1][1]["truth_of_slot"] == [160.4, 200.0, 30.0, 0.0]
    assert updates[2][1]["error_m"] == pytest.approx(0.4)
    # Another slot's truth leaves the track alone.
    assert [t for t, _ in view.ingest("isac/paper/truth", _truth(15, 190.0))] == ["truth", "truths"]


TARGETS = np.array(
    [[600.0, 1600.0, 30.0, 0.0], [np.nan] * 4, [1500.0, 1200.0, 0.0, 25.0]]
)  # target 2 (index 1) is not in the scene
TRACKS = (  # id, confirmed, x: 5 follows target index 0, 2 index 2; 9 is near nothing
    (5, True, [602.0, 1600.0, 30.0, 0.0]),
    (2, True, [1500.0, 1199.0, 0.0, 25.0]),
    (9, True, [650.0, 1600.0, 0.0, 0.0]),
    (7, False, [600.5, 1600.0, 0.0, 0.0]),
)


def _multi_view() -> MissionView:
    return MissionView(load_scenario("config/multi-target.yaml").trace_config(), clock=lambda: 1.0)


def _truth_set(slot: int) -> bytes:
    return encode(TruthSetMsg(slot, float(slot), TARGETS))


def _track_set(slot: int) -> bytes:
    entries = tuple(TrackEntry(i, c, np.array(x), P, 0.1 * i + slot) for i, c, x in TRACKS)
    return encode(TrackSetMsg(slot, float(slot), entries))


def _by_id(data: dict[str, Any]) -> dict[int, dict[str, Any]]:
    return {int(t["id"]): t for t in data["tracks"]}


def test_each_confirmed_track_follows_the_target_it_is_nearest_within_the_gate() -> None:
    view = _multi_view()
    assert view.follow_gate_m == 10.0  # multi_target.gospa_cutoff_m of the scenario
    view.ingest("isac/multi-target/truth", _truth_set(6))
    ((topic, data),) = view.ingest("isac/multi-target/track", _track_set(6))
    assert topic == "tracks" and data["follow_gate_m"] == 10.0
    tracks = _by_id(data)
    assert tracks[5]["target"] == 0 and tracks[5]["error_m"] == pytest.approx(2.0)
    assert tracks[2]["target"] == 2 and tracks[2]["error_m"] == pytest.approx(1.0)
    # Track 9 is 50 m from target 1, whose nearest confirmed track is 5: it follows none.
    assert tracks[9]["target"] is None and tracks[9]["error_m"] == pytest.approx(50.0)
    # A tentative track follows nothing and is not charted, even on top of a target.
    assert "target" not in tracks[7] and "error_m" not in tracks[7]
    assert data["truths_of_slot"] == [
        {"index": 0, "x": TARGETS[0].tolist()},
        {"index": 2, "x": TARGETS[2].tolist()},
    ]
    (row,) = data["series_rows"]
    assert row == pytest.approx(
        {"slot": 6, "pcrb/5": 6.5, "pcrb/2": 6.2, "pcrb/9": 6.9}
        | {"error/5": 2.0, "error/2": 1.0, "error/9": 50.0}
    )


def test_a_track_beyond_the_gate_follows_no_target_and_the_default_gate_holds() -> None:
    view = _multi_view()
    view.follow_gate_m = 1.5
    view.ingest("isac/multi-target/truth", _truth_set(3))
    (_, data), *_ = view.ingest("isac/multi-target/track", _track_set(3))
    tracks = _by_id(data)
    assert tracks[5]["target"] is None  # 2 m off: beyond 1.5 m
    assert tracks[2]["target"] == 2
    paper = MissionView(load_scenario("paper").trace_config())
    assert paper.follow_gate_m == DEFAULT_FOLLOW_GATE_M


def test_the_per_track_series_reach_the_snapshot_and_ride_with_each_update() -> None:
    view = _multi_view()
    for n in range(1, TRACK_ROWS_SENT + 5):
        view.ingest("isac/multi-target/track", _track_set(n))  # the truth after the tracks
        updates = view.ingest("isac/multi-target/truth", _truth_set(n))
    assert [t for t, _ in updates] == ["truths", "tracks"]
    rows = updates[1][1]["series_rows"]
    assert [r["slot"] for r in rows] == list(range(5, TRACK_ROWS_SENT + 5))
    assert all(r["error/5"] == pytest.approx(2.0) for r in rows)
    snap = json.loads(json.dumps(view.snapshot(), allow_nan=False))
    assert [r["slot"] for r in snap["track_series"]] == list(range(1, TRACK_ROWS_SENT + 5))
    assert snap["track_series"][0]["pcrb/2"] == pytest.approx(1.2)
    assert snap["series"] == []  # the single-target series stay empty
    assert all(math.isfinite(v) for r in snap["track_series"] for v in r.values())
