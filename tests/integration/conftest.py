"""Fixtures for the simulated-vehicle integration tests (helpers in tests/support/sim_harness.py)."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Iterator

import pytest

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from sim.autopilot.settings import AutopilotSettings
from tests.support.sim_harness import SIM_SPEED, SimRunner


@pytest.fixture
def sim_runner() -> Iterator[Callable[..., SimRunner]]:
    """Factory: `sim_runner(settings_list, speed=...)` starts a SimRunner, stopped at teardown."""
    runners: list[SimRunner] = []

    def make(settings: list[AutopilotSettings], speed: float = SIM_SPEED) -> SimRunner:
        runner = SimRunner(settings, speed).start()
        runners.append(runner)
        return runner

    yield make
    for runner in runners:
        runner.stop()


@pytest.fixture
async def hub(free_tcp_port: int) -> AsyncIterator[ZenohBus]:
    """A Zenoh session listening on loopback (the bridges' and the world's bus, and the test's
    observer)."""
    bus = await ZenohBus.open_async(BusSettings.hub(tcp_loopback(free_tcp_port)))
    try:
        yield bus
    finally:
        bus.close()
