"""The simulated vehicle's impaired MAVLink (sim/impaired_io.py on sim/autopilot/link.py) over real
loopback UDP, against a pymavlink offboard client: what the channel lets through arrives, exactly
(copies included), what it loses never does, and what it delays is late."""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from typing import Any

import pytest

from isac_mission.config import ChannelImpairmentConfig
from sim.autopilot.endpoint import Autopilot
from sim.autopilot.link import VehicleLink
from sim.impaired_io import DelayLine, wall_per_sim
from sim.impairment import ImpairedChannel, channel_rng
from tests.support.autopilot_client import Client, mavlink2
from tests.support.sim_harness import SIM_SPEED, SimRunner, wait_until

pytestmark = pytest.mark.timeout(120)
Fly = Callable[..., tuple[SimRunner, Autopilot, Client]]


def _impair(runner: SimRunner, ap: Autopilot, direction: str, **fields: float) -> list[DelayLine]:
    """Impair `direction` of the vehicle's offboard link (on the simulation's loop)."""
    made: list[DelayLine] = []

    def make(link: VehicleLink, which: str) -> DelayLine | None:
        if link.name != "offboard" or which != direction:
            return None
        ch = ImpairedChannel(ChannelImpairmentConfig(**fields), channel_rng(3, 0, 0, 0, 0))
        deliver = link.receive if which == "uplink" else link.sendto
        made.append(DelayLine(ch, deliver, wall_per_sim(SIM_SPEED)))
        return made[-1]

    runner.call(lambda: ap.impair_links(make))
    return made


def test_downlink_delivers_exactly_the_copies_it_draws_and_loses_the_rest(fly: Fly) -> None:
    runner, ap, client = fly()
    (line,) = _impair(
        runner, ap, "downlink", loss=0.3, latency_ms=200, jitter_ms=100, duplicate=0.1
    )
    offered: list[tuple[bytes, int]] = []

    def observe(args: tuple[Any, ...], delays: list[float]) -> None:
        buf = args[0]
        if buf[0] == 0xFD and buf[7] == mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            offered.append((bytes(buf), len(delays)))

    runner.call(lambda: setattr(line, "observer", observe))
    wait_until(lambda: len(offered) >= 300, 60.0, "300 positions through the channel")
    runner.call(lambda: setattr(line, "observer", None))
    runner.call(lambda: ap.impair_links(lambda link, which: None))  # the rest bypasses it
    wait_until(lambda: runner.call(lambda: line.in_flight) == 0, 10.0, "the channel to drain")
    time.sleep(0.2)  # loopback delivery of the last copies (bounded by the drain above)
    received: dict[bytes, int] = {}
    order: list[tuple[bytes, int]] = []
    while True:
        try:
            msg = client.recv("LOCAL_POSITION_NED", timeout_s=0.0)
        except AssertionError:
            break
        buf = bytes(msg.get_msgbuf())
        received[buf] = received.get(buf, 0) + 1
        order.append((buf, int(msg.time_boot_ms)))
    sent = dict(offered)
    for buf, copies in sent.items():
        assert received.get(buf, 0) == copies  # lost: never; once; duplicated: twice
    lost = sum(1 for _, c in offered if c == 0)
    n = len(offered)
    assert abs(lost - 0.3 * n) <= 5 * math.sqrt(n * 0.3 * 0.7), (lost, n)
    assert any(c == 2 for _, c in offered)
    # 20 Hz positions through 200 +- 100 ms: some overtake the ones sent before them.
    mine = [t for buf, t in order if buf in sent]
    assert any(b < a for a, b in itertools.pairwise(mine))


def test_uplink_loss_silences_commands_and_latency_delays_their_answer(fly: Fly) -> None:
    runner, ap, client = fly()
    (deaf,) = _impair(runner, ap, "uplink", loss=1.0)
    with pytest.raises(AssertionError, match="no COMMAND_ACK"):
        client.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, timeout_s=2.0)
    assert not ap.armed and deaf.channel.counts.lost >= 1
    # Now 800 ms of simulation time up (200 ms of wall time at speed 4), nothing lost.
    (late,) = _impair(runner, ap, "uplink", latency_ms=800)
    t0 = time.monotonic()
    result = client.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, timeout_s=10.0)
    assert result == mavlink2.MAV_RESULT_ACCEPTED and ap.armed
    assert time.monotonic() - t0 >= 0.8 / SIM_SPEED
    assert late.channel.counts.lost == 0 and late.channel.counts.delivered >= 1
