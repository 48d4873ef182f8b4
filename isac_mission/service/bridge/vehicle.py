"""`VehicleBridge`: one vehicle between its MAVLink link and Zenoh (see the package docstring).

The bridge owns a `MavlinkLink` (UDP 127.0.0.1:(base + m), PX4 SITL's offboard port, or the
`settings.link` URL: a serial device), a
`SetpointStream` (setpoints.py), a `LinkWatch` (supervision.py), a `VehicleCommander`
(commanding.py) and an `OffboardEntry` (offboard.py), and runs three paced loops (pacing.py):
GCS HEARTBEAT, telemetry (with link supervision) and the setpoint stream. It flies the mission
phases: `prepare` (the OFFBOARD entry), waypoints, `hold`, `land`, and the re-entry into
OFFBOARD after a link loss. It never takes a vehicle back from an operator or from the vehicle's
own failsafe (override.py, `override`), and carries out the operator's fleet commands
(`on_fleet`: hold, resume, land, release).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections import deque
from collections.abc import Sequence

import numpy as np

from isac_mission.bus import BusSettings, ZenohBus
from isac_mission.errors import LinkError
from isac_mission.mavwire.builders import (
    arm_command,
    gcs_heartbeat,
    hold_mode_command,
    land_command,
    request_position_command,
)
from isac_mission.mavwire.serial_link import open_link
from isac_mission.mavwire.status import VehicleStatus
from isac_mission.service.bridge.clock_time import close_bus_and_clock, open_bus_and_clock
from isac_mission.service.bridge.commanding import VehicleCommander
from isac_mission.service.bridge.counters import BridgeCounters
from isac_mission.service.bridge.legs import as_xy
from isac_mission.service.bridge.offboard import OffboardEntry
from isac_mission.service.bridge.operator import OverrideKeeper
from isac_mission.service.bridge.pacing import run_paced
from isac_mission.service.bridge.setpoints import SetpointStream
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.supervision import LinkWatch
from isac_mission.service.bridge.telemetry import telemetry_message, vehicle_xy
from isac_mission.timebase import SimTime
from isac_mission.types import FloatArray
from isac_mission.wire import Keys, TelemetryMsg, encode

log = logging.getLogger(__name__)


class VehicleBridge:
    """One vehicle's MAVLink bridge (see the package docstring).

    Args:
        settings: Ports, frames, rates, tolerances.
        time: Simulation time (a time that follows the world's clock messages is started on
            `bus` if it is not running: `SimTime.start_clock`).
        keys: The mission's Zenoh keys.
        bus: A Zenoh session owned by the caller; None = open one with `bus_settings`.
        bus_settings: For the bridge's own session (default `BusSettings()`).

    Use `async with VehicleBridge(...) as b:` or `await b.start()` ... `await b.stop()`.
    """

    def __init__(
        self,
        settings: BridgeSettings,
        time: SimTime,
        keys: Keys,
        bus: ZenohBus | None = None,
        *,
        bus_settings: BusSettings | None = None,
    ) -> None:
        self.settings = settings
        self.time = time
        self.keys = keys
        self._bus = bus
        self._own_bus = bus is None
        self._bus_settings = bus_settings
        self._started_clock = False
        self.link = open_link(
            settings.link_url,
            system_id=settings.vehicle_system_id,
            clock=time.now_s,
            lost_after_s=settings.link_lost_after_s,
            signing=settings.signing,
            name=f"vehicle {settings.index}",
        )
        self.counters = BridgeCounters()
        self.phase = "idle"
        """idle, preparing, ready (flying the mission in offboard), hold, landing, landed."""
        self._origin = np.array(settings.origin_xy_m, dtype=float)
        self._stream = SetpointStream(settings, time, self.link, self.counters)
        self._watch = LinkWatch(settings, self.counters)
        self._vehicle = VehicleCommander(settings, time, self.link, self.counters)
        self._offboard = OffboardEntry(settings, time, self._stream, self._vehicle)
        self._tasks: list[asyncio.Task[None]] = []
        self._reentry: asyncio.Task[None] | None = None
        self._waypoints_set = 0  # set_waypoint calls, to notice plans arriving during prepare
        self._keeper = OverrideKeeper(
            settings.index,
            time,
            self._stream,
            self._offboard,
            self._watch,
            self.counters,
            self._start_reentry,
        )
        self.link.on("STATUSTEXT", self._keeper.on_statustext)

    # -- lifecycle ---------------------------------------------------------------------------

    @property
    def bus(self) -> ZenohBus:
        """The Zenoh session (RuntimeError before start() when the bridge opens its own)."""
        if self._bus is None:
            raise RuntimeError("VehicleBridge: no bus before start()")
        return self._bus

    async def start(self) -> None:
        """Open the bus (if none was given), bind the MAVLink port, start the loops."""
        if self._tasks:
            return
        try:
            self._bus, started = await open_bus_and_clock(
                self._bus, self._bus_settings, self.time, self.keys
            )
            self._started_clock = self._started_clock or started
            await self.link.open()
        except BaseException:
            await self.stop()
            raise
        name = f"bridge-{self.settings.index}"
        s = self.settings
        loops = (
            (s.heartbeat_rate_hz, self._send_heartbeat),
            (s.telemetry_rate_hz, self._telemetry_tick),
            (s.setpoint_rate_hz, self._stream.send),
        )
        self._tasks = [
            asyncio.create_task(run_paced(rate, tick, self.time, self._loop_failed), name=name)
            for rate, tick in loops
        ]

    async def stop(self) -> None:
        """Stop the loops, close the MAVLink socket and the bridge's own bus (idempotent).
        Does not land: call `land()` first for that."""
        tasks = [*self._tasks, *([self._reentry] if self._reentry else [])]
        self._tasks, self._reentry = [], None
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self.link.close()
        await close_bus_and_clock(
            self._bus if self._own_bus else None, self.time if self._started_clock else None
        )
        self._started_clock = False
        if self._own_bus:
            self._bus = None

    async def __aenter__(self) -> VehicleBridge:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    # -- state -------------------------------------------------------------------------------

    @property
    def index(self) -> int:
        """Vehicle index m."""
        return self.settings.index

    @property
    def ready(self) -> bool:
        """True after prepare() succeeded, until hold() or land()."""
        return self.phase == "ready"

    @property
    def streaming(self) -> bool:
        """True while setpoints are being streamed."""
        return self._stream.streaming

    @property
    def altitude_m(self) -> float | None:
        """The mission altitude set by prepare(), m."""
        return self._stream.altitude_m

    @property
    def plan_slot(self) -> int:
        """The latest plan slot fed to this bridge (-1: none)."""
        return self._stream.plan_slot

    @plan_slot.setter
    def plan_slot(self, slot: int) -> None:
        self._stream.plan_slot = slot

    @property
    def setpoint_wall_s(self) -> deque[float]:
        """Wall times (time.monotonic) of the stream's latest periodic setpoints (at most
        TIMESTAMPS_KEPT), for jitter figures."""
        return self._stream.setpoint_wall_s

    @property
    def first_setpoint_wall_s(self) -> dict[int, float]:
        """Plan slot -> wall time of the first setpoint sent for it, for the latest
        TIMESTAMPS_KEPT plans (latency figures)."""
        return self._stream.first_setpoint_wall_s

    def vehicle_xy(self, status: VehicleStatus | None = None) -> FloatArray | None:
        """The vehicle's scenario-plane position [2], m (None before its first position)."""
        return vehicle_xy(self.link.status() if status is None else status, self._origin)

    def setpoint(self) -> tuple[FloatArray, FloatArray] | None:
        """The setpoint now (the carrot `setpoint_lead_s` ahead): scenario-plane position
        [2], m, and velocity [2], m/s."""
        return self._stream.setpoint()

    @property
    def slot(self) -> int:
        """The latest slot the bridge knows of (-1 before the mission)."""
        clock_slot = self.time.current_slot()  # None: a time without the world's slot clock
        from_clock = -1 if clock_slot is None else clock_slot
        return max(-1, from_clock, self.plan_slot - 1)

    @property
    def override(self) -> str:
        """Why the service does not fly the vehicle (operator.py, override.py); "" while it
        does."""
        return self._keeper.reason

    def telemetry(self, status: VehicleStatus | None = None) -> TelemetryMsg | None:
        """The vehicle's telemetry message (None before its first position). t_s is the
        simulation time at which the position arrived."""
        st = self.link.status() if status is None else status
        if st.position_ned_m is None or st.velocity_ned_mps is None:
            return None
        return telemetry_message(st, self._origin, self.index, self.slot, self.override)

    # -- mission -----------------------------------------------------------------------------

    async def prepare(self, start_xy_m: FloatArray | Sequence[float], altitude_m: float) -> None:
        """Arm, take off to `altitude_m`, enter OFFBOARD and fly to `start_xy_m` [2] (scenario
        plane, m); return when there, or as soon as a waypoint is set meanwhile (a plan:
        the mission has begun). See offboard.py. Raises LinkError naming the step that failed
        (command refused, timeout, link lost)."""
        start = as_xy(start_xy_m, "start_xy_m")
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"altitude_m must be finite and > 0, got {altitude_m}")
        self.phase = "preparing"
        self._offboard.want = False
        self._stream.altitude_m = float(altitude_m)
        waypoints_before = self._waypoints_set

        def plan_arrived() -> bool:
            return self._waypoints_set != waypoints_before

        try:
            await self._offboard.enter(start, altitude_m, plan_arrived)
        except BaseException:
            self.phase = "idle" if self.phase == "preparing" else self.phase
            raise
        self.phase = "ready"
        log.info("vehicle %d: ready at (%.1f, %.1f) m", self.index, *start)

    def set_waypoint(
        self,
        xy_m: FloatArray | Sequence[float],
        arrive_by_s: float | None,
        v_mps: FloatArray | Sequence[float] | None = None,
    ) -> None:
        """Fly the carrot to `xy_m` [2] (scenario plane, m) to arrive at simulation time
        `arrive_by_s` (None: at V_max) at velocity `v_mps` [2] (m/s; None: the leg's mean
        velocity), from where the carrot is now. Does not start the stream: before prepare()
        or after hold() the waypoint is only remembered. A waypoint set while prepare() runs
        ends its flight to the start point (the mission has begun)."""
        self._waypoints_set += 1
        v = None if v_mps is None else as_xy(v_mps, "v_mps")
        self._stream.set_goal(as_xy(xy_m), arrive_by_s, self.settings.v_max_mps, v)
        # The new leg goes out at once, not at the next tick of the stream (up to a period later).
        self._stream.send(periodic=False)

    async def hold(self) -> None:
        """Switch the vehicle to HOLD (PX4 AUTO.LOITER) and stop streaming setpoints (not a
        vehicle an operator or its failsafe took: `override`)."""
        if self._keeper.not_ours("hold"):
            return
        self._offboard.want = False
        await self._vehicle.command(hold_mode_command(self.link.target))
        self._stream.stop()
        self.phase = "hold"

    async def land(self) -> None:
        """Land where the vehicle is (PX4 LAND), wait for touchdown and the disarm (disarming
        if the vehicle has not after `disarm_wait_s`). Returns at once if landed and disarmed,
        or if the vehicle was never heard (nothing was commanded to it: there is nothing to
        land, and no link to land it with); LinkError when the link to a vehicle heard before
        is lost (the vehicle then follows its own loss action)."""
        s, vehicle = self.settings, self._vehicle
        if self._keeper.not_ours("land"):
            return
        self._offboard.want = False
        st = self.link.status()
        if st.heartbeat_s is None:
            log.info("vehicle %d: never heard on its link: nothing to land", self.index)
            return
        if st.lost:
            raise LinkError(f"vehicle {self.index}: cannot land: no link to the vehicle")
        if not st.airborne:
            self._stream.stop()
            if st.armed:
                await vehicle.command(arm_command(self.link.target, False))
            self.phase = "landed"
            return
        self.phase = "landing"
        await vehicle.command(land_command(self.link.target))
        self._stream.stop()
        height = st.altitude_m or 0.0
        await vehicle.wait(lambda st: st.landed, height / 0.5 + s.phase_timeout_s, "touchdown")
        try:
            await vehicle.wait(lambda st: not st.armed, s.disarm_wait_s, "the disarm after landing")
        except LinkError:
            await vehicle.command(arm_command(self.link.target, False))
            await vehicle.wait(lambda st: not st.armed, s.phase_timeout_s, "disarm")
        self.phase = "landed"
        log.info("vehicle %d: landed and disarmed", self.index)

    # -- internals: periodic loops and link supervision --------------------------------------

    def _loop_failed(self, err: Exception) -> None:
        """A periodic tick raised: count it, keep the loop alive, log the first few."""
        self.counters.loop_errors += 1
        self.counters.last_error = f"{type(err).__name__}: {err}"
        if self.counters.loop_errors <= 5 or self.counters.loop_errors % 100 == 0:
            log.exception("vehicle %d: periodic task failed", self.index)

    def _send_heartbeat(self) -> None:
        if self.link.send(gcs_heartbeat()):
            self.counters.heartbeats_sent += 1

    def _telemetry_tick(self) -> None:
        if not self.time.ready:
            # No simulation time to stamp with yet: telemetry stamped 0 would look minutes old
            # once the world's clock arrives, and the ground loop would plan around every vehicle.
            return
        st = self.link.status()
        if st.position_ned_m is None and not st.lost:  # heard, but no position (a held world)
            self.link.send(request_position_command(self.link.target))
        self._supervise(st)
        msg = self.telemetry(st)
        if msg is not None and self._bus is not None:
            stamped = msg.model_copy(update={"published_wall_s": time.time()})
            self._bus.publish(self.keys.telemetry(self.index), encode(stamped))
            self.counters.telemetry_published += 1

    def _supervise(self, st: VehicleStatus) -> None:
        """Follow link-state transitions and the gaps of both streams, positions and setpoints
        (supervision.py); after a loss or an interruption that left the vehicle in the
        offboard-loss HOLD or LAND, take it back to OFFBOARD; any other exit from OFFBOARD is an
        override (operator.py, override.py)."""
        now = self.time.now_s()
        if st.mode == "offboard":
            self._offboard.awaiting = False
        idle = self._reentry is None or self._reentry.done()
        self._watch.observe_uplink(self._stream.take_gap_s(), self._stream.silent_s(), now)
        if self._watch.observe(st, now, self._offboard.want, idle):
            if self._keeper.after_gap(st, now):
                self._start_reentry()
            return
        self._keeper.check(st, now, self.phase == "ready", idle)

    def _start_reentry(self) -> None:
        self._reentry = asyncio.create_task(
            self._offboard.reenter(), name=f"bridge-{self.index}-reentry"
        )

    async def on_fleet(self, command: str, request_id: str) -> None:
        """An operator's fleet command (`isac/<mission>/fleet`, request `request_id`): hold,
        resume, land or release this vehicle; a failure is logged and counted, not raised."""
        st = self.link.status()
        log.warning("vehicle %d: operator %s (request %s)", self.index, command, request_id)
        keeper = self._keeper
        try:
            if command == "hold" and self.phase == "ready" and not keeper.not_ours("hold"):
                keeper.take("control: hold")
                await self._vehicle.command(hold_mode_command(self.link.target))
            elif (command == "resume" and keeper.reason == "control: hold") or (
                command == "release" and keeper.reason and st.airborne
            ):
                keeper.hand_back(st, command=True)
            elif command == "land":
                keeper.reason = "control: land"
                self._stream.follow_vehicle = False
                await self.land()
        except LinkError as err:
            self.counters.last_error = str(err)
            log.warning("vehicle %d: operator %s failed: %s", self.index, command, err)
