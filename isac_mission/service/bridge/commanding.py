"""Commanding one vehicle and waiting on it: COMMAND_LONG with ACKs, status predicates, tolerances.

Command ACK timeouts are wall seconds (a round trip on the link, answered by the vehicle on
receipt); every other wait is in simulation seconds, with a wall-time bound should simulation
time stop (3 x timeout / speed + 10 s).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import numpy as np

from isac_mission.errors import LinkError
from isac_mission.mavwire.link import MavlinkLink
from isac_mission.mavwire.status import VehicleStatus
from isac_mission.service.bridge.counters import BridgeCounters
from isac_mission.service.bridge.pacing import MIN_SPEED
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.telemetry import vehicle_xy
from isac_mission.timebase import SimTime
from isac_mission.types import FloatArray


class VehicleCommander:
    """Sends commands to one vehicle and waits for its status to satisfy a predicate.

    Args:
        settings: The bridge's settings (index, origin, tolerances, command timeouts).
        time: Simulation time.
        link: The vehicle's MAVLink link.
        counters: The bridge's counters (last_error).
    """

    def __init__(
        self, settings: BridgeSettings, time: SimTime, link: MavlinkLink, counters: BridgeCounters
    ) -> None:
        self.settings = settings
        self.time = time
        self.link = link
        self.counters = counters
        self._origin = np.array(settings.origin_xy_m, dtype=float)

    @property
    def index(self) -> int:
        """Vehicle index m."""
        return self.settings.index

    def at_altitude(self, st: VehicleStatus, target_m: float | None) -> bool:
        """True when the vehicle is within `altitude_tolerance_m` of `target_m` (m)."""
        alt = st.altitude_m
        return (
            alt is not None
            and target_m is not None
            and abs(alt - target_m) <= self.settings.altitude_tolerance_m
        )

    def near(self, st: VehicleStatus, xy_m: FloatArray, target_m: float | None) -> bool:
        """True when the vehicle is within `arrive_tolerance_m` of `xy_m` [2] (scenario plane)
        horizontally and at altitude `target_m`."""
        here = vehicle_xy(st, self._origin)
        return (
            here is not None
            and float(np.hypot(*(here - xy_m))) <= self.settings.arrive_tolerance_m
            and self.at_altitude(st, target_m)
        )

    async def command(self, msg: Any) -> None:
        """Send a command until ACKed (`command_attempts` x `command_timeout_s` wall s);
        LinkError (noted in the counters) when refused or unanswered."""
        s = self.settings
        try:
            await self.link.command(msg, timeout_s=s.command_timeout_s, attempts=s.command_attempts)
        except LinkError as err:
            self.counters.last_error = str(err)
            raise

    async def wait(
        self, predicate: Callable[[VehicleStatus], bool], timeout_s: float, what: str
    ) -> VehicleStatus:
        """The first vehicle status satisfying `predicate`, checked after every message.

        LinkError naming `what` when `timeout_s` simulation seconds pass, when the link is
        lost, or (should simulation time stop) after 3 x timeout_s / speed + 10 wall seconds.
        """
        loop = asyncio.get_running_loop()
        deadline_s = self.time.now_s() + timeout_s
        wall_deadline = loop.time() + 3.0 * timeout_s / max(self.time.speed, MIN_SPEED) + 10.0
        while True:
            st = self.link.status()
            if predicate(st):
                return st
            if st.lost:
                raise LinkError(f"vehicle {self.index}: link lost while waiting for {what}")
            if self.time.now_s() > deadline_s or loop.time() > wall_deadline:
                raise LinkError(
                    f"vehicle {self.index}: timed out after {timeout_s:.1f} s waiting for {what}"
                )
            await self.link.wait_change(0.25)
