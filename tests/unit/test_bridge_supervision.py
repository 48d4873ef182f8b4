"""The bridge's link supervision (LinkWatch), pure: losses, regains, interruptions, re-entries."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from isac_mission.mavwire.builders import Target
from isac_mission.mavwire.status import VehicleStatus
from isac_mission.service.bridge.counters import BridgeCounters
from isac_mission.service.bridge.setpoints import SetpointStream
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.supervision import LinkWatch
from isac_mission.timebase import FuncTime


def status(
    lost: bool = False, mode: str = "offboard", position_s: float | None = 0.0
) -> VehicleStatus:
    return VehicleStatus(
        time_s=0.0,
        system_id=1,
        address=("127.0.0.1", 14540),
        heartbeat_s=0.0,
        lost=lost,
        mode=mode,
        custom_mode=0,
        armed=True,
        landed_state=0,
        position_ned_m=np.zeros(3),
        velocity_ned_mps=np.zeros(3),
        position_s=position_s,
        yaw_rad=0.0,
        home_amsl_m=488.0,
    )


def watch() -> tuple[LinkWatch, BridgeCounters]:
    counters = BridgeCounters()
    return LinkWatch(BridgeSettings(interruption_after_s=1.0), counters), counters


def test_a_loss_after_the_link_was_up_is_counted_and_the_regain_asks_for_offboard() -> None:
    w, c = watch()
    assert not w.observe(status(lost=True), 0.0, True, True)  # never up yet: not a loss
    assert not w.observe(status(), 0.1, True, True)  # first contact: nothing to re-enter
    assert not w.observe(status(lost=True, position_s=None), 5.0, True, True)
    assert c.link_losses == 1
    assert w.observe(status(mode="hold", position_s=None), 9.0, True, True)  # regained
    assert not w.observe(status(mode="hold", position_s=None), 9.1, True, True)  # once


def test_no_reentry_when_offboard_is_not_wanted_or_one_is_running() -> None:
    for want, idle in ((False, True), (True, False)):
        w, _ = watch()
        w.observe(status(), 0.0, want, idle)
        w.observe(status(lost=True, position_s=None), 5.0, want, idle)
        assert not w.observe(status(position_s=None), 9.0, want, idle)


def test_a_position_gap_then_a_hold_asks_for_offboard_once() -> None:
    w, c = watch()
    w.observe(status(position_s=10.0), 10.0, True, True)
    # 1.5 s without a position (> interruption_after_s), link never lost, still in offboard.
    assert not w.observe(status(position_s=11.5), 11.5, True, True)
    assert c.link_interruptions == 1
    # The vehicle reports the offboard-loss hold within the watch window: re-enter, once.
    assert w.observe(status(mode="hold", position_s=11.6), 11.6, True, True)
    assert not w.observe(status(mode="hold", position_s=11.7), 11.7, True, True)


def test_a_hold_after_the_watch_window_is_respected() -> None:
    w, _ = watch()
    w.observe(status(position_s=10.0), 10.0, True, True)
    w.observe(status(position_s=11.5), 11.5, True, True)
    late = 11.5 + 3.0 * 1.0 + 2.0 + 0.1  # past 3 x interruption_after_s + 2 s
    for t in np.arange(11.6, late, 0.1):  # positions flow again, the vehicle in offboard
        assert not w.observe(status(position_s=float(t)), float(t), True, True)
    # A hold now is someone else's mode change: respected.
    assert not w.observe(status(mode="hold", position_s=late), late, True, True)


def test_an_interruption_and_a_regain_together_ask_for_one_reentry() -> None:
    w, c = watch()
    w.observe(status(position_s=10.0), 10.0, True, True)
    w.observe(replace(status(lost=True), position_s=10.0), 13.0, True, True)
    assert c.link_losses == 1
    assert w.observe(status(mode="hold", position_s=16.0), 16.0, True, True)
    assert c.link_interruptions == 1


def test_a_position_heard_before_the_clock_is_no_interruption() -> None:
    """A bridge on the world's clock stamps what it hears before the first clock message with
    0; its first look is at the world's time (3.7 s here, the world started first): the next
    position, 50 ms later, is no gap of 3.75 s. A real gap after that still is one."""
    w, c = watch()
    assert not w.observe(status(position_s=0.0), 3.7, True, True)
    assert not w.observe(status(position_s=3.75), 3.75, True, True)
    assert c.link_interruptions == 0
    assert not w.observe(status(position_s=5.0), 5.0, True, True)
    assert c.link_interruptions == 1


def settled(w: LinkWatch, until: float = 20.0) -> None:
    """Positions from 10 s until `until`, the vehicle in offboard: past the first contact's
    watch window."""
    for t in np.arange(10.0, until, 0.1):
        assert not w.observe(status(position_s=float(t)), float(t), True, True)


def test_a_gap_in_the_setpoint_stream_then_a_hold_asks_for_offboard_once() -> None:
    """The uplink: positions keep coming (no downlink gap), but the bridge's own setpoints
    stopped for longer than the offboard-loss timeout less a period (0.95 s here)."""
    w, c = watch()
    assert w.uplink_gap_limit_s == 1.0 - 1.0 / 20.0
    settled(w)
    # The stream is silent: no re-entry yet (the vehicle refuses OFFBOARD without setpoints),
    # but a hold now is no override (gap_recent).
    w.observe_uplink(0.0, 1.2, 20.0)
    assert not w.observe(status(mode="hold", position_s=20.0), 20.0, True, True)
    assert w.gap_recent(status(mode="hold", position_s=20.0), 20.0)
    assert c.link_interruptions == 0
    # It runs again: the gap (1.3 s) asks for one re-entry, counted then.
    w.observe_uplink(1.3, 0.0, 20.1)
    assert w.observe(status(mode="hold", position_s=20.1), 20.1, True, True)
    assert not w.observe(status(mode="hold", position_s=20.2), 20.2, True, True)
    assert c.link_interruptions == 1


def test_a_short_setpoint_gap_or_one_without_a_hold_costs_nothing() -> None:
    w, c = watch()
    settled(w)
    w.observe_uplink(0.9, 0.0, 20.1)  # shorter than the limit: the vehicle kept OFFBOARD
    assert not w.gap_recent(status(mode="hold", position_s=20.1), 20.1)
    assert not w.observe(status(mode="hold", position_s=20.1), 20.1, True, True)
    w.observe_uplink(1.5, 0.0, 20.2)  # long enough, but the vehicle stays in OFFBOARD
    late = 20.2 + 3.0 * 1.0 + 2.0 + 0.1
    for t in np.arange(20.2, late, 0.1):
        assert not w.observe(status(position_s=float(t)), float(t), True, True)
    assert c.link_interruptions == 0
    # A hold after the watch window is someone else's.
    assert not w.gap_recent(status(mode="hold", position_s=late), late)
    assert not w.observe(status(mode="hold", position_s=late), late, True, True)


def test_gaps_of_both_streams_and_the_vehicles_word_count_one_interruption() -> None:
    w, c = watch()
    settled(w)
    w.offboard_loss_reported(21.0)  # the vehicle's STATUSTEXT
    w.observe_uplink(1.2, 0.0, 21.5)  # the bridge's own gap
    assert not w.observe(status(position_s=21.6), 21.6, True, True)  # and a position gap
    assert c.link_interruptions == 1  # the position gap, counted as it is seen
    assert w.observe(status(mode="hold", position_s=21.7), 21.7, True, True)
    assert c.link_interruptions == 1
    # The vehicle's word alone (a one-way gap the bridge did not see) opens the watch too.
    w2, c2 = watch()
    settled(w2)
    w2.offboard_loss_reported(20.05)
    assert w2.observe(status(mode="hold", position_s=20.1), 20.1, True, True)
    assert c2.link_interruptions == 1


def test_the_setpoint_stream_measures_its_own_gaps() -> None:
    """In simulation seconds as the vehicle counts them; a stopped or restarted stream has no
    gap (the bridge stopped it on purpose: hold, land)."""
    now = [10.0]
    sent: list[Any] = []
    link: Any = SimpleNamespace(
        vehicle_address=("127.0.0.1", 14540),
        target=Target(1),
        send=lambda msg: sent.append(msg) is None,
    )
    stream = SetpointStream(BridgeSettings(), FuncTime(lambda: now[0]), link, BridgeCounters())
    stream.altitude_m = 10.0
    stream.hover(np.zeros(2))
    stream.start()
    assert stream.silent_s() == 0.0  # nothing sent yet
    for t in (10.0, 10.05, 10.1):
        now[0] = t
        stream.send()
    assert stream.take_gap_s() == pytest.approx(0.05)
    now[0] = 11.3
    assert stream.silent_s() == pytest.approx(1.2)
    stream.send()
    assert stream.silent_s() < 0.01  # (the wall time since, at speed 1)
    assert stream.take_gap_s() == pytest.approx(1.2)
    assert stream.take_gap_s() == 0.0  # taken
    stream.stop()
    now[0] = 20.0
    assert stream.silent_s() == 0.0
    stream.start()
    stream.send()
    assert stream.take_gap_s() == 0.0 and len(sent) == 5
