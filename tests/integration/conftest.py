"""Fixtures for the simulated-vehicle integration tests (helpers in tests/support/sim_harness.py)."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Iterator
from typing import Any

import pytest

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import MavlinkSigningKey
from sim.autopilot.endpoint import Autopilot
from sim.autopilot.settings import AutopilotSettings
from tests.support.autopilot_client import Client, make_settings
from tests.support.signing_peer import Peer
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
def fly(
    sim_runner: Callable[..., SimRunner],
) -> Iterator[Callable[..., tuple[SimRunner, Autopilot, Client]]]:
    """Factory: one vehicle with `overrides`, a connected pymavlink client; closed at teardown."""
    clients: list[Client] = []

    def make(**overrides: Any) -> tuple[SimRunner, Autopilot, Client]:
        settings, port, _ = make_settings(**overrides)
        runner = sim_runner([settings])
        client = Client(port, settings.system_id)
        clients.append(client)
        client.connect()
        return runner, runner.autopilots[0], client

    yield make
    for client in clients:
        client.close()


@pytest.fixture
def peers() -> Iterator[Callable[..., Peer]]:
    """Factory `peers(dest, key)`: pymavlink peers of the signing tests, closed at teardown."""
    made: list[Peer] = []

    def make(dest: tuple[str, int], key: MavlinkSigningKey | None = None, **kw: Any) -> Peer:
        peer = Peer(dest, key, **kw)
        made.append(peer)
        return peer

    yield make
    for peer in made:
        peer.close()


@pytest.fixture
async def hub(free_tcp_port: int) -> AsyncIterator[ZenohBus]:
    """A Zenoh session listening on loopback (the bridges' and the world's bus, and the test's
    observer)."""
    bus = await ZenohBus.open_async(BusSettings.hub(tcp_loopback(free_tcp_port)))
    try:
        yield bus
    finally:
        bus.close()
