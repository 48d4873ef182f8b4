"""A multi-target mission with a vehicle's radio silent for 8 s: the multi-target ground loop
plans the other five around it (no share, no BS, D_s kept from where it holds) and takes it back
once its link is back (the single-target version: test_link_loss.py)."""

from __future__ import annotations

import asyncio
import json
import socket
from pathlib import Path

import numpy as np

from isac_mission.bus import tcp_loopback
from isac_mission.cli.embedded import run_embedded
from isac_mission.config import load_scenario
from isac_mission.service.assembly import LiveOptions
from tests.support.live_cli import ROOT
from tests.support.ports import free_port_block, sitl_ports

LOST = 2
OUTAGE_START_S, OUTAGE_S = 8.0, 8.0
SLOTS = 25


async def test_a_lost_vehicle_is_planned_around_and_readmitted_on_a_multi_target_mission(
    tmp_path: Path,
) -> None:
    s = load_scenario(ROOT / "config" / "multi-target.yaml").with_changes(N=SLOTS)
    opts = LiveOptions(
        speed=2.0,  # 8 simulation seconds are 4 wall seconds (loss detection also asks for wall)
        lockstep=True,
        seed=3,
        out_dir=tmp_path,
        zenoh_endpoint=tcp_loopback(free_port_block(1, socket.SOCK_STREAM)),
        **sitl_ports(s.M).world_kwargs(),
        link_outages=(f"{LOST}:{OUTAGE_START_S}:{OUTAGE_S}",),
    )
    result = await asyncio.wait_for(run_embedded(s, opts, asyncio.Event()), timeout=400)
    counters = result.report.counters
    assert counters["slots"] == SLOTS, counters
    assert counters["vehicle exclusions"] == 1, counters
    assert counters["vehicle readmissions"] == 1, counters
    assert not [k for k in counters if k.startswith(("internal", "rejected", "plans timed"))]

    lines = result.trace_path.read_text().splitlines()[1:]
    slots = [json.loads(line) for line in lines if not line.startswith('{"end"')]
    assert [d["slot"] for d in slots] == list(range(1, SLOTS + 1))
    without = [d for d in slots if d["assoc"][LOST] == -1]
    assert without, "no plan left the lost vehicle out"
    for d in without:
        assert d["status"] == "ok", d["status"]
        assert d["eta"][LOST] == 0.0
        # The others keep D_s from where it was (its waypoint: where it holds).
        xy = np.asarray(d["uav_xy"])
        others = np.delete(xy, LOST, axis=0)
        assert np.linalg.norm(others - xy[LOST], axis=1).min() >= s.d_safe - 1.0
    # Back in the plan at the end, with a share and a BS, and every target still followed.
    assert slots[-1]["assoc"][LOST] >= 0 and slots[-1]["eta"][LOST] > 0
    assert sum(t["confirmed"] for t in slots[-1]["tracks"]) >= 2
