"""The operator console in a real headless Chromium (Playwright), over real missions.

- a live `run` on free ports: the page's slot counter advances, the UAV positions it draws are
  the telemetry's (within V_max / telemetry rate + 1 m), R_th set from the page reaches the ground
  loop, a screenshot is saved, and 20 WebSocket connections opened and dropped leave the service's
  planning and memory alone;
- `view` over `simulate` traces: slider, play/pause, two methods side by side;
- with Zenoh security on, a page without the operator password cannot send a control;
- `serve` (the world in a separate `sim`) serves the same live page, which names the mission's
  phase from take-off to landing and never shows a slot outside 1..N.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import shutil
import subprocess
import sys
import time
from collections import defaultdict
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from isac_mission.bus import BusSettings, ZenohBus
from isac_mission.bus.certs import generate_users_file
from isac_mission.bus.security import read_users_file, secured_settings
from isac_mission.config import ZenohSecurityConfig
from isac_mission.records import read_trace
from isac_mission.wire import ControlMsg, Keys, PlanMsg, TelemetryMsg, decode
from tests.support.browser import (
    browser,
    churn_websockets,
    post,
    rss_kib,
    short_config,
    start_run,
    stop,
    wait_http,
)
from tests.support.live_cli import ROOT, cli, serve_argv, sim_argv, start
from tests.support.ports import free_tcp_port, sitl_ports
from tests.support.sim_harness import async_wait_until

KEYS = Keys("paper")
PHASES = ["starting", "take-off", "running", "landing", "done"]
"""The phases the page names, in their order."""
PAGE_TIMEOUT_MS = 240_000
V_MAX_MPS = 25.0
TELEMETRY_HZ = 10.0


@dataclass
class Observer:
    """The test's own view of the bus: telemetry per vehicle (publish stamp, xy), plans
    (wall time of arrival, slot) and control requests."""

    telemetry: dict[int, list[tuple[float, list[float]]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    plans: list[tuple[float, int]] = field(default_factory=list)
    controls: list[dict[str, Any]] = field(default_factory=list)


@contextlib.asynccontextmanager
async def observe(settings: BusSettings) -> AsyncIterator[Observer]:
    """Watch the mission's keys with an independent Zenoh session (retrying until it is up)."""
    obs = Observer()
    deadline = time.monotonic() + 120
    while True:
        try:
            bus = await ZenohBus.open_async(settings)
            break
        except Exception:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.5)

    async def pump() -> None:
        async with bus.subscribe(KEYS.everything, maxsize=8192) as sub:
            async for key, payload in sub:
                if key.startswith(KEYS.prefix + "/telemetry/"):
                    t = decode(TelemetryMsg, payload)
                    assert t.published_wall_s is not None
                    obs.telemetry[t.uav].append((t.published_wall_s, list(t.position_xy_m)))
                elif key == KEYS.plan:
                    obs.plans.append((time.monotonic(), decode(PlanMsg, payload).slot))
                elif key == KEYS.control:
                    obs.controls.append(json.loads(payload))
                    decode(ControlMsg, payload)

    task = asyncio.create_task(pump())
    try:
        yield obs
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        bus.close()


RECORD_SLOTS = """
window.__slotTexts = [];
document.addEventListener("DOMContentLoaded", () => {
  const e = document.getElementById("slot");
  new MutationObserver(() => window.__slotTexts.push(e.textContent))
    .observe(e, { childList: true, characterData: true, subtree: true });
});
"""
"""Records every text the page's slot counter shows."""


async def slot_of(page: Any) -> int:
    return int(await page.eval_on_selector("#slot", "e => Number(e.dataset.slot || -1)"))


async def wait_slot(page: Any, n: int) -> None:
    await page.wait_for_function(
        f"Number(document.getElementById('slot').dataset.slot || -1) >= {n}",
        timeout=PAGE_TIMEOUT_MS,
    )


async def test_live_console_draws_the_telemetry_commands_and_survives_connection_churn(
    tmp_path: Path,
) -> None:
    config = short_config(tmp_path, 150)
    proc, url, endpoint = start_run(config, tmp_path / "run", 2.0)
    try:
        await asyncio.to_thread(wait_http, url, proc)
        client = BusSettings(mode="client", connect=(endpoint,), connect_timeout_ms=2000)
        async with observe(client) as obs, browser() as b:
            page = await b.new_page(viewport={"width": 1400, "height": 900})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            await page.goto(url)
            await wait_slot(page, 2)
            first = await slot_of(page)
            await wait_slot(page, first + 2)

            # The positions drawn are the telemetry's.
            drawn = await page.evaluate("window.consoleState.M.drawn")
            assert sorted(drawn) == ["0", "1", "2"]
            tolerance_m = V_MAX_MPS / TELEMETRY_HZ + 1.0
            for m, d in drawn.items():
                history = obs.telemetry[int(m)]
                assert history, f"the test saw no telemetry of vehicle {m}"
                stamp, xy = min(history, key=lambda h: abs(h[0] - d["published_wall_s"]))
                assert abs(stamp - d["published_wall_s"]) < 1.0
                gap = math.hypot(xy[0] - d["x"], xy[1] - d["y"])
                assert gap <= tolerance_m, (m, d, xy)
                assert history[-1][0] - d["published_wall_s"] < 10.0  # a recent one

            # 20 WebSocket connections opened and dropped, three times over: each is served
            # its snapshot, the service goes on planning, its memory stays (the plan rate
            # during the churn, a wall-clock figure, is bench/console_churn.py's). Before the
            # commands, so that the memory measured is the churn's alone.
            rss0 = rss_kib(proc.pid)
            plans_before = len(obs.plans)
            await churn_websockets(url, rounds=3, connections=20)
            await async_wait_until(
                lambda: len(obs.plans) > plans_before, 120.0, "a plan after the churn"
            )
            rss1 = rss_kib(proc.pid)
            assert rss1 <= 1.1 * rss0, (rss0, rss1)
            # The dropped connections are gone: only the browser's page is left.
            deadline = time.monotonic() + 60
            while True:
                snap = await asyncio.to_thread(wait_http, url, proc)
                if snap["console"]["pages"] == 1 or time.monotonic() > deadline:
                    break
                await asyncio.sleep(0.5)
            assert snap["console"]["pages"] == 1

            # R_th from the page reaches the ground loop, and its reply is shown.
            await page.fill("#rth", "12")
            await page.click("#set-rth")
            await page.wait_for_selector(
                "#replies li[data-state='accepted']", timeout=PAGE_TIMEOUT_MS
            )
            reply = await page.text_content("#replies li[data-state='accepted']")
            assert reply is not None and reply.startswith("set") and "accepted" in reply
            # A command the ground loop refuses (release of a vehicle it does not exclude) is
            # shown refused with its reason.
            await page.select_option("#uav-select", "1")
            await page.click("button[data-command='release']")
            await page.wait_for_selector(
                "#replies li[data-state='refused']", timeout=PAGE_TIMEOUT_MS
            )
            refused = await page.text_content("#replies li[data-state='refused']")
            assert refused is not None and "release U1: refused" in refused
            # hold and resume one vehicle: both accepted.
            for command in ("hold", "resume"):
                await page.select_option("#uav-select", "2")
                await page.click(f"button[data-command='{command}']")
                await page.wait_for_function(
                    "[...document.querySelectorAll(\"#replies li[data-state='accepted']\")]"
                    f".some(li => li.textContent.startsWith('{command} U2'))",
                    timeout=PAGE_TIMEOUT_MS,
                )
            assert any(c.get("params") == {"rate_min_mbps": 12.0} for c in obs.controls)
            # ... and a malformed one is refused on the page, and nothing is sent.
            sent = len(obs.controls)
            await page.fill("#rth", "fast")
            await page.click("#set-rth")
            msg = await page.text_content("#control-msg")
            assert msg is not None and "is not a number" in msg and "nothing sent" in msg
            status, answer = await asyncio.to_thread(
                post, url, "api/control", {"command": "set", "params": {"rate_min_mbps": -1}}
            )
            assert status == 422 and answer["field"] == "control.params.rate_min_mbps"
            await asyncio.sleep(1.0)
            assert len(obs.controls) == sent

            shot = tmp_path / "console.png"
            await page.screenshot(path=str(shot), full_page=True)
            assert shot.stat().st_size > 20_000
            if (target := _screenshot_target()) is not None:
                shutil.copy(shot, target)

            assert errors == []
    finally:
        out = stop(proc)
    assert proc.returncode == 0, out[-3000:]


def _screenshot_target() -> Path | None:
    """docs/console.png when ISAC_CONSOLE_SCREENSHOT=docs is set (refreshing the README's)."""
    import os

    return ROOT / "docs" / "console.png" if os.environ.get("ISAC_CONSOLE_SCREENSHOT") else None


async def test_view_replays_simulate_traces_side_by_side(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "isac_mission.cli",
            "simulate",
            "config/paper.yaml",
            "--out",
            str(out),
            "--runs",
            "1",
            "--methods",
            "proposed,sd",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    traces = sorted((out / "traces").glob("*_run000.jsonl"))
    assert len(traces) == 2
    port = free_tcp_port()
    url = f"http://127.0.0.1:{port}/"
    proc = start(cli("view", *map(str, traces), "--console", f"127.0.0.1:{port}"))
    try:
        snap = await asyncio.to_thread(wait_http, url, proc)
        assert snap["mode"] == "replay"
        async with browser() as b:
            page = await b.new_page()
            await page.goto(url)
            await page.wait_for_function("window.consoleState.S.runs.length === 2")
            assert await page.get_attribute("#slider", "max") == "60"
            await page.evaluate(
                "() => { const s = document.getElementById('slider'); s.value = '30';"
                " s.dispatchEvent(new Event('input')); }"
            )
            assert await slot_of(page) == 30
            drawn = await page.evaluate("window.consoleState.M.replayDrawn")
            for layer, path in zip(drawn, traces, strict=True):
                trace = read_trace(path)
                assert layer["label"] == trace.method
                expected = trace.slots[29].uav_xy_m
                for xy, want in zip(layer["uavs"], expected, strict=True):
                    assert xy == pytest.approx(list(want), abs=1e-9)
            await page.click("#play")
            await wait_slot(page, 33)
            await page.click("#play")
            paused = await slot_of(page)
            await asyncio.sleep(1.0)
            assert await slot_of(page) == paused
    finally:
        stop(proc, 30)


async def test_a_page_without_the_operator_password_cannot_send_a_control(tmp_path: Path) -> None:
    users = tmp_path / "zenoh-users.txt"
    generate_users_file(users, ("ground", "world", "operator", "observer"))
    passwords = read_users_file(users)
    config = short_config(tmp_path, 120, enabled=True, users_file=str(users))
    proc, url, endpoint = start_run(config, tmp_path / "run", 2.0)
    cfg = ZenohSecurityConfig(enabled=True, users_file=users)
    settings = secured_settings(
        cfg, "paper", "observer", mode="client", connect=(endpoint,), login_from_users_file=True
    )
    try:
        await asyncio.to_thread(wait_http, url, proc)
        async with observe(settings) as obs, browser() as b:
            page = await b.new_page()
            posted: list[str] = []
            page.on("request", lambda r: posted.append(r.url) if "/api/control" in r.url else None)
            await page.goto(url)
            await page.wait_for_function(
                "document.getElementById('role').textContent === 'read-only'",
                timeout=PAGE_TIMEOUT_MS,
            )
            await wait_slot(page, 1)
            await page.fill("#rth", "12")
            await page.click("#set-rth")
            msg = await page.text_content("#control-msg")
            assert msg is not None and "read-only" in msg
            assert posted == []
            # The server refuses it as well, naming the missing token.
            status, answer = await asyncio.to_thread(
                post, url, "api/control", {"command": "set", "params": {"rate_min_mbps": 12}}
            )
            assert (status, answer["field"]) == (403, "token")
            # A wrong password is refused; the operator's is accepted and its command goes out.
            await page.fill("#password", "not-the-password")
            await page.click("#login")
            await page.wait_for_function(
                "document.getElementById('control-msg').textContent.includes('login refused')",
                timeout=60_000,
            )
            assert obs.controls == []
            await page.fill("#password", passwords["operator"])
            await page.click("#login")
            await page.wait_for_function(
                "document.getElementById('role').textContent === 'operator'", timeout=60_000
            )
            await page.fill("#rth", "12")
            await page.click("#set-rth")
            deadline = time.monotonic() + 60
            while not obs.controls and time.monotonic() < deadline:
                await asyncio.sleep(0.2)
            assert [c["params"] for c in obs.controls] == [{"rate_min_mbps": 12.0}]
            assert len(posted) == 1
    finally:
        out = stop(proc)
    assert proc.returncode == 0, out[-3000:]


async def test_serve_serves_the_console_of_a_mission_whose_world_runs_elsewhere(
    tmp_path: Path,
) -> None:
    config = short_config(tmp_path, 12)
    ports = sitl_ports(3)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    port = free_tcp_port()
    url = f"http://127.0.0.1:{port}/"
    serve = start(
        serve_argv(
            config,
            tmp_path / "out",
            endpoint,
            ports.offboard_base,
            "--console",
            f"127.0.0.1:{port}",
        )
    )
    world: subprocess.Popen[str] | None = None
    try:
        await asyncio.to_thread(wait_http, url, serve)
        async with browser() as b:
            page = await b.new_page()
            await page.add_init_script(RECORD_SLOTS)
            await page.goto(url)
            # The world starts once the page is open: `serve` flies nothing before it, so the
            # page cannot miss the mission (a 12-slot mission at --speed 10 lasts seconds, about
            # what starting Chromium takes on a loaded machine: CI once saw an empty map).
            world = start(sim_argv(config, endpoint, ports))
            await wait_slot(page, 3)
            # The slot label and the vehicles are drawn from different streams: wait for both.
            await page.wait_for_function(
                "Object.keys(window.consoleState.M.drawn).length >= 3", timeout=PAGE_TIMEOUT_MS
            )
            drawn = await page.evaluate("window.consoleState.M.drawn")
            assert sorted(drawn) == ["0", "1", "2"]
            # Through the take-off the slot counter showed no slot (the clock said -1).
            texts = await page.evaluate("window.__slotTexts")
            assert texts and all(t == "-" or 1 <= int(t) <= 12 for t in texts), texts
            # After the 12 slots the page says the fleet lands (the world's clock counts on).
            await page.wait_for_function(
                "['landing', 'done'].includes(document.getElementById('phase').dataset.phase)",
                timeout=PAGE_TIMEOUT_MS,
            )
            texts = await page.evaluate("window.__slotTexts")
            phases = [e["phase"] for e in await page.evaluate("window.consoleState.M.phaseLog")]
        out, err = await asyncio.to_thread(serve.communicate, None, 300)
        assert serve.returncode == 0, err[-3000:]
        assert f"console: {url}" in out
        # The slot counter showed only slots of the mission (the clock's -1 before the start
        # and its slots past N never), through the phases in their order.
        assert texts and all(t == "-" or 1 <= int(t) <= 12 for t in texts), texts
        seen = [p for i, p in enumerate(phases) if i == 0 or p != phases[i - 1]]
        assert seen[0] in ("starting", "take-off") and seen[-1] in ("landing", "done"), seen
        assert "running" in seen and seen == sorted(seen, key=PHASES.index), seen
    finally:
        if world is not None:
            stop(world, 60)
        stop(serve, 60)
