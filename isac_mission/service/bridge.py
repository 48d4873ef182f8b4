"""The MAVLink bridge: one `VehicleBridge` per vehicle between its MAVLink link and Zenoh.

Each bridge owns a `MavlinkLink` (UDP 127.0.0.1:(base + m), PX4 SITL's offboard port) and:

- publishes the vehicle's `TelemetryMsg` on `isac/<mission>/telemetry/<m>` at
  `telemetry_rate_hz` (default 10 Hz of simulation time), converted to the scenario plane;
- sends the GCS HEARTBEAT at `heartbeat_rate_hz` (1 Hz simulation time);
- flies the mission start (`prepare`): wait for the vehicle; stream setpoints (hover above the
  vehicle at the mission altitude); arm; PX4 takeoff command to the mission altitude (param7 =
  home AMSL + H, so it does not depend on the vehicle's MIS_TAKEOFF_ALT); once the takeoff is
  complete (altitude reached, mode no longer TAKEOFF) and the stream has run `offboard_stream_s`,
  switch to OFFBOARD; fly to the start point; return once within `arrive_tolerance_m` of it
  horizontally and `altitude_tolerance_m` of the altitude. PX4's takeoff was chosen over a climb
  in offboard: it is the sequence PX4 documents and MAVSDK's examples use, the vehicle's own
  climb limits apply, and offboard is entered only when airborne (no ground setpoints, which a
  PX4-like vehicle clamps to its minimum altitude);
- follows waypoints (`set_waypoint(xy, arrive_by_s)`, `BridgeFleet.on_plan`): a *carrot* (the
  setpoint) moves in a straight line from where it is toward the waypoint at the constant speed
  needed to arrive at `arrive_by_s`, never above V_max, with that velocity as feed-forward; it
  stops at the waypoint. The setpoint is streamed as SET_POSITION_TARGET_LOCAL_NED at
  `setpoint_rate_hz` (default 20 Hz of simulation time), sampled `setpoint_lead_s` (0.05 s)
  ahead of now to make up for the setpoint's hold time and the link latency. Legs chain (the
  next leg starts where the carrot is), so the velocity feed-forward is continuous across slots
  when the plan is. A waypoint set while `prepare` runs (the world started the mission as soon
  as every vehicle was in OFFBOARD at altitude) replaces the flight to the start point;
- `hold()` (PX4 HOLD) and `land()` (PX4 LAND, then waits for touchdown and the disarm, and
  disarms itself if the vehicle does not);
- link state: a vehicle whose HEARTBEAT stops for `link_lost_after_s` (simulation seconds) is
  reported with link "lost" in its telemetry. The setpoint stream keeps running meanwhile (the
  uplink may still work). When heartbeats return while the bridge is flying the mission and the
  vehicle is airborne but no longer in OFFBOARD (it took its loss action), the bridge moves the
  carrot to the vehicle, so the setpoint starts where the vehicle is, and re-enters OFFBOARD
  (the stream has kept running, as PX4 requires). A mode change by anyone else while the link is
  up is respected: the bridge reports it and does not take the vehicle back.

Frames: the scenario plane is x east, y north (m), the vehicle's MAV_FRAME_LOCAL_NED is centred
on its `origin_xy_m` in the scenario plane on the ground, so x = east + x0, y = north + y0,
altitude = -down. The simulated vehicles all use the scenario origin (0, 0), the default.

Time: everything runs on a `SimTime` (`now_s()` and `speed`). `ClockSimTime` follows the world's
Zenoh `clock` messages, extrapolated with wall time x speed; `WallTime` is the wall clock for
real vehicles; `FuncTime` adapts any clock function (e.g. an in-process SimClock). The periodic
loops sleep 1 / rate / speed wall seconds (at least 1 ms), paced against deadlines so sleep
overshoot does not lower the rate. Command ACK timeouts are wall seconds (a round trip on the
link, answered by the vehicle on receipt); every other timeout is in simulation seconds.

`BridgeFleet` runs M bridges on one Zenoh session: `start()`, `prepare_all()`, `on_plan(plan)`
(or `follow_plans()`, which subscribes to `isac/<mission>/plan`), `land_all()`, `stop()`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections import deque
from collections.abc import Awaitable, Callable, Coroutine, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np

from isac_mission.bus import BusSettings, Subscription, ZenohBus
from isac_mission.config import MavlinkSigningKey, Scenario
from isac_mission.errors import IsacError, LinkError, MessageError
from isac_mission.frames import (
    ned_to_scenario,
    ned_to_scenario_velocity,
    scenario_to_ned,
    scenario_to_ned_velocity,
)
from isac_mission.mavwire.builders import (
    arm_command,
    gcs_heartbeat,
    hold_mode_command,
    land_command,
    offboard_mode_command,
    position_target_local_ned,
    takeoff_command,
)
from isac_mission.mavwire.link import MavlinkLink
from isac_mission.mavwire.ports import OFFBOARD_BASE_PORT
from isac_mission.mavwire.status import VehicleStatus
from isac_mission.timebase import SimTime, SlotTimeline
from isac_mission.types import FloatArray
from isac_mission.wire import (
    TELEMETRY_MODES,
    ClockMsg,
    Keys,
    PlanMsg,
    TelemetryMsg,
    decode_clock,
    decode_plan,
    encode_telemetry,
)

log = logging.getLogger(__name__)

MIN_WALL_PERIOD_S: Final = 0.001
"""Shortest wall sleep of a periodic loop (a very fast or unpaced simulation)."""

TIMESTAMPS_KEPT: Final = 1024
"""How many setpoint wall times, and first-setpoint times of plans, a bridge keeps for the
timing figures: the latest ones, so that a long mission's memory does not grow with it
(docs/reliability.md, "Soak")."""

_MANUAL_MODES: Final = frozenset({"manual", "altctl", "posctl", "acro", "stabilized", "rattitude"})


# --------------------------------------------------------------------------- time sources


class ClockSimTime:
    """Simulation time from the world's `clock` messages, extrapolated in between.

    now_s() = t of the last clock message + (wall time since it arrived) x its speed, at most
    `max_extrapolation_s` beyond it (so time stops with the world's clock, e.g. while the world
    holds a slot boundary in lockstep), and never decreasing. A clock more than
    `restart_jump_s` behind is taken as a restarted world and followed.
    Before the first message now_s() is 0 and speed 1; `wait_ready()` waits for it.

    Feed it with `update(msg)`, or `start(bus, keys)` to subscribe to `isac/<mission>/clock`
    (invalid payloads are counted in `invalid`, logged and dropped).
    """

    def __init__(
        self,
        max_extrapolation_s: float = 0.2,
        restart_jump_s: float = 5.0,
        wall: Callable[[], float] = time.monotonic,
    ) -> None:
        if not max_extrapolation_s >= 0:
            raise ValueError(f"max_extrapolation_s must be >= 0, got {max_extrapolation_s}")
        self.max_extrapolation_s = float(max_extrapolation_s)
        self.restart_jump_s = float(restart_jump_s)
        self._wall = wall
        self._msg: ClockMsg | None = None
        self._msg_wall_s = 0.0
        self._last_now_s = 0.0
        self._ready = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._sub: Subscription | None = None
        self.received = 0
        self.invalid = 0

    def update(self, msg: ClockMsg, wall_s: float | None = None) -> None:
        """Take a clock message received at wall time `wall_s` (default: now)."""
        if self._msg is not None and msg.t_s < self._last_now_s - self.restart_jump_s:
            log.warning(
                "clock went back from %.2f s to %.2f s: world restarted", self._last_now_s, msg.t_s
            )
            self._last_now_s = msg.t_s
        self._msg = msg
        self._msg_wall_s = self._wall() if wall_s is None else wall_s
        self.received += 1
        self._ready.set()

    @property
    def ready(self) -> bool:
        """True once a clock message has arrived."""
        return self._msg is not None

    def now_s(self) -> float:
        """Current simulation time, s (see the class docstring)."""
        msg = self._msg
        if msg is None:
            return self._last_now_s
        ahead = min((self._wall() - self._msg_wall_s) * msg.speed, self.max_extrapolation_s)
        now = max(self._last_now_s, msg.t_s + max(ahead, 0.0))
        self._last_now_s = now
        return now

    @property
    def speed(self) -> float:
        """The world's speed (1 before the first message)."""
        return 1.0 if self._msg is None else self._msg.speed

    @property
    def slot_s(self) -> float | None:
        """Slot length, s (None before the first message)."""
        return None if self._msg is None else self._msg.slot_s

    @property
    def mission_t0_s(self) -> float | None:
        """Simulation time of slot 0 (None until the mission has started)."""
        return None if self._msg is None else self._msg.mission_t0_s

    def current_slot(self) -> int:
        """The slot n with t0 + n dt <= now (-1 before the mission)."""
        msg = self._msg
        if msg is None or msg.mission_t0_s is None:
            return -1
        n = SlotTimeline(msg.mission_t0_s, msg.slot_s).slot_of(self.now_s())
        return max(-1, n, msg.slot)

    def slot_end_s(self, slot: int) -> float | None:
        """t0 + slot * dt: when the vehicles must be at plan `slot`'s waypoints (None before
        the mission has started)."""
        msg = self._msg
        if msg is None or msg.mission_t0_s is None:
            return None
        return SlotTimeline(msg.mission_t0_s, msg.slot_s).slot_end_s(slot)

    async def wait_ready(self, timeout_s: float) -> None:
        """Wait for the first clock message, `timeout_s` wall seconds; IsacError after."""
        try:
            await asyncio.wait_for(self._ready.wait(), timeout_s)
        except TimeoutError:
            raise IsacError(f"no clock message within {timeout_s:g} s") from None

    @property
    def running(self) -> bool:
        """True while subscribed (after start, before stop)."""
        return self._task is not None

    def start(self, bus: ZenohBus, keys: Keys) -> None:
        """Subscribe to `keys.clock` on `bus` (call on the event loop)."""
        if self._task is not None:
            return
        self._sub = bus.subscribe(keys.clock, maxsize=64)
        self._task = asyncio.create_task(self._consume(self._sub), name="clock-sim-time")

    async def stop(self) -> None:
        """Undeclare the subscription (idempotent)."""
        if self._sub is not None:
            self._sub.close()
            self._sub = None
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def _consume(self, sub: Subscription) -> None:
        async for _key, payload in sub:
            try:
                msg = decode_clock(payload)
            except MessageError as err:
                self.invalid += 1
                if self.invalid <= 5 or self.invalid % 100 == 0:
                    log.warning("clock: invalid message #%d dropped: %s", self.invalid, err)
                continue
            self.update(msg)


# --------------------------------------------------------------------------- pure helpers


def _xy(value: FloatArray | Sequence[float], name: str = "xy_m") -> FloatArray:
    arr = np.array(value, dtype=float)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 2 finite numbers, got {value!r}")
    return arr


def telemetry_mode(px4_mode: str) -> str:
    """The telemetry mode name (wire.TELEMETRY_MODES) of a PX4 mode name."""
    if px4_mode in TELEMETRY_MODES:
        return px4_mode
    if px4_mode in _MANUAL_MODES:
        return "manual"
    return "other"


@dataclass(frozen=True)
class CarrotLeg:
    """A setpoint moving from `start_xy_m` [2] at time `start_s` toward `goal_xy_m` [2] at
    `speed_mps` in a straight line, then resting at the goal (scenario plane, m, s)."""

    start_xy_m: FloatArray
    goal_xy_m: FloatArray
    start_s: float
    speed_mps: float

    @property
    def distance_m(self) -> float:
        """Length of the leg, m."""
        return float(np.hypot(*(self.goal_xy_m - self.start_xy_m)))

    @property
    def end_s(self) -> float:
        """When the carrot reaches the goal, s."""
        d = self.distance_m
        return self.start_s if d <= 0.0 else self.start_s + d / self.speed_mps

    def sample(self, t_s: float) -> tuple[FloatArray, FloatArray]:
        """Carrot position [2], m, and velocity [2], m/s, at time `t_s`."""
        d = self.distance_m
        if d <= 0.0 or t_s >= self.end_s:
            return self.goal_xy_m.copy(), np.zeros(2)
        u = (self.goal_xy_m - self.start_xy_m) / d
        s = self.speed_mps * max(0.0, t_s - self.start_s)
        return self.start_xy_m + u * s, u * self.speed_mps


@dataclass(frozen=True)
class HermiteLeg:
    """A setpoint on the cubic from (start_xy_m, start_v_mps) at `start_s` to (goal_xy_m,
    goal_v_mps) at `end_s`, then resting at the goal (scenario plane, m, m/s, s).

    Position and velocity are continuous across legs, so a vehicle with finite acceleration can
    follow it; a constant-speed carrot jumps in velocity at every slot boundary, and a vehicle
    limited to a few m/s^2 then trails the plan by metres.
    """

    start_xy_m: FloatArray
    start_v_mps: FloatArray
    goal_xy_m: FloatArray
    goal_v_mps: FloatArray
    start_s: float
    end_s: float

    def sample(self, t_s: float) -> tuple[FloatArray, FloatArray]:
        """Setpoint position [2], m, and velocity [2], m/s, at time `t_s`."""
        T = self.end_s - self.start_s
        if T <= 0.0 or t_s >= self.end_s:
            return self.goal_xy_m.copy(), np.zeros(2)
        s = max(0.0, t_s - self.start_s) / T
        p0, p1 = self.start_xy_m, self.goal_xy_m
        m0, m1 = self.start_v_mps * T, self.goal_v_mps * T
        h00, h10, h01, h11 = (
            2 * s**3 - 3 * s**2 + 1,
            s**3 - 2 * s**2 + s,
            -2 * s**3 + 3 * s**2,
            s**3 - s**2,
        )
        d00, d10, d01, d11 = (
            6 * s**2 - 6 * s,
            3 * s**2 - 4 * s + 1,
            -6 * s**2 + 6 * s,
            3 * s**2 - 2 * s,
        )
        xy = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1
        v = (d00 * p0 + d10 * m0 + d01 * p1 + d11 * m1) / T
        return np.asarray(xy), np.asarray(v)


def hermite_leg(
    from_xy_m: FloatArray,
    from_v_mps: FloatArray,
    goal_xy_m: FloatArray,
    now_s: float,
    arrive_by_s: float,
    max_speed_mps: float,
) -> HermiteLeg:
    """The smooth leg to `goal_xy_m` by `arrive_by_s`, ending at the leg's mean velocity (the
    best guess of the next leg's), capped at `max_speed_mps`."""
    T = arrive_by_s - now_s
    mean_v = (np.asarray(goal_xy_m) - np.asarray(from_xy_m)) / T
    speed = float(np.hypot(*mean_v))
    if speed > max_speed_mps:
        mean_v = mean_v * (max_speed_mps / speed)
    return HermiteLeg(
        start_xy_m=np.asarray(from_xy_m, dtype=float),
        start_v_mps=np.asarray(from_v_mps, dtype=float),
        goal_xy_m=np.asarray(goal_xy_m, dtype=float),
        goal_v_mps=mean_v,
        start_s=float(now_s),
        end_s=float(arrive_by_s),
    )


def plan_leg(
    from_xy_m: FloatArray | Sequence[float],
    goal_xy_m: FloatArray | Sequence[float],
    now_s: float,
    arrive_by_s: float | None,
    max_speed_mps: float,
) -> CarrotLeg:
    """The carrot leg from `from_xy_m` to `goal_xy_m` starting at `now_s`: the constant speed
    that arrives at `arrive_by_s`, at most `max_speed_mps` (and exactly that when `arrive_by_s`
    is None or not in the future). Positions [2] in m, times in s."""
    if not (math.isfinite(max_speed_mps) and max_speed_mps > 0):
        raise ValueError(f"max_speed_mps must be finite and > 0, got {max_speed_mps}")
    a, b = _xy(from_xy_m, "from_xy_m"), _xy(goal_xy_m, "goal_xy_m")
    d = float(np.hypot(*(b - a)))
    speed = max_speed_mps
    if arrive_by_s is not None and arrive_by_s > now_s:
        speed = min(max_speed_mps, d / (arrive_by_s - now_s))
    if speed <= 0.0:  # d == 0
        speed = max_speed_mps
    return CarrotLeg(start_xy_m=a, goal_xy_m=b, start_s=float(now_s), speed_mps=float(speed))


# --------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class BridgeSettings:
    """One vehicle's bridge. Units: m, m/s, Hz; times in simulation seconds unless "wall".

    Attributes:
        index: 0-based vehicle index m (telemetry key `telemetry/<m>`).
        port: UDP port to bind on 127.0.0.1; None = base_port + index.
        base_port: PX4's offboard base port (14540).
        system_id: The vehicle's MAVLink system id; None = index + 1.
        origin_xy_m: Scenario-plane position of the vehicle's local NED origin (on the ground).
        v_max_mps: V_max: the carrot never moves faster.
        transit_speed_mps: Carrot speed flying to the start point; None = v_max_mps.
        setpoint_rate_hz: SET_POSITION_TARGET_LOCAL_NED rate (simulation Hz, >= 10).
        setpoint_lead_s: Each setpoint is the carrot this far ahead of now: a setpoint is
            held for one period (half a period late on average) and reaches the vehicle after
            the link's latency, so the vehicle would otherwise trail the plan by v x delay.
        velocity_feed_forward: Send the carrot's velocity (type_mask 0xDC0) or position only.
        smooth_legs: Fly planned legs (with an arrival time) on a cubic that keeps position and
            velocity continuous (HermiteLeg) instead of a constant-speed carrot.
        yaw_rad: Heading to hold (0 = north); None = yaw ignored (the vehicle keeps its own).
        telemetry_rate_hz: Telemetry publication rate (simulation Hz).
        heartbeat_rate_hz: GCS HEARTBEAT rate (simulation Hz).
        link_lost_after_s: No vehicle HEARTBEAT for this long = link lost.
        interruption_after_s: A gap this long in the vehicle's position stream is an
            interruption (PX4's COM_OF_LOSS_T: the vehicle may have left OFFBOARD).
        arrive_tolerance_m: Horizontal distance to the start point counted as arrived.
        altitude_tolerance_m: |altitude - H| counted as at altitude.
        offboard_stream_s: How long setpoints stream before the OFFBOARD switch.
        phase_timeout_s: Budget of each prepare/land phase on top of its expected duration.
        disarm_wait_s: After touchdown, how long the vehicle may take to disarm by itself.
        command_timeout_s: Wall seconds to wait for a COMMAND_ACK per attempt.
        command_attempts: Attempts per command.
        connect_timeout_s: Wall seconds to wait for the vehicle's first heartbeat and position.
        signing: MAVLink 2 signing key of the link (sign all, reject unsigned or badly signed;
            `link.errors` counts them); None = no signing.
    """

    index: int = 0
    port: int | None = None
    base_port: int = OFFBOARD_BASE_PORT
    system_id: int | None = None
    origin_xy_m: tuple[float, float] = (0.0, 0.0)
    v_max_mps: float = 25.0
    transit_speed_mps: float | None = None
    setpoint_rate_hz: float = 20.0
    setpoint_lead_s: float = 0.05
    velocity_feed_forward: bool = True
    smooth_legs: bool = True
    yaw_rad: float | None = None
    telemetry_rate_hz: float = 10.0
    heartbeat_rate_hz: float = 1.0
    link_lost_after_s: float = 3.0
    interruption_after_s: float = 1.0
    arrive_tolerance_m: float = 1.0
    altitude_tolerance_m: float = 1.0
    offboard_stream_s: float = 1.0
    phase_timeout_s: float = 60.0
    disarm_wait_s: float = 5.0
    command_timeout_s: float = 1.0
    command_attempts: int = 3
    connect_timeout_s: float = 30.0
    signing: MavlinkSigningKey | None = None

    def __post_init__(self) -> None:
        problems: list[str] = []
        if not 0 <= self.index <= 253:
            problems.append(f"index must be in [0, 253] (got {self.index})")
        if not 0 <= self.listen_port <= 65535:
            problems.append(f"port must be a UDP port (got {self.listen_port})")
        for name in (
            "v_max_mps",
            "setpoint_rate_hz",
            "telemetry_rate_hz",
            "heartbeat_rate_hz",
            "link_lost_after_s",
            "interruption_after_s",
            "arrive_tolerance_m",
            "altitude_tolerance_m",
            "phase_timeout_s",
            "command_timeout_s",
            "connect_timeout_s",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                problems.append(f"{name} must be finite and > 0 (got {value})")
        if self.transit_speed_mps is not None and not (
            math.isfinite(self.transit_speed_mps) and self.transit_speed_mps > 0
        ):
            problems.append(f"transit_speed_mps must be > 0 or None (got {self.transit_speed_mps})")
        for name in ("offboard_stream_s", "disarm_wait_s", "setpoint_lead_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                problems.append(f"{name} must be finite and >= 0 (got {value})")
        if self.command_attempts < 1:
            problems.append(f"command_attempts must be >= 1 (got {self.command_attempts})")
        if problems:
            raise IsacError("\n".join(f"BridgeSettings: {p}" for p in problems))

    @property
    def listen_port(self) -> int:
        """The bound port: `port`, or base_port + index."""
        return self.base_port + self.index if self.port is None else self.port

    @property
    def vehicle_system_id(self) -> int:
        """The vehicle's system id: `system_id`, or index + 1."""
        return self.index + 1 if self.system_id is None else self.system_id


# --------------------------------------------------------------------------- one vehicle


@dataclass
class BridgeCounters:
    """What a bridge did, for health reports."""

    telemetry_published: int = 0
    setpoints_sent: int = 0
    heartbeats_sent: int = 0
    link_losses: int = 0
    link_interruptions: int = 0
    offboard_reentries: int = 0
    loop_errors: int = 0
    last_error: str = ""


@dataclass
class _Goal:
    xy_m: FloatArray
    arrive_by_s: float | None
    max_speed_mps: float


async def _open_bus_and_clock(
    bus: ZenohBus | None, bus_settings: BusSettings | None, time: SimTime, keys: Keys
) -> tuple[ZenohBus, bool]:
    """The given bus, or a new one; starts a ClockSimTime's subscription if it is not running.
    Returns (bus, whether this call started the clock)."""
    if bus is None:
        bus = await ZenohBus.open_async(bus_settings)
    if isinstance(time, ClockSimTime) and not time.running:
        time.start(bus, keys)
        return bus, True
    return bus, False


async def _close_bus_and_clock(own_bus: ZenohBus | None, started_clock: SimTime | None) -> None:
    """Undo `_open_bus_and_clock`: stop the clock it started, close the bus it opened."""
    if isinstance(started_clock, ClockSimTime):
        await started_clock.stop()
    if own_bus is not None:
        own_bus.close()


class VehicleBridge:
    """One vehicle's MAVLink bridge (see the module docstring).

    Args:
        settings: Ports, frames, rates, tolerances.
        time: Simulation time (ClockSimTime is started on `bus` if it is not running).
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
        self.link = MavlinkLink(
            settings.listen_port,
            system_id=settings.vehicle_system_id,
            clock=time.now_s,
            lost_after_s=settings.link_lost_after_s,
            signing=settings.signing,
            name=f"vehicle {settings.index}",
        )
        self.counters = BridgeCounters()
        self.phase = "idle"
        """idle, preparing, ready (flying the mission in offboard), hold, landing, landed."""
        self.plan_slot = -1
        self.setpoint_wall_s: deque[float] = deque(maxlen=TIMESTAMPS_KEPT)
        """Wall times (time.monotonic) of the stream's latest periodic setpoints (at most
        TIMESTAMPS_KEPT), for jitter figures."""
        self.first_setpoint_wall_s: dict[int, float] = {}
        """Plan slot -> wall time of the first setpoint sent for it, for the latest
        TIMESTAMPS_KEPT plans (latency figures)."""
        """The latest plan slot fed to this bridge (-1: none)."""
        self._origin = np.array(settings.origin_xy_m, dtype=float)
        self._altitude_m: float | None = None
        self._leg: CarrotLeg | HermiteLeg | None = None
        self._goal: _Goal | None = None
        self._streaming = False
        self._stream_since_s = 0.0
        self._want_offboard = False
        self._reported_lost = True
        self._ever_ok = False
        self._tasks: list[asyncio.Task[None]] = []
        self._reentry: asyncio.Task[None] | None = None
        self._last_position_s: float | None = None
        self._reentry_watch_until_s = -math.inf
        """After the vehicle's stream resumes from a gap, re-enter OFFBOARD until this time if
        the vehicle reports the offboard-loss hold (the gap may be shorter than link loss)."""
        self._waypoints_set = 0  # set_waypoint calls, to notice plans arriving during prepare

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
            self._bus, started = await _open_bus_and_clock(
                self._bus, self._bus_settings, self.time, self.keys
            )
            self._started_clock = self._started_clock or started
            await self.link.open()
        except BaseException:
            await self.stop()
            raise
        name = f"bridge-{self.settings.index}"
        s = self.settings
        self._tasks = [
            asyncio.create_task(self._paced(s.heartbeat_rate_hz, self._send_heartbeat), name=name),
            asyncio.create_task(self._paced(s.telemetry_rate_hz, self._telemetry_tick), name=name),
            asyncio.create_task(self._paced(s.setpoint_rate_hz, self._send_setpoint), name=name),
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
        await _close_bus_and_clock(
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
        return self._streaming

    @property
    def altitude_m(self) -> float | None:
        """The mission altitude set by prepare(), m."""
        return self._altitude_m

    def vehicle_xy(self, status: VehicleStatus | None = None) -> FloatArray | None:
        """The vehicle's scenario-plane position [2], m (None before its first position)."""
        st = self.link.status() if status is None else status
        if st.position_ned_m is None:
            return None
        return ned_to_scenario(st.position_ned_m, self._origin)[0]

    def setpoint(self) -> tuple[FloatArray, FloatArray] | None:
        """The setpoint now (the carrot `setpoint_lead_s` ahead): scenario-plane position
        [2], m, and velocity [2], m/s."""
        return None if self._leg is None else self._leg.sample(self._carrot_time_s())

    @property
    def slot(self) -> int:
        """The latest slot the bridge knows of (-1 before the mission)."""
        from_clock = self.time.current_slot() if isinstance(self.time, ClockSimTime) else -1
        return max(-1, from_clock, self.plan_slot - 1)

    def telemetry(self, status: VehicleStatus | None = None) -> TelemetryMsg | None:
        """The vehicle's telemetry message (None before its first position). t_s is the
        simulation time at which the position arrived."""
        st = self.link.status() if status is None else status
        if st.position_ned_m is None or st.velocity_ned_mps is None:
            return None
        xy, alt = ned_to_scenario(st.position_ned_m, self._origin)
        v = st.velocity_ned_mps
        return TelemetryMsg(
            slot=self.slot,
            t_s=max(0.0, st.position_s or 0.0),
            uav=self.index,
            position_xy_m=xy,
            altitude_m=alt,
            velocity_xy_mps=ned_to_scenario_velocity(v),
            mode=telemetry_mode(st.mode),
            armed=st.armed,
            landed=st.landed,
            link="lost" if st.lost else "ok",
        )

    # -- mission -----------------------------------------------------------------------------

    async def prepare(self, start_xy_m: FloatArray | Sequence[float], altitude_m: float) -> None:
        """Arm, take off to `altitude_m`, enter OFFBOARD and fly to `start_xy_m` [2] (scenario
        plane, m); return when there, or as soon as a waypoint is set meanwhile (a plan:
        the mission has begun). See the module docstring. Raises LinkError naming the step
        that failed (command refused, timeout, link lost)."""
        s = self.settings
        start = _xy(start_xy_m, "start_xy_m")
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"altitude_m must be finite and > 0, got {altitude_m}")
        self.phase = "preparing"
        self._want_offboard = False
        self._altitude_m = float(altitude_m)
        waypoints_before = self._waypoints_set

        def plan_arrived() -> bool:
            return self._waypoints_set != waypoints_before

        try:
            st = await self.link.wait_for(
                lambda st: not st.lost and st.position_ned_m is not None,
                s.connect_timeout_s,
                "the vehicle's heartbeat and position",
            )
            if isinstance(self.time, ClockSimTime):
                await self.time.wait_ready(s.connect_timeout_s)
            here = self.vehicle_xy(st)
            assert here is not None
            self._hover(here)
            self._start_stream()
            if not st.airborne:
                st = await self._wait(
                    lambda st: st.home_amsl_m is not None, s.phase_timeout_s, "home position"
                )
                assert st.home_amsl_m is not None
                await self._command(arm_command(self.link.target, True))
                await self._command(takeoff_command(self.link.target, st.home_amsl_m + altitude_m))
                climb_s = altitude_m / 1.0 + s.phase_timeout_s
                await self._wait(
                    lambda st: st.airborne and st.mode != "takeoff" and self._at_altitude(st),
                    climb_s,
                    f"takeoff to {altitude_m:g} m",
                )
            await self._wait(
                lambda st: self.time.now_s() - self._stream_since_s >= s.offboard_stream_s,
                s.phase_timeout_s,
                "the setpoint stream",
            )
            here = self.vehicle_xy()
            assert here is not None
            if not plan_arrived():
                self._hover(here)  # the setpoint starts where the vehicle is
            await self._command(offboard_mode_command(self.link.target))
            self._want_offboard = True
            await self._wait(lambda st: st.mode == "offboard", s.phase_timeout_s, "OFFBOARD")
            # A plan that arrived meanwhile (the mission started) wins over the start point.
            transit = s.transit_speed_mps or s.v_max_mps
            if not plan_arrived():
                self._set_goal(start, None, transit)
            distance_m = float(np.hypot(*(start - here)))
            await self._wait(
                lambda st: self._near(st, start) or plan_arrived(),
                distance_m / transit + s.phase_timeout_s,
                f"arrival at the start point ({start[0]:.1f}, {start[1]:.1f}) m",
            )
            if plan_arrived():
                log.info("vehicle %d: a plan arrived during prepare; following it", self.index)
        except BaseException:
            self.phase = "idle" if self.phase == "preparing" else self.phase
            raise
        self.phase = "ready"
        log.info("vehicle %d: ready at (%.1f, %.1f) m", self.index, *start)

    def set_waypoint(self, xy_m: FloatArray | Sequence[float], arrive_by_s: float | None) -> None:
        """Fly the carrot to `xy_m` [2] (scenario plane, m) to arrive at simulation time
        `arrive_by_s` (None: at V_max), from where the carrot is now. Does not start the
        stream: before prepare() or after hold() the waypoint is only remembered. A waypoint
        set while prepare() runs ends its flight to the start point (the mission has begun)."""
        self._waypoints_set += 1
        self._set_goal(_xy(xy_m), arrive_by_s, self.settings.v_max_mps)
        # The new leg goes out at once, not at the next tick of the stream (up to a period later).
        self._send_setpoint(periodic=False)

    async def hold(self) -> None:
        """Switch the vehicle to HOLD (PX4 AUTO.LOITER) and stop streaming setpoints."""
        self._want_offboard = False
        await self._command(hold_mode_command(self.link.target))
        self._stop_stream()
        self.phase = "hold"

    async def land(self) -> None:
        """Land where the vehicle is (PX4 LAND), wait for touchdown and the disarm (disarming
        if the vehicle has not after `disarm_wait_s`). Returns at once if landed and disarmed;
        LinkError when the link is lost (the vehicle then follows its own loss action)."""
        s = self.settings
        self._want_offboard = False
        st = self.link.status()
        if st.lost:
            raise LinkError(f"vehicle {self.index}: cannot land: no link to the vehicle")
        if not st.airborne:
            self._stop_stream()
            if st.armed:
                await self._command(arm_command(self.link.target, False))
            self.phase = "landed"
            return
        self.phase = "landing"
        await self._command(land_command(self.link.target))
        self._stop_stream()
        height = st.altitude_m or 0.0
        await self._wait(lambda st: st.landed, height / 0.5 + s.phase_timeout_s, "touchdown")
        try:
            await self._wait(lambda st: not st.armed, s.disarm_wait_s, "the disarm after landing")
        except LinkError:
            await self._command(arm_command(self.link.target, False))
            await self._wait(lambda st: not st.armed, s.phase_timeout_s, "disarm")
        self.phase = "landed"
        log.info("vehicle %d: landed and disarmed", self.index)

    # -- internals: setpoints ----------------------------------------------------------------

    def _hover(self, xy_m: FloatArray) -> None:
        """Carrot and goal at `xy_m`, at rest."""
        self._leg = plan_leg(xy_m, xy_m, self._carrot_time_s(), None, self.settings.v_max_mps)
        self._goal = _Goal(xy_m.copy(), None, self.settings.v_max_mps)

    def _carrot_time_s(self) -> float:
        """The time the carrot is sampled at: now + setpoint_lead_s (simulation s)."""
        return self.time.now_s() + self.settings.setpoint_lead_s

    def _set_goal(self, xy_m: FloatArray, arrive_by_s: float | None, max_speed_mps: float) -> None:
        now = self._carrot_time_s()
        here_v = np.zeros(2)
        here: FloatArray | None = None
        if self._leg is not None:
            here, here_v = self._leg.sample(now)
        else:
            here = self.vehicle_xy()
        if here is None:
            here = xy_m
        if self.settings.smooth_legs and arrive_by_s is not None and arrive_by_s - now > 0.05:
            self._leg = hermite_leg(here, here_v, xy_m, now, arrive_by_s, max_speed_mps)
        else:
            self._leg = plan_leg(here, xy_m, now, arrive_by_s, max_speed_mps)
        self._goal = _Goal(xy_m.copy(), arrive_by_s, max_speed_mps)

    def _reanchor(self, status: VehicleStatus) -> None:
        """Restart the carrot at the vehicle, toward the current goal."""
        here = self.vehicle_xy(status)
        goal = self._goal
        if here is None or goal is None:
            return
        self._leg = plan_leg(
            here, goal.xy_m, self._carrot_time_s(), goal.arrive_by_s, goal.max_speed_mps
        )

    def _start_stream(self) -> None:
        if not self._streaming:
            self._streaming = True
            self._stream_since_s = self.time.now_s()

    def _stop_stream(self) -> None:
        self._streaming = False

    def _send_setpoint(self, periodic: bool = True) -> None:
        """Send the current setpoint; `periodic` marks the stream's own ticks (whose wall times
        are kept for the jitter figures) as opposed to the immediate send of a new plan."""
        if not self._streaming or self._leg is None or self._altitude_m is None:
            return
        if self.link.vehicle_address is None:
            return
        now = self.time.now_s()
        xy, v = self._leg.sample(self._carrot_time_s())
        msg = position_target_local_ned(
            self.link.target,
            scenario_to_ned(xy, self._altitude_m, self._origin),
            scenario_to_ned_velocity(v) if self.settings.velocity_feed_forward else None,
            self.settings.yaw_rad,
            time_boot_ms=round(now * 1000.0),
        )
        if self.link.send(msg):
            self.counters.setpoints_sent += 1
            wall = time.monotonic()
            if periodic:
                self.setpoint_wall_s.append(wall)
            firsts = self.first_setpoint_wall_s
            if self.plan_slot >= 0 and self.plan_slot not in firsts:
                firsts[self.plan_slot] = wall
                if len(firsts) > TIMESTAMPS_KEPT:
                    del firsts[next(iter(firsts))]  # the oldest plan (insertion order)

    # -- internals: periodic loops -----------------------------------------------------------

    async def _paced(self, rate_hz: float, tick: Callable[[], None]) -> None:
        """Call `tick()` every 1 / rate_hz simulation seconds until cancelled."""
        loop = asyncio.get_running_loop()
        due = loop.time()
        while True:
            try:
                tick()
            except Exception as err:  # keep the loop alive; count and report
                self.counters.loop_errors += 1
                self.counters.last_error = f"{type(err).__name__}: {err}"
                if self.counters.loop_errors <= 5 or self.counters.loop_errors % 100 == 0:
                    log.exception("vehicle %d: periodic task failed", self.index)
            period = max(1.0 / rate_hz / max(self.time.speed, 1e-9), MIN_WALL_PERIOD_S)
            due += period
            now = loop.time()
            if due < now - period:  # fell behind: re-anchor instead of bursting
                due = now
            await asyncio.sleep(max(0.0, due - now))

    def _send_heartbeat(self) -> None:
        if self.link.send(gcs_heartbeat()):
            self.counters.heartbeats_sent += 1

    def _telemetry_tick(self) -> None:
        st = self.link.status()
        self._supervise(st)
        msg = self.telemetry(st)
        if msg is not None and self._bus is not None:
            self._bus.publish(self.keys.telemetry(self.index), encode_telemetry(msg))
            self.counters.telemetry_published += 1

    def _supervise(self, st: VehicleStatus) -> None:
        """Follow link-state transitions; after a loss, take the vehicle back to OFFBOARD.

        A radio gap shorter than link loss but longer than PX4's offboard-loss timeout also
        leaves the vehicle in hold: when its position stream resumes after such a gap, the
        bridge re-enters OFFBOARD once the vehicle reports the hold."""
        self._watch_interruptions(st)
        if st.lost == self._reported_lost:
            return
        self._reported_lost = st.lost
        if st.lost:
            if self._ever_ok:
                self.counters.link_losses += 1
                log.warning(
                    "vehicle %d: link lost (no heartbeat for %.1f s)",
                    self.index,
                    self.settings.link_lost_after_s,
                )
            return
        regained = self._ever_ok
        self._ever_ok = True
        if regained:
            log.info("vehicle %d: link regained (mode %s)", self.index, st.mode)
            if self._want_offboard and (self._reentry is None or self._reentry.done()):
                self._reentry = asyncio.create_task(
                    self._reenter_offboard(), name=f"bridge-{self.index}-reentry"
                )

    def _watch_interruptions(self, st: VehicleStatus) -> None:
        now = self.time.now_s()
        if st.position_s is not None:
            last, self._last_position_s = self._last_position_s, st.position_s
            if last is not None and st.position_s - last > self.settings.interruption_after_s:
                log.warning(
                    "vehicle %d: no position for %.1f s; link interrupted",
                    self.index,
                    st.position_s - last,
                )
                self.counters.link_interruptions += 1
                self._reentry_watch_until_s = now + 3.0 * self.settings.interruption_after_s + 2.0
        if (
            now <= self._reentry_watch_until_s
            and not st.lost
            and st.mode != "offboard"
            and self._want_offboard
            and (self._reentry is None or self._reentry.done())
        ):
            self._reentry_watch_until_s = -math.inf
            self._reentry = asyncio.create_task(
                self._reenter_offboard(), name=f"bridge-{self.index}-reentry"
            )

    async def _reenter_offboard(self) -> None:
        s = self.settings
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
            self._reanchor(st)
            self._start_stream()
            await self._wait(
                lambda st: self.time.now_s() - self._stream_since_s >= s.offboard_stream_s,
                s.phase_timeout_s,
                "the setpoint stream",
            )
            if not self._want_offboard:
                return
            await self._command(offboard_mode_command(self.link.target))
            self.counters.offboard_reentries += 1
            log.info("vehicle %d: back in OFFBOARD after the link loss", self.index)
        except LinkError as err:
            self.counters.last_error = str(err)
            log.warning("vehicle %d: could not re-enter OFFBOARD: %s", self.index, err)

    # -- internals: waiting ------------------------------------------------------------------

    def _at_altitude(self, st: VehicleStatus) -> bool:
        alt = st.altitude_m
        target = self._altitude_m
        return (
            alt is not None
            and target is not None
            and abs(alt - target) <= self.settings.altitude_tolerance_m
        )

    def _near(self, st: VehicleStatus, xy_m: FloatArray) -> bool:
        here = self.vehicle_xy(st)
        return (
            here is not None
            and float(np.hypot(*(here - xy_m))) <= self.settings.arrive_tolerance_m
            and self._at_altitude(st)
        )

    async def _command(self, msg: Any) -> None:
        s = self.settings
        try:
            await self.link.command(msg, timeout_s=s.command_timeout_s, attempts=s.command_attempts)
        except LinkError as err:
            self.counters.last_error = str(err)
            raise

    async def _wait(
        self, predicate: Callable[[VehicleStatus], bool], timeout_s: float, what: str
    ) -> VehicleStatus:
        """The first vehicle status satisfying `predicate`, checked after every message.

        LinkError naming `what` when `timeout_s` simulation seconds pass, when the link is
        lost, or (should simulation time stop) after 3 x timeout_s / speed + 10 wall seconds.
        """
        loop = asyncio.get_running_loop()
        deadline_s = self.time.now_s() + timeout_s
        wall_deadline = loop.time() + 3.0 * timeout_s / max(self.time.speed, 1e-9) + 10.0
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


# --------------------------------------------------------------------------- the fleet


@dataclass
class FleetCounters:
    """Plans the fleet took or dropped."""

    plans_applied: int = 0
    plans_stale: int = 0
    plans_invalid: int = 0
    last_error: str = ""


@dataclass
class _FleetPlanState:
    last_slot: int = -1
    counters: FleetCounters = field(default_factory=FleetCounters)


class BridgeFleet:
    """M `VehicleBridge`s on one Zenoh session and one time source.

    Args:
        settings: One BridgeSettings per vehicle, index m at position m.
        time: Simulation time shared by the bridges.
        keys: The mission's Zenoh keys.
        bus: A Zenoh session owned by the caller; None = open one with `bus_settings`.
        slot_s: Slot length, s: the deadline of a plan when the time source does not know
            the mission start (plan n then arrives by now + slot_s).
        start_xy_m: [M, 2] default start points of `prepare_all`.
        altitude_m: Default mission altitude of `prepare_all`, m.
    """

    def __init__(
        self,
        settings: Sequence[BridgeSettings],
        time: SimTime,
        keys: Keys,
        bus: ZenohBus | None = None,
        *,
        bus_settings: BusSettings | None = None,
        slot_s: float = 1.0,
        start_xy_m: FloatArray | None = None,
        altitude_m: float | None = None,
    ) -> None:
        if not settings:
            raise IsacError("BridgeFleet: no vehicles")
        for m, s in enumerate(settings):
            if s.index != m:
                raise IsacError(f"BridgeFleet: settings[{m}] has index {s.index}")
        self.time = time
        self.keys = keys
        self.slot_s = float(slot_s)
        self.start_xy_m = None if start_xy_m is None else np.array(start_xy_m, dtype=float)
        self.altitude_m = altitude_m
        self._bus = bus
        self._own_bus = bus is None
        self._bus_settings = bus_settings
        self._settings = list(settings)
        self.bridges: list[VehicleBridge] = []
        self._plans = _FleetPlanState()
        self._started_clock = False

    @classmethod
    def from_scenario(
        cls,
        scenario: Scenario,
        time: SimTime,
        bus: ZenohBus | None = None,
        *,
        base_port: int = OFFBOARD_BASE_PORT,
        origins_xy_m: Sequence[tuple[float, float]] | None = None,
        bus_settings: BusSettings | None = None,
        **overrides: Any,
    ) -> BridgeFleet:
        """M bridges for `scenario`: V_max, vehicle m on base_port + m with system id m + 1,
        local origins `origins_xy_m` (default: the scenario origin for all), start points and
        altitude H for `prepare_all`, the scenario's MAVLink signing key; `overrides` go to
        every BridgeSettings."""
        if origins_xy_m is not None and len(origins_xy_m) != scenario.M:
            raise IsacError(f"origins_xy_m: {len(origins_xy_m)} origins for M = {scenario.M}")
        settings = [
            BridgeSettings(
                index=m,
                base_port=base_port,
                origin_xy_m=origins_xy_m[m] if origins_xy_m is not None else (0.0, 0.0),
                v_max_mps=scenario.v_max,
                **{"signing": scenario.mavlink_signing_key, **overrides},
            )
            for m in range(scenario.M)
        ]
        return cls(
            settings,
            time,
            Keys(scenario.mission_id),
            bus,
            bus_settings=bus_settings,
            slot_s=scenario.dt,
            start_xy_m=scenario.uav_start_xy,
            altitude_m=scenario.H,
        )

    @property
    def counters(self) -> FleetCounters:
        """Plan counters."""
        return self._plans.counters

    @property
    def bus(self) -> ZenohBus:
        """The shared Zenoh session (RuntimeError before start() when the fleet opens it)."""
        if self._bus is None:
            raise RuntimeError("BridgeFleet: no bus before start()")
        return self._bus

    async def start(self) -> None:
        """Open the bus if needed, start the time source's subscription and every bridge."""
        if self.bridges:
            return
        try:
            self._bus, started = await _open_bus_and_clock(
                self._bus, self._bus_settings, self.time, self.keys
            )
            self._started_clock = self._started_clock or started
            for s in self._settings:
                bridge = VehicleBridge(s, self.time, self.keys, self._bus)
                self.bridges.append(bridge)
                await bridge.start()
        except BaseException:
            await self.stop()
            raise

    async def stop(self) -> None:
        """Stop every bridge, the clock subscription and the fleet's own bus (idempotent)."""
        bridges, self.bridges = self.bridges, []
        for bridge in bridges:
            await bridge.stop()
        await _close_bus_and_clock(
            self._bus if self._own_bus else None, self.time if self._started_clock else None
        )
        self._started_clock = False
        if self._own_bus:
            self._bus = None

    async def __aenter__(self) -> BridgeFleet:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    async def _all(self, make: Callable[[VehicleBridge], Awaitable[None]], what: str) -> None:
        """Run `make(bridge)` for every bridge concurrently; LinkError listing the failures."""

        async def one(b: VehicleBridge) -> None:
            await make(b)

        coros: list[Coroutine[Any, Any, None]] = [one(b) for b in self.bridges]
        results = await asyncio.gather(*coros, return_exceptions=True)
        failures = [
            f"vehicle {b.index}: {r}"
            for b, r in zip(self.bridges, results, strict=True)
            if isinstance(r, BaseException)
        ]
        for r in results:
            if isinstance(r, BaseException) and not isinstance(r, Exception):
                raise r  # cancellation and friends pass through
        if failures:
            raise LinkError(f"{what} failed: " + "; ".join(failures))

    async def prepare_all(
        self, start_xy_m: FloatArray | None = None, altitude_m: float | None = None
    ) -> None:
        """`prepare` every vehicle concurrently: start_xy_m [M, 2] (default: the fleet's start
        points) at `altitude_m` (default: the fleet's altitude). LinkError if any fails."""
        starts = self.start_xy_m if start_xy_m is None else np.asarray(start_xy_m, dtype=float)
        alt = self.altitude_m if altitude_m is None else altitude_m
        if starts is None or alt is None:
            raise IsacError("prepare_all: no start points or altitude given")
        if starts.shape != (len(self.bridges), 2):
            raise IsacError(f"prepare_all: start_xy_m has shape {starts.shape}")
        await self._all(lambda b: b.prepare(starts[b.index], alt), "prepare")

    async def land_all(self) -> None:
        """`land` every vehicle concurrently; LinkError if any fails."""
        await self._all(lambda b: b.land(), "land")

    async def hold_all(self) -> None:
        """`hold` every vehicle concurrently; LinkError if any fails."""
        await self._all(lambda b: b.hold(), "hold")

    def deadline_s(self, slot: int) -> float:
        """When plan `slot`'s waypoints must be reached: t0 + slot * dt from the clock, or
        now + slot_s when the mission start is unknown (simulation seconds)."""
        if isinstance(self.time, ClockSimTime):
            end = self.time.slot_end_s(slot)
            if end is not None:
                return end
        return self.time.now_s() + self.slot_s

    def on_plan(self, plan: PlanMsg, arrive_by_s: float | None = None) -> bool:
        """Send each vehicle toward its waypoint of `plan` (plan.plan.uav_xy_m [M, 2]) by
        `arrive_by_s` (default `deadline_s(plan.slot)`). Plans not newer than the last one are
        dropped (counted). True if applied."""
        st = self._plans
        waypoints = np.asarray(plan.plan.uav_xy_m, dtype=float)
        if waypoints.shape != (len(self.bridges), 2):
            st.counters.plans_invalid += 1
            st.counters.last_error = f"plan {plan.slot}: waypoints of shape {waypoints.shape}"
            log.warning("%s", st.counters.last_error)
            return False
        if plan.slot <= st.last_slot:
            st.counters.plans_stale += 1
            return False
        st.last_slot = plan.slot
        deadline = self.deadline_s(plan.slot) if arrive_by_s is None else arrive_by_s
        for bridge in self.bridges:
            bridge.plan_slot = plan.slot
            bridge.set_waypoint(waypoints[bridge.index], deadline)
        st.counters.plans_applied += 1
        return True

    async def follow_plans(self) -> None:
        """Apply every valid plan published on `isac/<mission>/plan` until cancelled (invalid
        payloads are counted, logged and dropped)."""
        n = len(self.bridges)
        async with self.bus.subscribe(self.keys.plan, maxsize=16) as sub:
            async for _key, payload in sub:
                try:
                    plan = decode_plan(payload, n_uavs=n)
                except MessageError as err:
                    self.counters.plans_invalid += 1
                    self.counters.last_error = str(err)
                    log.warning("plan dropped: %s", err)
                    continue
                self.on_plan(plan)
