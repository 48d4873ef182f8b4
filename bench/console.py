"""The operator console's figures, measured in a real headless Chromium, and the service's timing
with and without the console.

Runs short live missions in this process (`run_embedded`: world, MAVLink bridges, ground loop over
loopback UDP and Zenoh; at --speed 1, H lowered to 30 m so take-off and landing take seconds),
alternating console off and console on. With the console on, a separate client process (this file
with --client) opens the page in Chromium and ten non-rendering WebSocket clients, and watches the
bus with its own Zenoh session. It measures, in the browser:
- telemetry to screen: from a telemetry message's `published_wall_s` to the animation frame that
  drew it (median, p95; target median <= 200 ms);
- the share of the vehicles' telemetry messages drawn (target >= 95 %), against every message
  the client's own session saw in the window;
- page load to first drawn map (navigation start to the first map frame; target <= 1 s), over
  five reloads;
and, over a 60-slot `simulate` trace in `view`, the redraw time per slider step (p95 <= 50 ms).
From the service: setpoint period jitter p99 (|period - 50 ms|, all vehicles) and the
detection-to-setpoint median, console off (repeated) and on.

Run: python bench/console.py [--slots 30] [--off-runs 3] [--on-runs 2]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-background-networking", "--disable-component-update"]


def _free_tcp_port() -> int:
    from tests.support.ports import free_port_block

    return free_port_block(1, socket.SOCK_STREAM)


# ------------------------------------------------------------------------------ the client


async def _client(url: str, endpoint: str, seconds: float, out: Path) -> None:
    """Chromium on the page + 10 non-rendering WebSocket clients + an own bus observer."""
    import websockets
    from playwright.async_api import async_playwright

    from isac_mission.bus import BusSettings, ZenohBus

    published: list[tuple[int, float]] = []
    bus = None
    for _ in range(240):
        try:
            bus = await ZenohBus.open_async(
                BusSettings(mode="client", connect=(endpoint,), connect_timeout_ms=2000)
            )
            break
        except Exception:
            await asyncio.sleep(0.5)
    assert bus is not None

    async def watch() -> None:
        from isac_mission.wire import TelemetryMsg, decode

        async with bus.subscribe("isac/*/telemetry/*", maxsize=8192) as sub:
            async for _key, payload in sub:
                t = decode(TelemetryMsg, payload)
                if t.published_wall_s is not None:
                    published.append((t.uav, t.published_wall_s))

    async def silent(ws_url: str) -> None:
        async with websockets.connect(ws_url, max_size=None) as ws:
            async for _ in ws:
                pass

    watcher = asyncio.create_task(watch())
    ws_url = url.replace("http://", "ws://") + "ws"
    result: dict[str, Any] = {}
    async with async_playwright() as p:
        b = await p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = await b.new_page(viewport={"width": 1400, "height": 900})
        # Wait for the console, then for the mission's telemetry.
        for _ in range(600):
            try:
                await page.goto(url)
                break
            except Exception:
                await asyncio.sleep(0.5)
        await page.wait_for_function(
            "window.consoleState.M.telemetryDrawn > 10", timeout=600_000, polling=200
        )
        first_map = []
        for _ in range(5):
            await page.reload()
            await page.wait_for_function("window.consoleState.M.firstMapWallMs !== null")
            first_map.append(
                await page.evaluate("window.consoleState.M.firstMapWallMs - performance.timeOrigin")
            )
        silents = [asyncio.create_task(silent(ws_url)) for _ in range(10)]
        await asyncio.sleep(2.0)
        t0 = time.time()
        await page.evaluate(
            "window.consoleState.M.latenciesMs = []; window.consoleState.M.drawnIds = []"
        )
        await asyncio.sleep(seconds)
        t1 = time.time()
        await asyncio.sleep(1.0)
        m = await page.evaluate(
            "({lat: window.consoleState.M.latenciesMs, ids: window.consoleState.M.drawnIds})"
        )
        for t in silents:
            t.cancel()
        await b.close()
    watcher.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await watcher
    bus.close()
    window = {(u, s) for u, s in published if t0 + 0.5 <= s <= t1 - 0.5}
    drawn = {(int(u), float(s)) for u, s in m["ids"]}
    result["first_map_ms"] = first_map
    result["latency_ms"] = m["lat"]
    result["published"] = len(window)
    result["drawn"] = len(window & drawn)
    out.write_text(json.dumps(result))


async def _replay_client(url: str, out: Path) -> None:
    from playwright.async_api import async_playwright

    async with async_playwright() as p:
        b = await p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = await b.new_page(viewport={"width": 1400, "height": 900})
        await page.goto(url)
        await page.wait_for_function("window.consoleState.S.runs.length > 0")
        await page.evaluate("window.consoleState.M.redrawMs = []")
        for _ in range(3):
            for n in range(1, 61):
                await page.evaluate(
                    f"() => {{ const s = document.getElementById('slider'); s.value = '{n}';"
                    " s.dispatchEvent(new Event('input')); }"
                )
        redraw = await page.evaluate("window.consoleState.M.redrawMs")
        await b.close()
    out.write_text(json.dumps({"redraw_ms": redraw}))


# ------------------------------------------------------------------------------ the missions


async def _mission(slots: int, console: bool, tmp: Path, seconds: float) -> dict[str, Any]:
    from isac_mission.bus import tcp_loopback
    from isac_mission.cli.embedded import run_embedded
    from isac_mission.config import load_scenario
    from isac_mission.console import (
        BusAccess,
        ConsoleAddress,
        ConsoleServer,
        ConsoleService,
        MissionView,
    )
    from isac_mission.service.assembly import LiveOptions
    from tests.support.ports import sitl_ports

    s = load_scenario(ROOT / "config" / "paper.yaml").with_changes(N=slots, H=30.0, dH=15.0)
    endpoint = tcp_loopback(_free_tcp_port())
    opts = LiveOptions(
        speed=1.0,
        out_dir=tmp / f"run-{time.monotonic_ns()}",
        zenoh_endpoint=endpoint,
        **sitl_ports(s.M).world_kwargs(),
    )
    server = client = None
    client_out = tmp / f"client-{time.monotonic_ns()}.json"
    if console:
        view = MissionView(s.trace_config() | {"method": "proposed"})
        server = ConsoleServer(
            ConsoleService(view, BusAccess(s.mission_id, endpoint)),
            ConsoleAddress("127.0.0.1", _free_tcp_port()),
        )
        url = server.start()
        client = subprocess.Popen(
            [sys.executable, __file__, "--client", url, endpoint, str(seconds), str(client_out)],
            cwd=ROOT,
        )
    wall0 = time.monotonic()
    try:
        result = await run_embedded(s, opts, asyncio.Event())
    finally:
        if client is not None:
            await asyncio.to_thread(client.wait, 300)
        if server is not None:
            server.stop()
    wall_s = time.monotonic() - wall0
    jitter = np.concatenate(
        [np.abs(np.array(p) * 1e3 - 50.0) for p in result.setpoint_periods_s.values()]
    )
    out: dict[str, Any] = {
        "jitter_p99_ms": float(np.percentile(jitter, 99)),
        "det_to_setpoint_median_ms": float(np.median(result.detection_to_setpoint_s) * 1e3),
        "slots": len(result.report.records),
    }
    if server is not None:
        out["console_thread_cpu_pct"] = 100.0 * server.cpu_s / wall_s
    if console and client_out.exists():
        out["client"] = json.loads(client_out.read_text())
    return out


def _replay(tmp: Path) -> list[float]:
    from isac_mission.console import ConsoleAddress, ConsoleServer, ConsoleService, MissionView
    from isac_mission.console.replay import load_replay, replay_config

    sim = tmp / "sim"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "isac_mission.cli",
            "simulate",
            "config/paper.yaml",
            "--runs",
            "1",
            "--methods",
            "proposed,sd",
            "--out",
            str(sim),
        ],
        cwd=ROOT,
        check=True,
        capture_output=True,
    )
    replay = load_replay(sorted((sim / "traces").glob("*_run000.jsonl")))
    server = ConsoleServer(
        ConsoleService(MissionView(replay_config(replay)), None),
        ConsoleAddress("127.0.0.1", _free_tcp_port()),
        replay=replay,
    )
    url = server.start()
    out = tmp / "replay.json"
    try:
        subprocess.run(
            [sys.executable, __file__, "--replay-client", url, str(out)], cwd=ROOT, check=True
        )
    finally:
        server.stop()
    return list(json.loads(out.read_text())["redraw_ms"])


def _spread(values: list[float]) -> str:
    return f"{np.median(values):.2f} [{min(values):.2f}-{max(values):.2f}]"


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--client":
        asyncio.run(_client(sys.argv[2], sys.argv[3], float(sys.argv[4]), Path(sys.argv[5])))
        return
    if len(sys.argv) > 1 and sys.argv[1] == "--replay-client":
        asyncio.run(_replay_client(sys.argv[2], Path(sys.argv[3])))
        return
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--slots", type=int, default=30)
    ap.add_argument("--off-runs", type=int, default=3)
    ap.add_argument("--on-runs", type=int, default=2)
    args = ap.parse_args()
    from isac_mission.quiet import quiet_highs_banner

    quiet_highs_banner()
    order = ["off", "on"] * max(args.off_runs, args.on_runs)
    runs: dict[str, list[dict[str, Any]]] = {"off": [], "on": []}
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        for kind in order:
            if len(runs[kind]) >= (args.off_runs if kind == "off" else args.on_runs):
                continue
            r = asyncio.run(_mission(args.slots, kind == "on", tmp, seconds=args.slots * 0.5))
            runs[kind].append(r)
            print(f"console {kind}: {json.dumps({k: v for k, v in r.items() if k != 'client'})}")
        redraw = _replay(tmp)
    lat = [x for r in runs["on"] for x in r["client"]["latency_ms"]]
    first = [x for r in runs["on"] for x in r["client"]["first_map_ms"]]
    pub = sum(r["client"]["published"] for r in runs["on"])
    drawn = sum(r["client"]["drawn"] for r in runs["on"])
    print()
    print(f"{'figure':<52} {'measured':>22} {'target':>12}")
    print(f"{'telemetry to screen, median (ms)':<52} {np.median(lat):>22.1f} {'<= 200':>12}")
    print(f"{'telemetry to screen, p95 (ms)':<52} {np.percentile(lat, 95):>22.1f} {'':>12}")
    share = 100.0 * drawn / max(pub, 1)
    print(
        f"{'telemetry messages drawn at --speed 1 (%)':<52} {share:>17.1f} ({drawn}/{pub}) {'>= 95':>6}"
    )
    print(
        f"{'page load to first drawn map, median (ms)':<52} {np.median(first):>22.1f} {'<= 1000':>12}"
    )
    print(
        f"{'replay redraw per slider step, p95 (ms)':<52} {np.percentile(redraw, 95):>22.2f} {'<= 50':>12}"
    )
    print()
    print(
        f"{'service (1 browser + 10 WebSocket clients)':<44} {'console off':>20} {'console on':>20} {'ratio':>7}"
    )
    for key, name in (
        ("jitter_p99_ms", "setpoint period jitter p99 (ms)"),
        ("det_to_setpoint_median_ms", "detection-to-setpoint median (ms)"),
    ):
        off = [r[key] for r in runs["off"]]
        on = [r[key] for r in runs["on"]]
        print(
            f"{name:<44} {_spread(off):>20} {_spread(on):>20} {np.median(on) / np.median(off):>7.2f}"
        )
    print(
        f"(median [min-max] over {len(runs['off'])} console-off and {len(runs['on'])} console-on runs of {args.slots} slots)"
    )


if __name__ == "__main__":
    main()
