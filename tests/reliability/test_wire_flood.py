"""A live mission under a garbage flood (issue 7, item 3).

`run_embedded` flies a short mission with and without a flooder process publishing garbage (a
few MB-sized payloads among it) on the detections, telemetry and clock keys; every slot must
complete, the garbage must be counted, and the wall-clock slot periods must stay in their normal
band.

Every socket is on 127.0.0.1; every Zenoh session has explicit loopback endpoints and no
multicast scouting (BusSettings).
"""

from __future__ import annotations

import asyncio
import os
import socket
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from isac_mission.bus import tcp_loopback
from isac_mission.cli.embedded import run_embedded
from isac_mission.cli.mission import LiveOptions
from isac_mission.config import Scenario
from isac_mission.service.ground.report import SlotEvent
from tests.support.ports import free_port_block, sitl_ports


@dataclass
class SlotTimes:
    """Wall times of the slots of one live run, and what the run counted."""

    wall_s: list[float] = field(default_factory=list)
    counters: dict[str, int] = field(default_factory=dict)

    @property
    def periods_s(self) -> list[float]:
        return list(np.diff(self.wall_s))


async def _live_run(
    s: Scenario, tmp: Path, speed: float, flood: tuple[float, float] | None
) -> SlotTimes:
    """run_embedded on free ports; flood = (messages per second, seconds between the MB-sized
    ones) starts the flooder process for the duration of the run."""
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    opts = LiveOptions(
        speed=speed,
        lockstep=False,
        out_dir=tmp,
        zenoh_endpoint=endpoint,
        **sitl_ports(s.M).world_kwargs(),
    )
    times = SlotTimes()

    def on_slot(_event: SlotEvent) -> None:
        times.wall_s.append(time.monotonic())

    flooder: subprocess.Popen[str] | None = None
    if flood is not None:
        flooder = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "tests.support.wire_garbage",
                endpoint,
                s.mission_id,
                str(s.M),
                *(str(x) for x in flood),
            ],
            cwd=Path(__file__).resolve().parents[2],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=os.environ | {"PYTHONUNBUFFERED": "1"},
        )
    try:
        result = await asyncio.wait_for(
            run_embedded(s, opts, asyncio.Event(), on_slot=on_slot), timeout=150
        )
    finally:
        if flooder is not None:
            flooder.terminate()
            out, err = flooder.communicate(timeout=30)
            assert flooder.returncode == 0, err[-2000:]
            assert "flooding" in out, (out, err[-2000:])
            times.counters["flood sent"] = int(out.strip().rsplit(" ", 1)[-1])
    times.counters |= dict(result.report.counters)
    assert len(result.report.records) == s.N, "not every slot completed"
    return times


async def test_the_slot_rate_holds_under_a_garbage_flood(paper: Scenario, tmp_path: Path) -> None:
    """A clean live run, then the same run while a flooder process publishes the bad-payload
    catalogue at 300 messages per wall second on the detections, telemetry and clock keys, a 2-3
    MB payload every 0.5 s among them. Every slot completes, the garbage is counted, and every slot
    period stays within 0.5x-2x the nominal dt / speed (its median within 20 %)."""
    s = paper.with_changes(N=16, H=20.0)  # a low altitude: a short climb before slot 0
    speed = 5.0
    nominal = s.dt / speed
    clean = await _live_run(s, tmp_path / "clean", speed, None)
    flooded = await _live_run(s, tmp_path / "flood", speed, (300.0, 0.5))
    rows = []
    for name, run in (("clean", clean), ("flood", flooded)):
        p = run.periods_s
        rows.append(
            f"{name}: median {statistics.median(p) * 1e3:.1f} ms, min {min(p) * 1e3:.1f} ms, "
            f"max {max(p) * 1e3:.1f} ms (nominal {nominal * 1e3:.0f} ms)"
        )
    rejected = sum(v for k, v in flooded.counters.items() if k.startswith("rejected "))
    print("slot periods, N = 16 at speed 5:", "; ".join(rows))
    print(f"flood: {flooded.counters['flood sent']} sent, {rejected} counted as rejected")
    for run in (clean, flooded):
        p = run.periods_s
        assert all(0.5 * nominal <= x <= 2.0 * nominal for x in p), p
        assert abs(statistics.median(p) - nominal) <= 0.2 * nominal
    assert sum(v for k, v in clean.counters.items() if k.startswith("rejected ")) == 0
    reasons = {k for k in flooded.counters if k.startswith("rejected ")}
    assert {"rejected payload too large", "rejected payload not JSON", "rejected schema"} <= reasons
    # The mission lasted > N x nominal wall seconds at 300 per second: thousands of messages.
    assert rejected >= 0.5 * 300.0 * (s.N - 1) * nominal
