"""A real headless Chromium for the console tests (Debian's `chromium`, driven by Playwright),
and the `run` / `view` processes they open it on.

`scripts/test.sh` installs Chromium when it is missing; without it these tests fail with the
command that installs it (they never skip). Chromium runs with its background networking off,
so no request leaves loopback.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import time
import urllib.request
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any, Final

import yaml

from tests.support.live_cli import ROOT, cli, start
from tests.support.ports import free_tcp_port, sitl_ports

CHROMIUM: Final = "/usr/bin/chromium"
ARGS: Final = (
    "--no-sandbox",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-default-apps",
    "--no-first-run",
)


@contextlib.asynccontextmanager
async def browser() -> AsyncIterator[Any]:
    """A headless Chromium (playwright.async_api Browser)."""
    from playwright.async_api import async_playwright

    if not Path(CHROMIUM).exists():
        raise AssertionError(
            f"{CHROMIUM} is missing: run scripts/test.sh, or apt-get install -y chromium"
        )
    async with async_playwright() as p:
        b = await p.chromium.launch(executable_path=CHROMIUM, args=list(ARGS), headless=True)
        try:
            yield b
        finally:
            await b.close()


def short_config(tmp: Path, duration_s: float, **security: Any) -> Path:
    """config/paper.yaml cut to `duration_s` seconds of slots, with security.zenoh settings."""
    cfg = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    cfg["timing"]["duration_s"] = duration_s
    if security:
        cfg.setdefault("security", {})["zenoh"] = security
    path = tmp / "console.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def start_run(
    config: Path, out: Path, speed: float, *extra: str
) -> tuple[subprocess.Popen[str], str, str]:
    """`isac-mission run` with the console on a free port; (process, page URL, Zenoh endpoint)."""
    port, zenoh = free_tcp_port(), free_tcp_port()
    endpoint = f"tcp/127.0.0.1:{zenoh}"
    argv = cli(
        "run",
        str(config),
        "--speed",
        str(speed),
        "--out",
        str(out),
        "--zenoh-listen",
        endpoint,
        *sitl_ports(3).cli_args(),
        "--console",
        f"127.0.0.1:{port}",
        *extra,
    )
    return start(argv), f"http://127.0.0.1:{port}/", endpoint


def wait_http(url: str, proc: subprocess.Popen[str], timeout_s: float = 120.0) -> dict[str, Any]:
    """Poll `url`api/snapshot until it answers (bounded; fails if the process ends first)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            err = proc.stderr.read() if proc.stderr is not None else ""
            raise AssertionError(f"process ended ({proc.returncode}): {err[-3000:]}")
        with (
            contextlib.suppress(OSError),
            urllib.request.urlopen(url + "api/snapshot", timeout=5) as r,
        ):
            data: dict[str, Any] = json.load(r)
            return data
        time.sleep(0.2)
    raise AssertionError(f"{url} did not answer within {timeout_s} s")


def post(url: str, path: str, body: Any, headers: dict[str, str] | None = None) -> tuple[int, Any]:
    """POST JSON; (status, decoded JSON answer)."""
    req = urllib.request.Request(
        url + path.lstrip("/"),
        data=json.dumps(body).encode(),
        headers={"Content-Type": "application/json", **(headers or {})},
        method="POST",
    )
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.load(r)
    except urllib.error.HTTPError as err:
        return err.code, json.load(err)


def rss_kib(pid: int) -> int:
    """Resident set size of a process (KiB), from /proc."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError(f"no VmRSS for {pid}")


def stop(proc: subprocess.Popen[str], timeout_s: float = 120.0) -> str:
    """SIGINT, wait; kill if it does not end. Its stdout."""
    import signal

    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out or ""


async def churn_websockets(url: str, rounds: int = 3, connections: int = 20) -> None:
    """Open `connections` WebSocket clients on the console at `url`, read each one's first
    message (a snapshot), close them all; `rounds` times, a wall second apart."""
    import asyncio

    import websockets

    ws_url = url.replace("http://", "ws://") + "ws"
    for _ in range(rounds):
        socks = [await websockets.connect(ws_url) for _ in range(connections)]
        for s in socks:
            first_msg = json.loads(await asyncio.wait_for(s.recv(), 30))
            assert first_msg[0]["topic"] == "snapshot"
        for s in socks:
            await s.close()
        await asyncio.sleep(1.0)
