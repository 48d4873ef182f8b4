"""The console page in a real headless Chromium, fed bus messages a test publishes on a real Zenoh
hub on loopback (the console subscribes to it as it subscribes to a ground loop's):

- the page names the mission's phase (starting, take-off, running slot k of N, landing, done)
  from the clock, the health status and the vehicles' telemetry, and never shows a slot
  outside 1..N (the world's clock says -1 before the start and keeps counting past N);
- the target close-up shows the estimate, its 2-sigma ellipse and the truth of the same slot
  apart, at a scale the test checks against the page's own drawing transform, and the map
  that follows the target shows each waypoint apart from its vehicle;
- a multi-target mission charts each confirmed track, names its targets 1-based with the track
  that follows each, and places every map label inside the map and apart from the others;
- a single target is drawn as one track (T1) with its target, its charts per track, and a
  `track_set` of a slot wins over the `track` of the same slot (one target drawn, not two);
- landed vehicles read "landed", and each vehicle's share and BS are the plan's (a vehicle out of
  the plan reads "no BS", share 0; a fleet held reads so for every vehicle), and a plan that is
  not the one flown is marked as such;
- `isac-mission view` places its labels apart and inside the map too, with one replay badge.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import load_scenario
from isac_mission.console import (
    BusAccess,
    ConsoleAddress,
    ConsoleServer,
    ConsoleService,
    MissionView,
)
from isac_mission.records import TraceWriter
from isac_mission.records.slot import SlotRecord
from isac_mission.wire import Keys
from tests.support.browser import browser, stop, wait_http
from tests.support.live_cli import cli, start
from tests.support.ports import free_tcp_port

TIMEOUT_S = 60.0
"""A generous bound on each wait for the page (it reacts within a frame or two)."""
WAIT_MS = int(TIMEOUT_S * 1000)

_RECORD_SLOTS = """
window.__slotTexts = [];
document.addEventListener("DOMContentLoaded", () => {
  const e = document.getElementById("slot");
  new MutationObserver(() => window.__slotTexts.push(e.textContent))
    .observe(e, { childList: true, characterData: true, subtree: true });
});
"""
"""Records every text the page's slot counter shows (on any version of the page)."""


def _envelope(kind: str, slot: int, t_s: float, **fields: Any) -> bytes:
    return json.dumps({"schema": "isac/1", "type": kind, "slot": slot, "t": t_s, **fields}).encode()


def _telemetry(
    uav: int,
    xy: tuple[float, float],
    *,
    mode: str = "offboard",
    armed: bool = True,
    landed: bool = False,
    override: str = "",
    slot: int = 0,
    t_s: float = 0.0,
) -> bytes:
    return _envelope(
        "telemetry",
        slot,
        t_s,
        uav=uav,
        position_xy_m=list(xy),
        altitude_m=0.0 if landed else 100.0,
        velocity_xy_mps=[0.0, 0.0],
        mode=mode,
        armed=armed,
        landed=landed,
        link="ok",
        published_wall_s=time.time(),
        override=override,
    )


def _clock(slot: int, t_s: float, mission_t0: float | None) -> bytes:
    return _envelope("clock", slot, t_s, mission_t0=mission_t0, slot_s=1.0, speed=1.0)


def _health(slot: int, status: str, vehicles: dict[str, str]) -> bytes:
    return _envelope(
        "health", slot, float(slot), status=status, counters={"slots": max(slot, 0)},
        last_error="", vehicles=vehicles,
    )  # fmt: skip


def _plan(slot: int, assoc: list[int], shares: list[float], waypoints: list[list[float]]) -> bytes:
    return _envelope(
        "plan",
        slot,
        float(slot),
        assoc=assoc,
        bandwidth_share=shares,
        waypoints_xy_m=waypoints,
        objective=1.0,
        status="ok",
        reason="",
        solve_s=0.02,
    )


def _track(slot: int, x: list[float], P: np.ndarray) -> bytes:
    return _envelope(
        "track", slot, float(slot), x=x, P=P.tolist(), J=np.linalg.inv(P).tolist(),
        pcrb_trace=float(np.trace(P)), published_wall_s=time.time(),
    )  # fmt: skip


@dataclass
class Rig:
    """A console over a Zenoh hub the test publishes on, and a Chromium page on it."""

    hub: ZenohBus
    page: Any
    keys: Keys
    service: ConsoleService
    errors: list[str] = field(default_factory=list)

    def put(self, key: str, payload: bytes) -> None:
        self.hub.publish(key, payload)

    async def until(self, expression: str) -> None:
        """Wait (bounded) until a JavaScript expression over the page's state holds."""
        await self.page.wait_for_function(
            f"(() => {{ const S = window.consoleState.S, M = window.consoleState.M; "
            f"try {{ return !!({expression}); }} catch (e) {{ return false; }} }})()",
            timeout=WAIT_MS,
            polling=50,
        )

    async def state(self, expression: str) -> Any:
        return await self.page.evaluate(
            f"(() => {{ const S = window.consoleState.S, M = window.consoleState.M; "
            f"return {expression}; }})()"
        )


@contextlib.asynccontextmanager
async def console_page(config: dict[str, Any]) -> AsyncIterator[Rig]:
    """A live console for `config` (a trace config) on free loopback ports, a Zenoh hub where the
    ground loop would listen, and a page on it (1400 x 1000) that records its slot texts."""
    endpoint = tcp_loopback(free_tcp_port())
    keys = Keys(str(config["mission_id"]))
    service = ConsoleService(MissionView(config), BusAccess(str(config["mission_id"]), endpoint))
    server = ConsoleServer(service, ConsoleAddress("127.0.0.1", free_tcp_port()))
    url = server.start()
    try:
        async with await ZenohBus.open_async(BusSettings.hub(endpoint)) as hub, browser() as b:
            deadline = time.monotonic() + TIMEOUT_S
            while service.status != "watching":
                assert time.monotonic() < deadline, "the console never joined the bus"
                await asyncio.sleep(0.05)
            page = await b.new_page(viewport={"width": 1400, "height": 1000})
            rig = Rig(hub, page, keys, service)
            page.on("pageerror", lambda e: rig.errors.append(str(e)))
            await page.add_init_script(_RECORD_SLOTS)
            await page.goto(url)
            await page.wait_for_function("window.consoleState.S.mode === 'live'", timeout=WAIT_MS)
            await hub.wait_for_subscribers(keys.clock, TIMEOUT_S)
            yield rig
            assert rig.errors == []
    finally:
        server.stop()


def _px(value: float) -> Any:
    """Approximately `value` pixels (within half a pixel)."""
    return pytest.approx(value, abs=0.5)


def _labels_apart_and_inside(labels: list[dict[str, float]], width: float, height: float) -> None:
    """Every label box lies inside [0, width] x [0, height] and overlaps no other (px)."""
    assert labels, "no label drawn"
    for a in labels:
        assert a["x"] >= -0.01 and a["y"] >= -0.01, a
        assert a["x"] + a["w"] <= width + 0.01 and a["y"] + a["h"] <= height + 0.01, a
    for i, a in enumerate(labels):
        for b in labels[i + 1 :]:
            ix = min(a["x"] + a["w"], b["x"] + b["w"]) - max(a["x"], b["x"])
            iy = min(a["y"] + a["h"], b["y"] + b["h"]) - max(a["y"], b["y"])
            assert ix <= 0.01 or iy <= 0.01, (a, b)


# ---------------------------------------------------------------- A: the mission's phase


async def test_the_page_names_the_phase_and_shows_no_slot_outside_the_mission() -> None:
    config = load_scenario("paper").trace_config() | {"method": "horizon"}
    n_slots = int(config["N"])
    starts = [tuple(xy) for xy in config["uav_start_xy"]]
    async with console_page(config) as rig:
        k = rig.keys

        def fleet(**kw: Any) -> None:
            for m, xy in enumerate(starts):
                rig.put(k.telemetry(m), _telemetry(m, xy, **kw))

        async def phase_is(phase: str, slot: str) -> None:
            await rig.until(
                f"document.getElementById('phase').dataset.phase === '{phase}' && "
                f"document.getElementById('slot').textContent === '{slot}'"
            )

        # Before the start: the world's clock says slot -1; the vehicles are on the ground.
        rig.put(k.health, _health(0, "running", {"0": "active", "1": "active", "2": "active"}))
        rig.put(k.clock, _clock(-1, 1.0, None))
        fleet(mode="manual", armed=False, landed=True, slot=-1)
        await phase_is("starting", "-")
        # Armed and climbing: take-off; the tracker's cue is drawn where the target is expected.
        fleet(mode="takeoff", armed=True, landed=False, slot=-1)
        rig.put(k.clock, _clock(-1, 5.0, None))
        await phase_is("take-off", "-")
        cues = await rig.state("M.cuesDrawn")
        assert [(c["x"], c["y"]) for c in cues] == [tuple(config["x0"][:2])]
        assert await rig.state("M.inset.items.filter(i => i.kind === 'estimate').length") == 1
        # The mission starts (slot 0 ended at t0): slot 1 is flown, then slot 12, then N.
        rig.put(k.clock, _clock(0, 10.0, 10.0))
        await phase_is("running", "1")
        rig.put(k.clock, _clock(11, 21.5, 10.0))
        await phase_is("running", "12")
        rig.put(k.clock, _clock(n_slots, 10.0 + n_slots, 10.0))
        await phase_is("running", str(n_slots))
        # The ground loop is done; the vehicles land while the world's clock counts on.
        rig.put(k.health, _health(n_slots, "done", {"0": "active", "1": "active", "2": "active"}))
        fleet(mode="land", armed=True, landed=False, slot=n_slots + 1)
        rig.put(k.clock, _clock(n_slots + 16, 86.0, 10.0))
        await phase_is("landing", str(n_slots))
        fleet(mode="land", armed=False, landed=True, slot=n_slots + 30)
        rig.put(k.clock, _clock(n_slots + 77, 147.0, 10.0))
        await phase_is("done", str(n_slots))
        assert await rig.page.text_content("#slots-total") == f" / {n_slots}"

        log = await rig.state("M.phaseLog")
        phases = [e["phase"] for e in log]
        order = ["starting", "take-off", "running", "landing", "done"]
        assert [p for i, p in enumerate(phases) if i == 0 or p != phases[i - 1]] == order
        texts = await rig.page.evaluate("window.__slotTexts")
        assert texts, "the slot counter never changed"
        for text in texts:
            assert text == "-" or 1 <= int(text) <= n_slots, texts
        await rig.until(  # the panels follow the map within a quarter of a second
            "document.getElementById('mission-table').textContent"
            f".includes('done, after slot {n_slots} of {n_slots}')"
        )

        # A mission the ground loop stopped: done after the last slot it processed; before the
        # start, no slot at all (the page's own phase function, on the bus's states).
        stopped = await rig.page.evaluate(
            """() => missionPhase(window.consoleState.S.config, {
                 clock: {slot: 40, mission_t0: 10},
                 health: {status: "stopped", slot: 23},
                 "telemetry/0": {armed: false, landed: true}})"""
        )
        assert stopped == {"phase": "done", "slot": 23, "stopped": True}
        early = await rig.page.evaluate(
            """() => missionPhase(window.consoleState.S.config, {
                 clock: {slot: -1, mission_t0: null}, health: {status: "stopped", slot: 0},
                 "telemetry/0": {armed: true, landed: false}})"""
        )
        assert early == {"phase": "landing", "slot": None, "stopped": True}


# ---------------------------------------------------------------- B: the target close-up


async def test_the_close_up_shows_the_estimate_its_ellipse_and_the_truth_apart() -> None:
    config = load_scenario("paper").trace_config() | {"method": "horizon"}
    target = np.array([1000.0, 1500.0])
    estimate = target + np.array([0.3, 0.25])  # 0.39 m off
    P = np.diag([0.16, 0.0625, 0.5, 0.5])  # 2-sigma semi-axes 0.8 m (east) and 0.5 m
    offsets = [(60.0, 0.0), (-40.0, 45.0), (-30.0, -55.0)]
    uav_xy = [target + o for o in offsets]
    waypoints = [(xy + 0.3 * (target - xy)).tolist() for xy in uav_xy]  # 12-20 m ahead
    async with console_page(config) as rig:
        k = rig.keys
        rig.put(k.clock, _clock(12, 22.0, 10.0))
        for m, xy in enumerate(uav_xy):
            rig.put(k.telemetry(m), _telemetry(m, (xy[0], xy[1]), slot=12, t_s=22.0))
        rig.put(k.plan, _plan(13, [0, 1, 2], [1 / 3] * 3, waypoints))
        truth = _envelope("truth", 12, 22.0, target_x=[*target.tolist(), 30.0, 0.0])
        rig.put(k.truth, truth)
        # The world's truth of the next slot, 30 m on, arrives before the estimate of slot 12.
        rig.put(k.truth, _envelope("truth", 13, 23.0, target_x=[1030.0, 1500.0, 30.0, 0.0]))
        rig.put(k.track, _track(12, [*estimate.tolist(), 30.0, 0.0], P))
        await rig.until("M.inset && M.inset.items.some(i => i.kind === 'truth')")
        inset = await rig.state("M.inset")
        est = next(i for i in inset["items"] if i["kind"] == "estimate")
        tru = next(i for i in inset["items"] if i["kind"] == "truth")
        s = inset["s"]
        # The ellipse as drawn is 2 sigma at the inset's scale, its semi-axes 15 px or more.
        assert est["a"] == _px(0.8 * s) and est["b"] == _px(0.5 * s)
        assert est["b"] >= 15.0
        # The truth is the estimate's slot's (0.39 m away), far enough to tell apart from the
        # cross (7 px) and the diamond (6 px).
        gap_px = math.hypot(est["x"] - tru["x"], est["y"] - tru["y"])
        assert gap_px == _px(math.hypot(0.3, 0.25) * s)
        assert gap_px >= 14.0
        # At the whole area's scale none of this can be seen: under a pixel.
        area = await rig.state("M.map")
        assert not area["follow"] and 0.8 * area["s"] < 1.0
        # Following the target, the map shows each waypoint apart from its vehicle.
        await rig.page.check("#follow")
        await rig.until("M.map.follow === true")
        drawn = await rig.state("M.map")
        assert drawn["s"] > 20 * area["s"]
        for m in range(3):
            u = next(u for u in drawn["uavs"] if u["m"] == m)
            w = next(w for w in drawn["waypoints"] if w["m"] == m)
            assert math.hypot(u["x"] - w["x"], u["y"] - w["y"]) >= 6 + 5 + 10  # marker, cross
        _labels_apart_and_inside(drawn["labels"], 760, 620)


# ---------------------------------------------------------------- C: several targets


async def test_several_targets_are_charted_per_track_and_numbered_one_way() -> None:
    config = load_scenario("config/multi-target.yaml").trace_config() | {"method": "horizon"}
    P = np.diag([4.0, 4.0, 1.0, 1.0])
    # Targets 1 and 3 are in the scene (target 2 comes later); track 5 follows target 1, track 2
    # target 3, track 7 is tentative.
    bs0 = config["bs_xy"][0]  # on the area's east edge: its label must not run off the map
    uav_xy = [
        (bs0[0] - 30.0, bs0[1] + 10.0),
        (bs0[0] - 50.0, bs0[1] - 15.0),
        (bs0[0] - 40.0, bs0[1] + 25.0),
        (700.0, 1640.0),
        (715.0, 1645.0),
        (1540.0, 1230.0),
    ]
    async with console_page(config) as rig:
        k = rig.keys
        rig.put(k.clock, _clock(8, 18.0, 10.0))
        for m, xy in enumerate(uav_xy):
            rig.put(k.telemetry(m), _telemetry(m, xy, slot=8, t_s=18.0))
        plan = _plan(9, [0, 0, 0, 3, 3, 4], [1 / 6] * 6, [list(xy) for xy in uav_xy])
        rig.put(k.plan, plan)
        for n in range(5, 9):
            t1 = [600.0 + 30 * n, 1600.0, 30.0, 0.0]
            t3 = [1500.0, 1200.0 + 25 * n, 0.0, 25.0]
            truths = _envelope("truth_set", n, float(n), targets=[t1, None, t3])
            rig.put(k.truth, truths)
            tracks = [
                {"id": 5, "confirmed": True, "x": [t1[0] + 2.0, t1[1], 30.0, 0.0]},
                {"id": 2, "confirmed": True, "x": [t3[0], t3[1] - 1.0, 0.0, 25.0]},
                {"id": 7, "confirmed": False, "x": [t1[0] + 60.0, t1[1] + 10.0, 0.0, 0.0]},
            ]
            for tr in tracks:
                tr |= {"P": P.tolist(), "pcrb_position_trace": 0.5 + 0.1 * int(tr["id"])}
            rig.put(k.track, _envelope("track_set", n, float(n), tracks=tracks))
        await rig.until("S.latest.tracks && S.latest.tracks.slot === 8 && S.trackSeries.size >= 4")
        await rig.until("M.charts.error && M.charts.error.length === 2")
        charts = await rig.state("M.charts")
        for name in ("pcrb", "error"):
            assert [c["label"] for c in charts[name]] == ["T2", "T5"], charts[name]
            assert all(c["points"] >= 4 for c in charts[name]), charts[name]
        caption = await rig.page.text_content("#caption-error")
        assert caption is not None and "per confirmed track" in caption
        # One numbering: targets 1-based in the scenario's order, each with its track.
        await rig.until("M.labels.some(l => l.text.startsWith('target 1'))")
        texts = [label["text"] for label in await rig.state("M.labels")]
        assert "target 1 known (T5)" in texts and "target 3 turning (T2)" in texts
        assert {"T2", "T5", "T7"} <= set(texts)
        assert not any(t.startswith("t0") or t.startswith("t2") for t in texts)
        table = await rig.page.text_content("#mission-table")
        assert table is not None and "target 1 known" in table and "T5, 2.00 m" in table
        # Every label inside the map and apart from the others.
        _labels_apart_and_inside(await rig.state("M.labels"), 760, 620)
        # The close-up follows the confirmed track with the lowest id, on its target.
        inset = await rig.state("M.inset")
        assert any(
            i["kind"] == "truth" and i["label"] == "target 3 turning" for i in inset["items"]
        )


# ---------------------------------------------------------------- C2: one target, as a track


async def test_a_single_target_is_drawn_as_one_track_through_the_tracks_path() -> None:
    config = load_scenario("paper").trace_config() | {"method": "horizon"}
    P = np.diag([0.16, 0.0625, 0.5, 0.5])
    uav_xy = [(1060.0, 1500.0), (960.0, 1545.0), (970.0, 1445.0)]

    def target(n: int) -> list[float]:
        return [700.0 + 25.0 * n, 1500.0, 25.0, 0.0]

    async with console_page(config) as rig:
        k = rig.keys
        rig.put(k.clock, _clock(12, 22.0, 10.0))
        for m, xy in enumerate(uav_xy):
            rig.put(k.telemetry(m), _telemetry(m, xy, slot=12, t_s=22.0))
        rig.put(k.plan, _plan(13, [0, 1, 2], [1 / 3] * 3, [list(xy) for xy in uav_xy]))
        # An older ground's feed: `truth` and `track` only.
        for n in range(9, 13):
            rig.put(k.truth, _envelope("truth", n, float(n), target_x=target(n)))
            estimate = [target(n)[0] + 0.3, target(n)[1] - 0.4, 25.0, 0.0]
            rig.put(k.track, _track(n, estimate, P))
        await rig.until(
            "S.latest.tracks && S.latest.tracks.slot === 12 && S.trackSeries.size >= 4 && "
            "M.charts.error && M.charts.error.length === 1 && M.charts.error[0].points >= 4 && "
            "document.getElementById('mission-table').textContent.includes('T1, 0.50 m')"
        )
        drawn = await rig.state("M.tracksDrawn")
        assert drawn == [{"id": 1, "confirmed": True, "x": 1000.3, "y": 1499.6}]
        truths = await rig.state("M.truthsDrawn")
        assert truths == [{"index": 0, "x": 1000.0, "y": 1500.0}]
        assert len(await rig.state("M.map.estimates")) == 1  # one drawing of the target
        texts = [label["text"] for label in await rig.state("M.labels")]
        assert "T1" in texts and "target 1 (T1)" in texts
        # The charts per track hold what the single target's did: the position bound and the
        # error per track, and the (lead) track's velocity bound.
        charts = await rig.state("M.charts")
        assert [c["label"] for c in charts["pcrb"]] == [
            "T1",
            "lead track velocity (m\u00b2/s\u00b2)",
        ]
        assert all(c["points"] >= 4 for c in charts["pcrb"]), charts["pcrb"]
        assert [c["label"] for c in charts["error"]] == ["T1"]
        table = await rig.page.text_content("#mission-table")
        assert table is not None and "tr(PCRB)" in table and "(lead track)" not in table
        assert f"{np.trace(P):.4f}" in table and "1 confirmed, 0 tentative" in table
        note = await rig.page.text_content("#inset-note")
        assert note is not None and "T1 follows target 1, 0.50 m off" in note
        assert await rig.state("document.getElementById('inset-track').hidden") is True

        # A ground that publishes `track_set` beside its lead `track`: the track_set wins, the
        # track of its slot draws no second target.
        rig.put(k.truth, _envelope("truth", 13, 13.0, target_x=target(13)))
        entry = {"id": 4, "confirmed": True, "x": [1025.2, 1500.1, 25.0, 0.0]}
        entry |= {"P": P.tolist(), "pcrb_position_trace": 0.2}
        rig.put(k.track, _envelope("track_set", 13, 13.0, tracks=[entry]))
        rig.put(k.track, _track(13, entry["x"], P))
        await rig.until(
            "S.latest.track && S.latest.track.slot === 13 && "
            "M.tracksDrawn.length && M.tracksDrawn[0].id === 4"
        )
        # The frame that drew the track too (it was scheduled when the track came).
        await rig.page.evaluate(
            "new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))"
        )
        assert await rig.state("M.tracksDrawn") == [
            {"id": 4, "confirmed": True, "x": 1025.2, "y": 1500.1}
        ]
        assert len(await rig.state("M.map.estimates")) == 1


# ---------------------------------------------------------------- D: vehicles as they are


async def test_vehicles_read_landed_and_their_share_and_bs_as_the_plan_says() -> None:
    config = load_scenario("paper").trace_config() | {"method": "horizon"}
    xy = [tuple(p) for p in config["uav_start_xy"]]
    wps = [list(p) for p in xy]
    active = {"0": "active", "1": "active", "2": "active"}

    async def row(rig: Rig, m: int, *parts: str) -> str:
        """Vehicle m's row, once it holds every one of `parts` (the panels follow the map
        within a quarter of a second)."""
        where = f"document.querySelector('#vehicles tr:nth-child({m + 1})')"
        await rig.until(
            " && ".join(f"{where}.textContent.includes({json.dumps(p)})" for p in parts) or "true"
        )
        text = await rig.page.text_content(f"#vehicles tr:nth-child({m + 1})")
        return text or ""

    async with console_page(config) as rig:
        k = rig.keys
        rig.put(k.health, _health(20, "running", active))
        rig.put(k.clock, _clock(20, 30.0, 10.0))
        for m in range(3):
            rig.put(k.telemetry(m), _telemetry(m, xy[m], slot=20, t_s=30.0))
        rig.put(k.plan, _plan(21, [0, 1, 2], [1 / 3] * 3, wps))
        await rig.until("S.latest.plan && S.latest.plan.slot === 21 && S.latest.clock")
        await rig.until(
            "document.getElementById('vehicles').textContent.includes('BS0 \u03b7 0.333')"
        )

        # U0 held: out of the plan, no BS and share 0, as the plan says.
        rig.put(k.telemetry(0), _telemetry(0, xy[0], mode="hold", override="control: hold"))
        rig.put(k.plan, _plan(22, [-1, 1, 2], [0.0, 0.5, 0.5], wps))
        rig.put(k.clock, _clock(21, 31.0, 10.0))
        u0 = await row(rig, 0, "no BS")
        assert "no BS \u03b7 0 " in u0 and "0.333" not in u0 and "BS0" not in u0, u0
        assert "BS1 \u03b7 0.500" in await row(rig, 1, "0.500")
        labels = [label["text"] for label in await rig.state("M.labels")]
        assert any(t.startswith("U0 \u00b7 hold \u00b7 no BS \u00b7 \u03b7 0") for t in labels)

        # The whole fleet held: nobody is served, every vehicle reads no BS and share 0.
        rig.put(k.plan, _plan(23, [-1, -1, -1], [0.0, 0.0, 0.0], wps))
        for m in range(3):
            assert "no BS \u03b7 0 " in await row(rig, m, "no BS")
        # No plan since (none published, or one the console refused) while the slots go on:
        # the page says the plan it shows is not the one being flown.
        rig.put(k.clock, _clock(25, 35.0, 10.0))
        text = await row(rig, 1, "slots old")
        assert "no BS \u03b7 0 (plan of slot 23, 3 slots old)" in text, text

        # The mission over: every vehicle landed reads landed, not active.
        rig.put(k.health, _health(60, "done", active))
        for m in range(3):
            rig.put(k.telemetry(m), _telemetry(m, xy[m], mode="land", armed=False, landed=True))
        rig.put(k.clock, _clock(75, 85.0, 10.0))
        await rig.until("document.getElementById('phase').dataset.phase === 'done'")
        for m in range(3):
            text = await row(rig, m, "landed, disarmed")
            assert text.startswith(f"U{m} landed, disarmed") and text.endswith("\u00b7 landed"), (
                text
            )
        labels = [label["text"] for label in await rig.state("M.labels")]
        for m in range(3):
            assert any(t.startswith(f"U{m} \u00b7 landed") for t in labels), labels


# ---------------------------------------------------------------- `view`


def _trace(path: Path, method: str, config: dict[str, Any], n_slots: int) -> None:
    """A trace of `n_slots` slots whose vehicles sit at their start points, each served by BS0."""
    M = int(config["M"])
    xy = np.array(config["uav_start_xy"], dtype=float)
    target = np.array(config["x0"], dtype=float)
    P = np.diag([0.16, 0.0625, 0.5, 0.5])
    with TraceWriter(path, config) as writer:
        for n in range(1, n_slots + 1):
            writer.write_slot(
                SlotRecord(
                    slot=n,
                    method=method,
                    status="ok",
                    uav_xy_m=xy,
                    bandwidth_share=np.full(M, 1.0 / M),
                    assoc=np.zeros(M, dtype=np.int64),
                    target_true=target,
                    target_est=target + np.array([0.3, 0.2, 0.0, 0.0]),
                    target_pred=target,
                    r_diag=np.ones(2 * M),
                    pcrb_trace=1.0,
                    solve_ms=10.0,
                    P=P,
                    J=np.linalg.inv(P),
                    plan_xy=xy + 5.0,
                )
            )


async def test_view_places_its_labels_apart_inside_the_map_with_one_replay_badge(
    tmp_path: Path,
) -> None:
    config = load_scenario("paper").trace_config()
    paths = []
    for method in ("proposed", "sd", "comm"):
        paths.append(tmp_path / f"{method}_run000.jsonl")
        _trace(paths[-1], method, config, 3)
    port = free_tcp_port()
    url = f"http://127.0.0.1:{port}/"
    proc = start(cli("view", *map(str, paths), "--console", f"127.0.0.1:{port}"))
    try:
        await asyncio.to_thread(wait_http, url, proc)
        async with browser() as b:
            page = await b.new_page(viewport={"width": 1400, "height": 1000})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            await page.goto(url)
            await page.wait_for_function(
                "window.consoleState.S.runs.length === 3 && window.consoleState.M.labels",
                timeout=WAIT_MS,
            )
            texts = [t["text"] for t in await page.evaluate("window.consoleState.M.labels")]
            # Three methods' vehicles on the same spots and one BS serving all nine.
            methods = ("proposed", "sd", "comm")
            assert {f"{r} U{m} \u00b7 \u03b7 0.33" for r in methods for m in (0, 1, 2)} <= set(
                texts
            )
            assert any(t.startswith("BS0 \u2192 proposed:U0") for t in texts)
            labels = await page.evaluate("window.consoleState.M.labels")
            _labels_apart_and_inside(labels, 760, 620)
            badges = await page.eval_on_selector_all(
                "header .badge", "bs => bs.filter(b => !b.hidden).map(b => b.textContent)"
            )
            assert badges.count("replay") == 1, badges
            inset = await page.evaluate("window.consoleState.M.inset")
            assert sum(i["kind"] == "estimate" for i in inset["items"]) == 3
            assert errors == []
    finally:
        stop(proc, 30)
