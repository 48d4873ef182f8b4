"""An operator's weight change, mid-mission, is answered and flown: the multi-target mission
live (`run_embedded`: the simulated world, the MAVLink bridges and the ground loop over loopback
Zenoh and UDP, lockstep), once as it is and once with the fleet command `priority` 10 for the
turning target's track sent by an operator's session when slot K's tracks are out.

The two missions are the same up to the slot the reply names (lockstep: the same seed gives the
same reports and plans; the vehicles fly them within a fraction of a percent), and from it on the weighted track's bound, tr(PCRB_pos), is lower with
the change than without it: the fleet flew the weight (with two confirmed tracks, p = (1, 10)
weighs the turning target's bound 1.82 and the known one's 0.18: tracking/priorities.py). The
turning target is the one whose bound attention moves most (docs/performance.md, "The
multi-target tracker": 0.87 m^2 under `proposed`, 0.49 under `horizon`).
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import socket
from pathlib import Path

import numpy as np
import pytest

from isac_mission.bus import tcp_loopback
from isac_mission.cli.embedded import run_embedded
from isac_mission.config import Scenario, load_scenario
from isac_mission.errors import MessageError
from isac_mission.records.tracks import TracksSlot
from isac_mission.service.assembly import LiveOptions
from isac_mission.wire import ControlMsg, ControlReplyMsg, Keys, decode_any, encode
from tests.support.live_cli import ROOT
from tests.support.mission_watch import open_client
from tests.support.ports import free_port_block, sitl_ports

pytestmark = pytest.mark.timeout(600)

SLOTS = 30
"""The entering target comes in at 20 s: three tracks weigh in over the last slots."""
SEED = 1
SEND_AT_SLOT = 7
"""The command goes out once slot 7's tracks are out (the turning target is confirmed by then)."""
TURNING_TRACK = 2
"""The turning target's track: the first one the tracker starts (the known target's is 1)."""
TURNING_TARGET = 2
"""The turning target's index in config/multi-target.yaml."""
WEIGHT = 10.0
WAIT_S = 120.0


def _scenario() -> Scenario:
    return load_scenario(ROOT / "config" / "multi-target.yaml").with_changes(N=SLOTS)


def _options(s: Scenario, out: Path) -> LiveOptions:
    return LiveOptions(
        speed=25.0,
        lockstep=True,
        seed=SEED,
        out_dir=out,
        zenoh_endpoint=tcp_loopback(free_port_block(1, socket.SOCK_STREAM)),
        **sitl_ports(s.M).world_kwargs(),
    )


def _turning_bound(slots: list[TracksSlot], first: int) -> dict[int, float]:
    """slot -> the turning target's track's tr(PCRB_pos) after that slot (m^2), from slot
    `first` on; the track is the turning target's (within 20 m of it)."""
    out = {}
    for o in slots[first - 1 :]:
        track = next(t for t in o.tracks if t.track_id == TURNING_TRACK)
        assert track.confirmed
        off_m = np.hypot(*(track.belief.x[:2] - o.truth[TURNING_TARGET, :2]))
        assert off_m < 20.0, (o.slot, off_m)
        out[o.slot] = track.bound.position_trace
    return out


async def _fly_without(s: Scenario, out: Path) -> list[TracksSlot]:
    result = await asyncio.wait_for(run_embedded(s, _options(s, out), asyncio.Event()), 400)
    return result.multi_target_slots


async def _fly_with_priority(s: Scenario, out: Path) -> tuple[list[TracksSlot], ControlReplyMsg]:
    """The mission with the command sent when slot SEND_AT_SLOT's tracks are out; its slots and
    the command's reply."""
    opts = _options(s, out)
    loop = asyncio.get_running_loop()
    due, replied = asyncio.Event(), asyncio.Event()
    replies: list[ControlReplyMsg] = []

    def on_tracks(o: TracksSlot, _latency: float) -> None:
        if o.slot == SEND_AT_SLOT:
            loop.call_soon_threadsafe(due.set)

    async def operate() -> None:
        keys = Keys(s.mission_id)
        with await open_client(opts.zenoh_endpoint, WAIT_S) as operator:

            async def pump() -> None:
                async for _key, payload in operator.messages(keys.everything):
                    with contextlib.suppress(MessageError):
                        msg = decode_any(payload)
                        if isinstance(msg, ControlReplyMsg):
                            replies.append(msg)
                            replied.set()

            listening = asyncio.create_task(pump())
            try:
                await asyncio.wait_for(due.wait(), WAIT_S)
                request = ControlMsg.priority(0, 0.0, "weight", track=TURNING_TRACK, weight=WEIGHT)
                operator.publish(keys.control, encode(request))
                await asyncio.wait_for(replied.wait(), WAIT_S)
            finally:
                listening.cancel()

    operator_task = asyncio.create_task(operate())
    result = await asyncio.wait_for(
        run_embedded(s, opts, asyncio.Event(), on_tracks=on_tracks), 400
    )
    await asyncio.wait_for(operator_task, WAIT_S)
    assert replies, "no reply to the priority command"
    return result.multi_target_slots, replies[0]


async def test_a_weight_set_mid_mission_is_flown(tmp_path: Path) -> None:
    s = _scenario()
    without = await _fly_without(s, tmp_path / "without")
    with_change, reply = await _fly_with_priority(s, tmp_path / "with")
    assert [o.slot for o in without] == list(range(1, SLOTS + 1))
    assert [o.slot for o in with_change] == list(range(1, SLOTS + 1))

    assert reply.accepted and reply.command == "priority", reply
    m = re.match(rf"track {TURNING_TRACK}: priority 10 from slot (\d+) on", reply.effect)
    assert m is not None, reply.effect
    first = int(m.group(1))
    assert SEND_AT_SLOT < first <= SLOTS - 10, first

    before = _turning_bound(without, SEND_AT_SLOT)
    after = _turning_bound(with_change, SEND_AT_SLOT)
    # The same mission up to the slot the reply names (lockstep, the same seed: the same plans;
    # the vehicles fly them a fraction of a percent apart, as live flights do) ...
    early = range(SEND_AT_SLOT, first)
    np.testing.assert_allclose([after[n] for n in early], [before[n] for n in early], rtol=0.02)
    # ... and from it on the weighted track is bounded tighter than without the change.
    late = range(first + 1, SLOTS + 1)  # the first slot's update comes from the plan it made
    mean_without = float(np.mean([before[n] for n in late]))
    mean_with = float(np.mean([after[n] for n in late]))
    print(
        f"turning target's tr(PCRB_pos), slots {first + 1}..{SLOTS}: {mean_without:.4f} m^2 "
        f"without, {mean_with:.4f} m^2 with priority {WEIGHT:g}"
    )
    assert mean_with < 0.95 * mean_without, (mean_with, mean_without)
    # The slots record the priority their plan was made with: 1 before, 10 from `first` on.
    recorded = {
        o.slot: 1.0 if o.priorities is None else o.priorities[TURNING_TRACK] for o in with_change
    }
    assert {n: recorded[n] for n in range(1, first)} == {n: 1.0 for n in range(1, first)}
    assert {n: recorded[n] for n in range(first, SLOTS + 1)} == {
        n: WEIGHT for n in range(first, SLOTS + 1)
    }
