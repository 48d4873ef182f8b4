"""The bridge's link supervision (LinkWatch), pure: losses, regains, interruptions, re-entries."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from isac_mission.mavwire.status import VehicleStatus
from isac_mission.service.bridge.counters import BridgeCounters
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.supervision import LinkWatch


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
