"""The console's server over a real Zenoh hub and real HTTP / WebSocket clients on loopback:
bus messages reach a page as updates (bad ones counted, not shown), every bad web request gets a
4xx naming the field and sends nothing, a good command goes out on `control`, a page that
never reads does not hold up the others, and a multi-target mission's tracks are drawn by a real
headless Chromium."""

from __future__ import annotations

import asyncio
import json
import time
import urllib.error
import urllib.request
from typing import Any

import numpy as np
import pytest
import websockets

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import load_scenario
from isac_mission.console import (
    BusAccess,
    ConsoleAddress,
    ConsoleServer,
    ConsoleService,
    MissionView,
)
from isac_mission.wire import (
    ControlMsg,
    Keys,
    TelemetryMsg,
    TrackEntry,
    TrackSetMsg,
    decode,
    encode,
)
from tests.support.browser import browser
from tests.support.ports import free_tcp_port

TIMEOUT_S = 30.0
KEYS = Keys("paper")


def _post(url: str, body: bytes, content_type: str = "application/json") -> tuple[int, Any]:
    req = urllib.request.Request(
        url + "api/control", data=body, headers={"Content-Type": content_type}, method="POST"
    )
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.load(r)
    except urllib.error.HTTPError as err:
        return err.code, json.load(err)


def _telemetry(uav: int, x_m: float) -> bytes:
    msg = TelemetryMsg(
        3,
        3.0,
        uav,
        np.array([x_m, 5.0]),
        100.0,
        np.zeros(2),
        "offboard",
        True,
        False,
        "ok",
        published_wall_s=time.time(),
    )
    return encode(msg)


async def _until(pred: Any, what: str) -> None:
    deadline = time.monotonic() + TIMEOUT_S
    while not pred():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.05)


async def test_console_server_pushes_bus_updates_and_validates_every_request() -> None:
    endpoint = tcp_loopback(free_tcp_port())
    s = load_scenario("paper")
    service = ConsoleService(MissionView(s.trace_config()), BusAccess("paper", endpoint))
    server = ConsoleServer(service, ConsoleAddress("127.0.0.1", free_tcp_port()))
    url = server.start()
    ws_url = url.replace("http://", "ws://") + "ws"
    try:
        async with await ZenohBus.open_async(BusSettings.hub(endpoint)) as hub:
            await _until(lambda: service.status == "watching", "the console's bus")
            async with (
                hub.subscribe(KEYS.control) as controls,
                websockets.connect(ws_url) as page,
                websockets.connect(ws_url) as stalled,
            ):
                first = json.loads(await asyncio.wait_for(page.recv(), TIMEOUT_S))
                assert first[0]["topic"] == "snapshot"
                assert first[0]["data"]["config"]["M"] == 3
                await asyncio.wait_for(stalled.recv(), TIMEOUT_S)  # then it never reads again
                await hub.wait_for_subscribers(KEYS.telemetry(1), TIMEOUT_S)
                hub.publish(KEYS.telemetry(1), b"garbage")
                for i in range(2000):
                    hub.publish(KEYS.telemetry(1), _telemetry(1, float(i)))
                seen: list[float] = []
                deadline = time.monotonic() + TIMEOUT_S
                while (not seen or seen[-1] < 1999.0) and time.monotonic() < deadline:
                    for u in json.loads(await asyncio.wait_for(page.recv(), TIMEOUT_S)):
                        if u["topic"] == "telemetry/1":
                            seen.append(u["data"]["position_xy_m"][0])
                assert seen and seen[-1] == 1999.0  # the newest, whatever was coalesced
                assert seen == sorted(seen)
                assert service.view.rejected["payload not JSON"] == 1

                # Bad requests: 4xx naming the field; nothing on the bus.
                for body, ctype, status, field in (
                    (b'{"command": "set"}', "text/plain", 415, "content-type"),
                    (b"{", "application/json", 400, "body"),
                    (b'{"command": "fly"}', "application/json", 422, "command"),
                    (b'{"command": "set", "x": 1}', "application/json", 422, "x"),
                    (
                        b'{"command": "set", "params": {"rate_min_mbps": 0}}',
                        "application/json",
                        422,
                        "control.params.rate_min_mbps",
                    ),
                    (b'{"command": "release"}', "application/json", 422, "control.uav"),
                    (b'{"command": "hold", "uav": 3}', "application/json", 422, "control.uav"),
                ):
                    got, answer = await asyncio.to_thread(_post, url, body, ctype)
                    assert (got, answer["field"]) == (status, field), answer
                # A good one goes out, validated by the ground loop's own decoder.
                got, answer = await asyncio.to_thread(
                    _post, url, b'{"command": "set", "params": {"rate_min_mbps": 15}}'
                )
                assert got == 202
                key, payload = await controls.get(TIMEOUT_S)
                assert key == KEYS.control
                sent = decode(ControlMsg, payload)
                assert sent.params == {"rate_min_mbps": 15.0}
                assert json.loads(payload)["id"] == answer["id"]
                # Nothing else was sent: the refused requests never reached the bus.
                try:
                    extra = await controls.get(1.0)
                except TimeoutError:
                    extra = None
                assert extra is None
    finally:
        server.stop()


_RECORD_TEXT = """
window.__drawnText = [];
const fillText = CanvasRenderingContext2D.prototype.fillText;
CanvasRenderingContext2D.prototype.fillText = function (text, ...rest) {
  if (this.canvas.id === "map") window.__drawnText.push(String(text));
  return fillText.call(this, text, ...rest);
};
"""
"""Records every text the page paints on the map canvas."""


async def test_a_page_draws_both_tracks_of_a_track_set_with_their_ids() -> None:
    endpoint = tcp_loopback(free_tcp_port())
    s = load_scenario("paper")
    service = ConsoleService(MissionView(s.trace_config()), BusAccess("paper", endpoint))
    server = ConsoleServer(service, ConsoleAddress("127.0.0.1", free_tcp_port()))
    url = server.start()
    P = np.diag([400.0, 100.0, 1.0, 1.0])
    tracks = (
        TrackEntry(3, True, np.array([400.0, 500.0, 0.0, 0.0]), P, 1.0),
        TrackEntry(7, False, np.array([900.0, 300.0, 0.0, 0.0]), P, 2.0),
    )
    try:
        async with (
            await ZenohBus.open_async(BusSettings.hub(endpoint)) as hub,
            browser() as b,
        ):
            await _until(lambda: service.status == "watching", "the console's bus")
            page = await b.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            await page.add_init_script(_RECORD_TEXT)
            await page.goto(url)
            await page.wait_for_function("window.consoleState.S.mode === 'live'")
            await hub.wait_for_subscribers(KEYS.track, TIMEOUT_S)
            hub.publish(KEYS.track, encode(TrackSetMsg(4, 4.0, tracks)))
            await page.wait_for_function(
                "(window.consoleState.M.tracksDrawn || []).length === 2",
                timeout=TIMEOUT_S * 1000,
            )
            drawn = await page.evaluate("window.consoleState.M.tracksDrawn")
            assert drawn == [
                {"id": 3, "confirmed": True, "x": 400.0, "y": 500.0},
                {"id": 7, "confirmed": False, "x": 900.0, "y": 300.0},
            ]
            texts = await page.evaluate("window.__drawnText")
            assert "T3" in texts and "T7" in texts
            assert errors == []
    finally:
        server.stop()


def test_a_busy_console_port_is_reported_and_the_mission_goes_on(
    capsys: pytest.CaptureFixture[str],
) -> None:
    import socket

    from isac_mission.cli.view import start_live_console
    from isac_mission.config import load_scenario
    from isac_mission.console.server import ConsoleAddress, ConsolePortBusyError, bind

    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen(1)
    port = taken.getsockname()[1]
    try:
        with pytest.raises(ConsolePortBusyError) as info:
            bind(ConsoleAddress("127.0.0.1", port))
        text = str(info.value)
        assert f"port {port}" in text and "--console HOST:PORT" in text and "--no-console" in text
        server = start_live_console(
            load_scenario("paper"), "proposed", "tcp/127.0.0.1:7447", f"127.0.0.1:{port}"
        )
        assert server is None
        err = " ".join(capsys.readouterr().err.split())
        assert f"port {port}" in err and "runs without the console" in err
    finally:
        taken.close()
