"""A multi-target mission flown live (`run_embedded`: the simulated world, the MAVLink bridges
and the multi-target ground loop over loopback Zenoh and UDP): the world shows `simulate`'s
targets for the seed, every UAV's unlabelled report reaches the ground loop with the truth of
its origins, every target in the scene ends up followed by a confirmed track, and the trace is
the multi-target trace."""

from __future__ import annotations

import asyncio
import json
import socket
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from isac_mission.bus import tcp_loopback
from isac_mission.cli.embedded import run_embedded
from isac_mission.config import load_scenario
from isac_mission.experiment.replay import replay_trace
from isac_mission.experiment.track_metrics import follow
from isac_mission.records import read_trace
from isac_mission.records.header import TRACE_FORMAT
from isac_mission.records.tracks import TracksSlot
from isac_mission.service.assembly import LiveOptions, planning_scenario
from isac_mission.tracking.gospa import UNASSIGNED
from sim.multi_target_scene import MultiTargetScene
from tests.support.live_cli import ROOT
from tests.support.ports import free_port_block, sitl_ports

pytestmark = pytest.mark.timeout(420)

SLOTS = 30  # the entering target comes in at 20 s: every target is in the scene at the end
SEED = 1


async def test_a_live_multi_target_mission_tracks_every_target_in_the_scene(
    tmp_path: Path,
) -> None:
    s = load_scenario(ROOT / "config" / "multi-target.yaml").with_changes(N=SLOTS)
    opts = LiveOptions(
        speed=25.0,
        lockstep=True,
        seed=SEED,
        out_dir=tmp_path,
        zenoh_endpoint=tcp_loopback(free_port_block(1, socket.SOCK_STREAM)),
        **sitl_ports(s.M).world_kwargs(),
    )
    seen: list[TracksSlot] = []
    result = await asyncio.wait_for(
        run_embedded(s, opts, asyncio.Event(), on_tracks=lambda o, _lat: seen.append(o)),
        timeout=400,
    )
    counters = result.report.counters
    assert [o.slot for o in result.multi_target_slots] == list(range(1, SLOTS + 1)), counters
    assert [o.slot for o in seen] == list(range(1, SLOTS + 1))
    assert not [k for k in counters if k.startswith(("rejected", "internal"))], counters
    assert result.fleet_counters["plans applied"] >= SLOTS

    scene = MultiTargetScene(s, SEED)
    for o in result.multi_target_slots:
        # The world's targets are simulate's for the seed (the offline twin's truth) ...
        np.testing.assert_array_equal(o.truth, scene.truth(o.slot))
        # ... and every measurement that reached the ground came with its origin.
        for r in o.reports:
            assert len(r.origin) == len(r.measurements)
            assert np.all(r.origin >= -1)
        assert o.plan.report.status in ("ok", "infeasible"), o.plan.report.reason
    # Real reports: targets and false alarms, from UAVs that moved.
    origins = np.concatenate([r.origin for o in seen for r in o.reports])
    assert np.any(origins == -1) and np.any(origins >= 0)
    last = result.multi_target_slots[-1]
    assert not np.allclose(last.uav_xy_m, s.uav_start_xy)

    present = np.flatnonzero(np.all(np.isfinite(last.truth), axis=1))
    assert len(present) == len(s.targets)
    confirmed = [t for t in last.tracks if t.confirmed]
    followed = follow(last.truth[present, :2], confirmed)
    assert np.all(followed != UNASSIGNED), [t.belief.x[:2] for t in confirmed]
    for i, t in enumerate(present):
        # Each track is as close as it says it is (inside its own 99.9 % position gate; the
        # entering target's track is a few slots old, with metres of uncertainty).
        track = confirmed[followed[i]]
        e = track.belief.x[:2] - last.truth[t, :2]
        d2 = float(e @ np.linalg.solve(track.belief.P[:2, :2], e))
        assert d2 <= chi2.ppf(0.999, 2), f"target {t}: {np.hypot(*e):.1f} m off, d2 = {d2:.1f}"

    lines = result.trace_path.read_text().splitlines()
    assert json.loads(lines[0])["format"] == TRACE_FORMAT
    # The slots, then the line that says the run ended complete (docs/trace.md, "End").
    assert len(lines) == SLOTS + 2
    assert json.loads(lines[-1]) == {"end": {"status": "complete", "last_slot": SLOTS, "N": SLOTS}}
    ids = {t["id"] for t in json.loads(lines[-2])["tracks"]}
    assert ids == {t.track_id for t in last.tracks}

    # Planned as offline (lockstep): every slot's recorded inputs, the tracker restored from the
    # previous line, give the recorded plan again through the offline planner.
    rows = replay_trace(read_trace(result.trace_path), planning_scenario(s, LiveOptions()))
    assert len(rows) >= 0.8 * (SLOTS - 1), [r.slot for r in rows]
    assert max(float(r.replay_gap_m.max()) for r in rows) < 1e-3
    assert all(r.replay_fallback == r.fallback for r in rows)
