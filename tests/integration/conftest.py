"""Fixtures for the simulated-vehicle integration tests (helpers in tests/support/sim_harness.py)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from sim.autopilot import AutopilotSettings
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
