"""A live mission with or without a flooder process publishing garbage on the bus (issue 7).

`live_run` flies `run_embedded` on free loopback ports and, when asked, starts
`tests.support.wire_garbage` beside it; it returns the slots' wall times and the run's counters.
Used by tests/reliability/test_wire_flood.py (what is counted) and bench/wire_flood.py (the slot
periods, which are a timing figure and so a benchmark).
"""

from __future__ import annotations

import asyncio
import os
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from isac_mission.bus import tcp_loopback
from isac_mission.cli.embedded import run_embedded
from isac_mission.config import Scenario
from isac_mission.service.assembly import LiveOptions
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


async def live_run(
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
