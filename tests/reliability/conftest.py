"""Fixtures of the reliability tests."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from isac_mission.config import Scenario
from isac_mission.service.ground.report import GroundReport
from tests.support.ground_rig import GroundRig, ground_rig_session


@pytest.fixture
async def ground_rig(
    paper: Scenario, free_tcp_port: int, tmp_path: Path
) -> AsyncIterator[tuple[GroundRig, asyncio.Task[GroundReport]]]:
    """A running GroundLoop (N_SLOTS slots, trace in tmp_path) and the world session."""
    async with ground_rig_session(paper, free_tcp_port, tmp_path) as rig:
        yield rig
