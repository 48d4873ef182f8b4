"""Shared fixtures and the suite's tiers.

Tiers (docs/testing.md, "Tiers"), set by folder so that no test can be left without one:
- fast (tests/unit, tests/numerics): pure functions, models, codecs, config, the layering rules,
  numerics at a size that runs in seconds. No subprocess, no socket, no browser: the guard below
  fails a fast test that opens one, so it moves to a live folder.
- live (tests/integration, tests/e2e, tests/reliability, tests/packaging): everything that starts
  processes, opens sockets, or drives a browser or a third-party client.
- slow: the full-size variants of the tests that take `full_size` (directly or through a
  fixture); each also runs at its CI size in its own tier. Collected only with --full.
`pytest -m fast`, `pytest -m live` (scripts/test.sh runs the two in that order).
"""

from __future__ import annotations

import os
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from tests.support import ports

# The planner's compiled-problem cache (isac_mission/nlp_cache.py): no background compiles in
# the suite (a compile takes a core for seconds to minutes), and no developer's cache read;
# inherited by every process a test starts. tests/integration/test_nlp_cache.py sets its own.
os.environ.setdefault("ISAC_MISSION_COMPILE", "off")
if "ISAC_MISSION_NLP_CACHE" not in os.environ:
    # Made (and removed at exit) by the process that set it; the workers it starts inherit it.
    _nlp_cache = tempfile.TemporaryDirectory(prefix="isac-mission-nlp-")
    os.environ["ISAC_MISSION_NLP_CACHE"] = _nlp_cache.name

ROOT = Path(__file__).resolve().parent.parent
TESTS = ROOT / "tests"

TIER_OF_FOLDER = {
    "unit": "fast",
    "numerics": "fast",
    "integration": "live",
    "e2e": "live",
    "reliability": "live",
    "packaging": "live",
}
"""The tier of every test folder under tests/ (a test in a folder not listed is a usage error)."""


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--full",
        action="store_true",
        default=False,
        help="Also run the slow tier: the full-size variants (Monte Carlo runs, soak length).",
    )
    parser.addoption(
        "--soak-slots",
        type=int,
        default=None,
        help="Length of the live soak test in slots (default: 240 at CI size, 3600 at full size).",
    )


def tier_of(path: Path) -> str:
    """The tier of a test file, by its folder under tests/ (TIER_OF_FOLDER)."""
    folder = path.resolve().relative_to(TESTS).parts[0]
    tier = TIER_OF_FOLDER.get(folder)
    if tier is None:
        raise pytest.UsageError(
            f"{path}: tests/{folder}/ has no tier; add it to TIER_OF_FOLDER in tests/conftest.py"
        )
    return tier


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark each test with its folder's tier; without --full, deselect the slow tier. A test
    marked full_size_only has no CI size: its CI-size variant is never collected."""
    full = bool(config.getoption("--full"))
    kept: list[pytest.Item] = []
    dropped: list[pytest.Item] = []
    for item in items:
        item.add_marker(tier_of(item.path))
        slow = item.get_closest_marker("slow") is not None
        params = getattr(item, "callspec", None)
        ci_size = params is not None and params.params.get("full_size") is False
        full_only = item.get_closest_marker("full_size_only") is not None and ci_size
        (dropped if full_only or (slow and not full) else kept).append(item)
    if dropped:
        config.hook.pytest_deselected(items=dropped)
        items[:] = kept


def pytest_sessionstart(session: pytest.Session) -> None:
    """matplotlib's font cache built before any test: on a fresh machine its first import runs
    fc-list, a process the fast tier's guard refuses to whichever test imports it first."""
    import matplotlib.font_manager  # noqa: F401


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """No planner thread of an in-process live mission may be solving when pytest's interpreter
    shuts down (it would abort it: isac_mission/service/ground/planner_thread.py)."""
    from isac_mission.service.ground.planner_thread import drain_planner_threads

    drain_planner_threads(timeout_s=120.0)


class TierViolationError(AssertionError):
    """A fast-tier test reached for a socket, a subprocess or a Zenoh session."""


def _refuse(what: str) -> Any:
    def refuse(*_args: Any, **_kwargs: Any) -> Any:
        raise TierViolationError(
            f"a fast-tier test {what}: move it to a live folder (tests/conftest.py, tiers)"
        )

    return refuse


@pytest.fixture(autouse=True)
def _fast_tier_opens_nothing(
    request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch
) -> Iterator[None]:
    """In the fast tier: no network socket, no process, no Zenoh session (TIER_OF_FOLDER).
    Unix sockets stay allowed (asyncio's event loop wakes itself through a socket pair)."""
    if request.node.get_closest_marker("fast") is None:
        yield
        return
    for name in ("bind", "connect", "connect_ex", "sendto"):
        original = getattr(socket.socket, name)

        def guarded(
            self: socket.socket, *args: Any, _original: Any = original, _name: str = name
        ) -> Any:
            if self.family in (socket.AF_INET, socket.AF_INET6):
                _refuse(f"opened a network socket ({_name})")()
            return _original(self, *args)

        monkeypatch.setattr(socket.socket, name, guarded)
    monkeypatch.setattr(subprocess.Popen, "_execute_child", _refuse("started a process"))
    monkeypatch.setattr(os, "fork", _refuse("forked a process"))
    try:
        import zenoh

        monkeypatch.setattr(zenoh, "open", _refuse("opened a Zenoh session"))
    except ImportError:
        pass
    yield


@pytest.fixture(
    scope="session",
    params=[pytest.param(False, id="ci"), pytest.param(True, marks=pytest.mark.slow, id="full")],
)
def full_size(request: pytest.FixtureRequest) -> bool:
    """Each test that takes it runs at its CI size (in its tier) and at full size (the slow
    tier, with --full only)."""
    return bool(request.param)


@pytest.fixture(scope="session")
def soak_slots(request: pytest.FixtureRequest, full_size: bool) -> int:
    """Slots of the live soak test: --soak-slots N, else 3600 at full size, else 240."""
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


@pytest.fixture
def horizon_plans_one_target(monkeypatch: pytest.MonkeyPatch) -> None:
    """The method registry as if `horizon` planned one target (`max_targets=1`), as a method a
    user registers for one target: no shipped method plans one target only, and the tests of
    how such a method is refused on a scenario of several targets use this one."""
    from dataclasses import replace

    from isac_mission.planning import registry

    patched = tuple(
        replace(r, max_targets=1) if r.name == "horizon" else r for r in registry.REGISTRY
    )
    monkeypatch.setattr(registry, "REGISTRY", patched)
