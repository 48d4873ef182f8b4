"""The time port (isac_mission/timebase.py `SimTime`): what each time says of the world's slot
clock, so the bridges never ask a time for its type.

Free-running times (`WallTime`, `FuncTime`, any subclass of `SimTime`) follow no slot clock
(slots None), are always ready and have no clock to start; `ClockSimTime` follows the world's
`clock` messages: its slots and slot ends once the mission started, ready after the first
message, and a subscription that `start_clock` starts once.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from isac_mission.errors import IsacError
from isac_mission.service.bridge.clock_time import (
    ClockSimTime,
    close_bus_and_clock,
    open_bus_and_clock,
)
from isac_mission.service.bridge.fleet import BridgeFleet
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.timebase import FuncTime, SimTime, WallTime
from isac_mission.wire import ClockMsg, Keys

KEYS = Keys("t")


def clock_msg(t_s: float, t0: float | None = None, slot: int = -1) -> ClockMsg:
    return ClockMsg(slot=slot, t_s=t_s, slot_s=2.0, speed=10.0, mission_t0_s=t0)


class _Minimal(SimTime):
    """A time that implements only now_s and speed, inheriting the port's other members."""

    def now_s(self) -> float:
        return 7.0

    @property
    def speed(self) -> float:
        return 1.0


class _Subscription:
    """A subscription that yields nothing until closed."""

    def __init__(self) -> None:
        self.closed = False
        self._done = asyncio.Event()

    def close(self) -> None:
        self.closed = True
        self._done.set()

    def __aiter__(self) -> _Subscription:
        return self

    async def __anext__(self) -> tuple[str, bytes]:
        await self._done.wait()
        raise StopAsyncIteration


class _Bus:
    """Records the keys subscribed to (no Zenoh)."""

    def __init__(self) -> None:
        self.subscribed: list[str] = []
        self.subscriptions: list[_Subscription] = []
        self.closed = False

    def subscribe(self, key: str, maxsize: int = 0) -> _Subscription:
        self.subscribed.append(key)
        sub = _Subscription()
        self.subscriptions.append(sub)
        return sub

    def close(self) -> None:
        self.closed = True


FREE_RUNNING: list[SimTime] = [WallTime(), FuncTime(lambda: 5.0, 2.0), _Minimal()]


@pytest.mark.parametrize("time", FREE_RUNNING, ids=lambda t: type(t).__name__)
async def test_a_free_running_time_follows_no_slot_clock_and_is_always_ready(
    time: SimTime,
) -> None:
    assert not time.follows_slot_clock
    assert time.current_slot() is None
    assert time.slot_end_s(3) is None
    assert time.ready
    await asyncio.wait_for(time.wait_ready(0.0), timeout=1.0)  # returns at once
    bus: Any = _Bus()
    assert time.start_clock(bus, KEYS) is False
    assert bus.subscribed == []
    await time.stop_clock()  # nothing to stop


def test_clock_sim_time_reports_its_slot_and_slot_end_from_the_clock_messages() -> None:
    wall = [0.0]
    t = ClockSimTime(wall=lambda: wall[0])
    assert t.follows_slot_clock
    assert not t.ready
    assert t.current_slot() == -1
    assert t.slot_end_s(3) is None
    t.update(clock_msg(10.0))  # the world runs, the mission has not started
    assert t.ready
    assert t.current_slot() == -1
    assert t.slot_end_s(3) is None
    t.update(clock_msg(15.0, t0=11.0, slot=2))  # slot n ends at 11 + 2 n s
    assert t.current_slot() == 2
    assert t.slot_end_s(3) == 17.0
    assert t.slot_end_s(0) == 11.0


async def test_clock_sim_time_waits_for_its_first_message() -> None:
    t = ClockSimTime()
    with pytest.raises(IsacError, match="no clock message"):
        await t.wait_ready(0.01)
    t.update(clock_msg(1.0))
    await asyncio.wait_for(t.wait_ready(0.01), timeout=1.0)


async def test_clock_sim_time_starts_its_subscription_once_and_stops_it() -> None:
    t, bus = ClockSimTime(), _Bus()
    zbus: Any = bus  # a ZenohBus to the clock
    assert t.start_clock(zbus, KEYS) is True
    assert t.running
    assert bus.subscribed == [KEYS.clock]
    assert t.start_clock(zbus, KEYS) is False
    assert bus.subscribed == [KEYS.clock]
    await t.stop_clock()
    assert not t.running
    assert bus.subscriptions[0].closed
    await t.stop_clock()  # idempotent


async def test_open_and_close_start_and_stop_only_a_clock_that_needs_it() -> None:
    bus: Any = _Bus()
    clock = ClockSimTime()
    same, started = await open_bus_and_clock(bus, None, clock, KEYS)
    assert same is bus and started and clock.running
    _, again = await open_bus_and_clock(bus, None, clock, KEYS)
    assert not again  # already running: the first opener stops it
    await close_bus_and_clock(None, clock)
    assert not clock.running and not bus.closed
    _, started = await open_bus_and_clock(bus, None, WallTime(), KEYS)
    assert not started and bus.subscribed == [KEYS.clock]
    await close_bus_and_clock(bus, None)
    assert bus.closed


def test_a_fleet_deadline_is_the_slot_end_or_now_plus_a_slot() -> None:
    settings = [BridgeSettings(index=0)]
    free = BridgeFleet(settings, FuncTime(lambda: 100.0), KEYS, slot_s=2.0)
    assert free.deadline_s(5) == 102.0
    clock = ClockSimTime(wall=lambda: 0.0)
    fleet = BridgeFleet(settings, clock, KEYS, slot_s=2.0)
    clock.update(clock_msg(15.0))  # mission start unknown
    assert fleet.deadline_s(5) == pytest.approx(17.0)
    clock.update(clock_msg(15.0, t0=11.0, slot=2))
    assert fleet.deadline_s(5) == 21.0
