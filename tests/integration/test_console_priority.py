"""Track priorities on the console page in a real headless Chromium, over a real GroundLoop and
the simulated world on a real Zenoh hub on loopback (the console joins it as it joins a `run`):

- the Tracks table lists the ground loop's track (T1) with its priority, 1;
- text that is no number is refused by the page, a weight out of range by the console (the bus's
  model, naming the field), and nothing is sent;
- a good weight typed in T1's row goes out as `priority`, the row shows the ground loop's reply
  (accepted, from which slot), and then the priority the ground loop's tracks carry;
- a request for a track that does not exist is listed refused with the ground loop's reason;
- `view` over the trace the loop wrote shows the tracks' priorities read-only (no input).
"""

from __future__ import annotations

import asyncio
import re
import time
from pathlib import Path
from typing import Any

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import Scenario
from isac_mission.console import (
    BusAccess,
    ConsoleAddress,
    ConsoleServer,
    ConsoleService,
    MissionView,
)
from isac_mission.console.replay import load_replay, replay_config
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.settings import GroundSettings
from sim.world import run_world
from sim.world_options import WorldOptions
from tests.support.browser import browser, post
from tests.support.ports import free_tcp_port, sitl_ports

TIMEOUT_S = 60.0
WAIT_MS = int(TIMEOUT_S * 1000)
SLOTS = 80
ROW = 'tr[data-track="1"]'


async def _until(page: Any, expression: str) -> None:
    """Wait (bounded) until a JavaScript expression over the page holds."""
    await page.wait_for_function(
        f"(() => {{ const S = window.consoleState.S, M = window.consoleState.M; "
        f"try {{ return !!({expression}); }} catch (e) {{ return false; }} }})()",
        timeout=WAIT_MS,
        polling=50,
    )


async def _note(page: Any) -> str:
    text: str = await page.inner_text(f"{ROW} .prio-note")
    return text


async def test_the_operator_sets_a_tracks_priority_from_the_page(
    paper: Scenario, tmp_path: Path
) -> None:
    s = paper.with_changes(N=SLOTS)
    endpoint = tcp_loopback(free_tcp_port())
    trace = tmp_path / "live.jsonl"
    service = ConsoleService(MissionView(s.trace_config()), BusAccess(s.mission_id, endpoint))
    server = ConsoleServer(service, ConsoleAddress("127.0.0.1", free_tcp_port()))
    url = server.start()
    stop_world, stop_ground = asyncio.Event(), asyncio.Event()
    try:
        with ZenohBus.open(BusSettings.hub(endpoint)) as bus:
            loop = GroundLoop(s, bus, GroundSettings(trace_path=trace))
            opts = WorldOptions(
                speed=4.0,
                lockstep=True,
                lockstep_timeout_s=20.0,
                bus=BusSettings(connect=(endpoint,)),
                **sitl_ports(3).world_kwargs(),
                seed=2,
            )
            ground = asyncio.create_task(loop.run(stop_ground))
            world = asyncio.create_task(run_world(s, opts, stop_world))
            try:
                async with browser() as b:
                    deadline = time.monotonic() + TIMEOUT_S
                    while service.status != "watching":
                        assert time.monotonic() < deadline, "the console never joined the bus"
                        await asyncio.sleep(0.05)
                    page = await b.new_page(viewport={"width": 1400, "height": 1000})
                    errors: list[str] = []
                    page.on("pageerror", lambda e: errors.append(str(e)))
                    await page.goto(url)
                    await _operate(page, url)
                    assert errors == []
            finally:
                stop_ground.set()
                stop_world.set()
                await asyncio.wait_for(world, timeout=30)
                report = await asyncio.wait_for(ground, timeout=30)
    finally:
        server.stop()
    counters = report.counters
    assert counters["operator commands"] == 1, counters
    assert counters["operator commands refused"] == 1, counters
    assert not [k for k in counters if k.startswith(("rejected", "internal"))], counters
    await _replay(trace)


async def _operate(page: Any, url: str) -> None:
    await _until(page, "S.mode === 'live' && (M.tracksTable || []).length === 1")
    assert await page.evaluate("window.consoleState.M.tracksTable") == [
        {"id": 1, "confirmed": True, "priority": "1"}
    ]
    assert await page.inner_text(f"{ROW} td.prio") == "1"
    assert await page.inner_text(f"{ROW} td.track") == "T1"

    # Refused before anything is sent: by the page (no number), by the console (out of range).
    await page.fill(f"{ROW} input", "lots")
    await page.click(f"{ROW} button")
    await _until(page, "document.querySelector('tr[data-track=\"1\"]').dataset.state === 'error'")
    assert await _note(page) == 'priority of T1: "lots" is not a number (nothing sent)'
    await page.fill(f"{ROW} input", "12")
    await page.press(f"{ROW} input", "Enter")
    await _until(
        page,
        "document.querySelector('tr[data-track=\"1\"] .prio-note').textContent.includes('12 is')",
    )
    assert await _note(page) == (
        "refused (HTTP 422): control.params.weight: 12 is above 10; nothing sent"
    )
    assert await page.evaluate("Object.keys(window.consoleState.S.sent).length") == 0

    # A good one: sent, answered, then shown as the ground loop's tracks carry it.
    await page.fill(f"{ROW} input", "3.5")
    await page.click(f"{ROW} button")
    await _until(
        page, "document.querySelector('tr[data-track=\"1\"]').dataset.state === 'accepted'"
    )
    note = await _note(page)
    m = re.fullmatch(r"accepted: track 1: priority 3\.5 from slot (\d+) on", note)
    assert m is not None, note
    await _until(page, "M.tracksTable[0].priority === '3.5'")
    assert await page.inner_text(f"{ROW} td.prio") == "3.5"
    sent = await page.evaluate("Object.values(window.consoleState.S.sent)")
    assert [e["request"] for e in sent] == [
        {"command": "priority", "params": {"weight": 3.5}, "track": 1}
    ]
    item = await page.inner_text("#replies li[data-state=accepted]")
    assert item.startswith('priority T1 {"weight":3.5}: accepted'), item

    # A track the ground loop does not have: its refusal is listed with the loop's reason.
    status, answer = await asyncio.to_thread(
        post, url, "api/control", {"command": "priority", "track": 7, "params": {"weight": 2}}
    )
    assert status == 202, answer
    await _until(page, "document.querySelector('#replies li[data-state=refused]')")
    refused = await page.inner_text("#replies li[data-state=refused]")
    assert refused.startswith('priority T7 {"weight":2}: refused'), refused
    assert "no track 7" in refused, refused
    # On until the slot the reply named is traced (planned with 3.5), for the replay below.
    await _until(page, f"S.latest.tracks.slot >= {int(m.group(1))}")


async def _replay(trace: Path) -> None:
    """`view` over the loop's trace: the tracks table shows each slot's priorities, read-only."""
    replay = load_replay([trace])
    frames = replay["runs"][0]["frames"]
    assert frames, "the loop traced no slot"
    last = len(frames)
    # The trace records the priority each slot was planned with: 1 at first, 3.5 at the end.
    assert [_shown(t["priority"]) for t in frames[0]["tracks"]] == ["1"]
    assert [_shown(t["priority"]) for t in frames[-1]["tracks"]] == ["3.5"]
    service = ConsoleService(MissionView(replay_config(replay)), None)
    server = ConsoleServer(service, ConsoleAddress("127.0.0.1", free_tcp_port()), replay=replay)
    url = server.start()
    try:
        async with browser() as b:
            page = await b.new_page(viewport={"width": 1400, "height": 1000})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            await page.goto(url)
            await _until(page, "S.mode === 'replay' && S.runs.length === 1")
            for frame, want in ((1, "1"), (last, "3.5")):
                await page.eval_on_selector(
                    "#slider",
                    f"(e) => {{ e.value = '{frame}'; e.dispatchEvent(new Event('input')); }}",
                )
                await _until(page, f"S.frame === {frame}")
                rows = await page.evaluate("window.consoleState.M.tracksTable")
                assert rows == [{"id": 1, "confirmed": True, "priority": want}], (frame, rows)
                assert await page.inner_text(f"{ROW} td.prio") == want
            assert await page.eval_on_selector_all("#tracks-table input", "es => es.length") == 0
            assert await page.eval_on_selector("#controls", "e => e.hidden")
            note = await page.inner_text("#tracks-note")
            assert note.startswith("priority (read-only)"), note
            assert errors == []
    finally:
        server.stop()


def _shown(priority: float) -> str:
    """A priority as the page writes it (3.5, 1, 0)."""
    return f"{priority:g}"
