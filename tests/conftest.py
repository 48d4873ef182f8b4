"""Shared fixtures: scenarios, seeded generators, free loopback ports, and the --full switch."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from tests.support import ports

ROOT = Path(__file__).resolve().parent.parent


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--full",
        action="store_true",
        default=False,
        help="Run long tests at full size (Monte Carlo runs, soak length).",
    )
    parser.addoption(
        "--soak-slots",
        type=int,
        default=None,
        help="Length of the live soak test in slots (default 240; 3600 with --full).",
    )


@pytest.fixture(scope="session")
def full_size(request: pytest.FixtureRequest) -> bool:
    """True when the suite runs with --full."""
    return bool(request.config.getoption("--full"))


@pytest.fixture(scope="session")
def soak_slots(request: pytest.FixtureRequest, full_size: bool) -> int:
    """Slots of the live soak test: --soak-slots N, else 3600 with --full, else 240."""
    given = request.config.getoption("--soak-slots")
    if given is not None:
        return int(given)
    return 3600 if full_size else 240


@pytest.fixture(scope="session")
def paper() -> Scenario:
    """config/paper.yaml: Table I with the calibrated sensing model."""
    return load_scenario(ROOT / "config" / "paper.yaml")


@pytest.fixture(scope="session")
def paper_literal() -> Scenario:
    """config/paper-literal.yaml: Table I exactly as printed."""
    return load_scenario(ROOT / "config" / "paper-literal.yaml")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture
def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that was free a moment ago (tests/support/ports.py)."""
    return ports.free_udp_port()


@pytest.fixture
def free_tcp_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (tests/support/ports.py)."""
    return ports.free_tcp_port()
