"""Entering OFFBOARD: the mission start of one vehicle, and the re-entry after a link loss.

The mission start (`OffboardEntry.enter`): wait for the vehicle; stream setpoints (hover above
the vehicle at the mission altitude); arm; PX4 takeoff command to the mission altitude (param7 =
home AMSL + H, so it does not depend on the vehicle's MIS_TAKEOFF_ALT); once the takeoff is
complete (altitude reached, mode no longer TAKEOFF) and the stream has run `offboard_stream_s`,
switch to OFFBOARD; fly to the start point; return once within `arrive_tolerance_m` of it
horizontally and `altitude_tolerance_m` of the altitude. PX4's takeoff was chosen over a climb
in offboard: it is the sequence PX4 documents and MAVSDK's examples use, the vehicle's own climb
limits apply, and offboard is entered only when airborne (no ground setpoints, which a PX4-like
vehicle clamps to its minimum altitude). A waypoint set meanwhile (the world started the mission
as soon as every vehicle was in OFFBOARD at altitude) replaces the flight to the start point.

The re-entry (`OffboardEntry.reenter`): the carrot moves to the vehicle, so the setpoint starts
where the vehicle is, and the bridge re-enters OFFBOARD once the stream has run again, as PX4
requires (docs/reliability.md).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from isac_mission.errors import LinkError
from isac_mission.mavwire.builders import arm_command, offboard_mode_command, takeoff_command
from isac_mission.service.bridge.commanding import VehicleCommander
from isac_mission.service.bridge.setpoints import SetpointStream
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.telemetry import vehicle_xy
from isac_mission.timebase import SimTime
from isac_mission.types import FloatArray

log = logging.getLogger(__name__)

TAKEOFF_ATTEMPTS = 3
"""Arm-and-takeoff attempts at the mission start (OffboardEntry._arm_and_take_off)."""


class OffboardEntry:
    """Takes one vehicle into OFFBOARD (and back into it after a link loss).

    Args:
        settings: The bridge's settings (timeouts, stream time, speeds).
        time: Simulation time.
        stream: The bridge's setpoint stream.
        vehicle: The bridge's commander of the vehicle.
    """

    def __init__(
        self,
        settings: BridgeSettings,
        time: SimTime,
        stream: SetpointStream,
        vehicle: VehicleCommander,
    ) -> None:
        self.settings = settings
        self.time = time
        self.stream = stream
        self.vehicle = vehicle
        self.link = vehicle.link
        self.counters = vehicle.counters
        self.want = False
        """True while the bridge flies the mission in OFFBOARD (a re-entry is wanted)."""
        self.awaiting = False
        """True from the bridge's OFFBOARD command until the vehicle reports OFFBOARD (a mode
        other than OFFBOARD meanwhile is no override: override.py)."""
        self._origin = np.array(settings.origin_xy_m, dtype=float)

    @property
    def index(self) -> int:
        """Vehicle index m."""
        return self.settings.index

    def _vehicle_xy(self) -> FloatArray | None:
        return vehicle_xy(self.link.status(), self._origin)

    async def _arm_and_take_off(self, target_amsl_m: float) -> None:
        """Arm, then take off to `target_amsl_m`. A vehicle left armed on the ground disarms
        itself after COM_DISARM_PRFLT (10 s), and then refuses the takeoff (DENIED): over a lossy
        radio the takeoff's acknowledgements can be lost for that long (CI saw it). Arm again
        and retry, TAKEOFF_ATTEMPTS times in all; LinkError after the last."""
        vehicle = self.vehicle
        for attempt in range(1, TAKEOFF_ATTEMPTS + 1):
            await vehicle.command(arm_command(self.link.target, True))
            try:
                await vehicle.command(takeoff_command(self.link.target, target_amsl_m))
                return
            except LinkError as err:
                if "DENIED" not in str(err) or attempt == TAKEOFF_ATTEMPTS:
                    raise
                log.warning("vehicle %d: %s; arming again (attempt %d)", self.index, err, attempt)

    async def enter(
        self, start: FloatArray, altitude_m: float, plan_arrived: Callable[[], bool]
    ) -> None:
        """Take off to `altitude_m` (the stream's altitude), enter OFFBOARD and fly to `start`
        [2] (scenario plane, m), or stop flying there once `plan_arrived()`. LinkError naming
        the step that failed."""
        s, stream, vehicle = self.settings, self.stream, self.vehicle
        st = await self.link.wait_for(
            lambda st: not st.lost and st.position_ned_m is not None,
            s.connect_timeout_s,
            "the vehicle's heartbeat and position",
        )
        await self.time.wait_ready(s.connect_timeout_s)  # the world's first clock message
        here = vehicle_xy(st, self._origin)
        assert here is not None
        stream.hover(here)
        stream.start()
        if not st.airborne:
            st = await vehicle.wait(
                lambda st: st.home_amsl_m is not None, s.phase_timeout_s, "home position"
            )
            assert st.home_amsl_m is not None
            await self._arm_and_take_off(st.home_amsl_m + altitude_m)
            climb_s = altitude_m / 1.0 + s.phase_timeout_s
            await vehicle.wait(
                lambda st: (
                    st.airborne
                    and st.mode != "takeoff"
                    and vehicle.at_altitude(st, stream.altitude_m)
                ),
                climb_s,
                f"takeoff to {altitude_m:g} m",
            )
        await vehicle.wait(
            lambda st: self.time.now_s() - stream.since_s >= s.offboard_stream_s,
            s.phase_timeout_s,
            "the setpoint stream",
        )
        here = self._vehicle_xy()
        assert here is not None
        if not plan_arrived():
            stream.hover(here)  # the setpoint starts where the vehicle is
        self.awaiting = True
        await vehicle.command(offboard_mode_command(self.link.target))
        self.want = True
        await vehicle.wait(lambda st: st.mode == "offboard", s.phase_timeout_s, "OFFBOARD")
        # A plan that arrived meanwhile (the mission started) wins over the start point.
        transit = s.transit_speed_mps or s.v_max_mps
        if not plan_arrived():
            stream.set_goal(start, None, transit)
        distance_m = float(np.hypot(*(start - here)))
        await vehicle.wait(
            lambda st: vehicle.near(st, start, stream.altitude_m) or plan_arrived(),
            distance_m / transit + s.phase_timeout_s,
            f"arrival at the start point ({start[0]:.1f}, {start[1]:.1f}) m",
        )
        if plan_arrived():
            log.info("vehicle %d: a plan arrived during prepare; following it", self.index)

    async def reenter(self) -> None:
        """Back into OFFBOARD after a link loss or interruption, if the vehicle is airborne and
        not in OFFBOARD already; a failure is counted and logged, not raised."""
        s, stream, vehicle = self.settings, self.stream, self.vehicle
        try:
            st = self.link.status()
            if st.mode == "offboard":
                return
            if not st.airborne:
                log.warning(
                    "vehicle %d: on the ground after the link loss; not re-entering OFFBOARD",
                    self.index,
                )
                return
            stream.reanchor(st)
            stream.start()
            await vehicle.wait(
                lambda st: self.time.now_s() - stream.since_s >= s.offboard_stream_s,
                s.phase_timeout_s,
                "the setpoint stream",
            )
            if not self.want:
                return
            self.awaiting = True
            await vehicle.command(offboard_mode_command(self.link.target))
            self.counters.offboard_reentries += 1
            log.info("vehicle %d: back in OFFBOARD", self.index)
        except LinkError as err:
            self.counters.last_error = str(err)
            log.warning("vehicle %d: could not re-enter OFFBOARD: %s", self.index, err)
