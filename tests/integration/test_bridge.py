"""The MAVLink bridge against simulated PX4-like vehicles over real loopback UDP and Zenoh.

Vehicles run on a SimClock at `SPEED` x real time in the sim harness's thread (`sim_runner`); a
tick callback publishes the `clock` on a Zenoh hub session as the world does, so the bridges'
`ClockSimTime` follows real clock messages. The fleet test runs the real `sim.world.World`
(vehicles, clock, sensing) in the test's event loop next to a `BridgeFleet`, and plays the
ground loop: it answers slot n's detections with plan n + 1 and checks where the vehicles were
measured. Tests wait for events (Zenoh messages, clock boundaries signalled from the sim
thread, state conditions) with generous wall-clock deadlines; nothing sleeps to synchronise.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import random
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from isac_mission.bus import BusSettings, ZenohBus
from isac_mission.config import Scenario
from isac_mission.mavwire.builders import Target, hold_mode_command, message_interval_command
from isac_mission.mavwire.signing import new_encoder, pack
from isac_mission.service.bridge import BridgeFleet, BridgeSettings, ClockSimTime, VehicleBridge
from isac_mission.types import SlotPlan, SolveReport
from isac_mission.wire import (
    ClockMsg,
    Keys,
    PlanMsg,
    TelemetryMsg,
    decode_detection,
    decode_telemetry,
    encode_clock,
    encode_plan,
)
from sim.autopilot import Autopilot, AutopilotSettings, FlightMode
from sim.world import World
from sim.world_options import WorldOptions
from tests.support.sim_harness import SimRunner, async_wait_until, free_udp_ports

pytestmark = pytest.mark.timeout(120)

SPEED = 10.0
"""Simulation seconds per wall second."""
ALTITUDE_M = 10.0
V_MAX_MPS = 12.0  # the simulated airframe's MPC_XY_VEL_MAX
CLOCK_PERIOD_S = 0.1  # the world publishes its clock at 10 Hz of simulation time
TIMEOUT_S = 30.0  # wall seconds for any single awaited event
ARRIVE_TOL_M = 1.5
MIN_RATE_HZ = 10.0
KEYS = Keys("bridge-test")


# --------------------------------------------------------------------------- helpers


class ClockPublisher:
    """SimClock tick callback (sim thread): the world's `clock` message every 0.1 s sim."""

    def __init__(self, bus: ZenohBus, slot_s: float) -> None:
        self.bus = bus
        self.slot_s = slot_s
        self.mission_t0_s: float | None = None
        self._next_s = 0.0

    def __call__(self, now_s: float, dt_s: float) -> None:
        if now_s + 1e-9 < self._next_s or self.bus.closed:
            return
        self._next_s = (math.floor(now_s / CLOCK_PERIOD_S + 1e-9) + 1) * CLOCK_PERIOD_S
        t0 = self.mission_t0_s
        slot = -1 if t0 is None or now_s < t0 else int((now_s - t0) / self.slot_s + 1e-9)
        msg = ClockMsg(slot=slot, t_s=now_s, slot_s=self.slot_s, speed=SPEED, mission_t0_s=t0)
        with contextlib.suppress(RuntimeError):  # the bus closed meanwhile
            self.bus.publish(KEYS.clock, encode_clock(msg))


@dataclass
class Snapshot:
    """What the vehicles and the bridges were at a simulation time (taken on the sim thread)."""

    time_s: float
    states: list[Any]
    setpoints_sent: list[int]


class BoundaryRecorder:
    """SimClock tick callback (sim thread): snapshots at chosen simulation times, each
    signalled to the test's event loop through an asyncio.Event."""

    def __init__(self, runner: SimRunner, bridges: list[VehicleBridge]) -> None:
        self.runner = runner
        self.bridges = bridges
        self.loop = asyncio.get_running_loop()
        self._lock = threading.Lock()
        self._watch: list[tuple[float, asyncio.Event]] = []
        self.snapshots: dict[float, Snapshot] = {}

    def watch(self, t_s: float) -> asyncio.Event:
        event = asyncio.Event()
        with self._lock:
            self._watch.append((t_s, event))
        return event

    def __call__(self, now_s: float, dt_s: float) -> None:
        with self._lock:
            due = [(t, e) for t, e in self._watch if t <= now_s + 1e-9]
            self._watch = [(t, e) for t, e in self._watch if t > now_s + 1e-9]
        for t_s, event in due:
            self.snapshots[t_s] = Snapshot(
                now_s,
                [ap.state for ap in self.runner.autopilots],
                [b.counters.setpoints_sent for b in self.bridges],
            )
            self.loop.call_soon_threadsafe(event.set)


@dataclass
class Rig:
    """Simulated vehicles with a Zenoh clock, and the ports their bridges must bind."""

    runner: SimRunner
    hub: ZenohBus
    clock: ClockPublisher
    bridge_ports: list[int]
    bridges: list[VehicleBridge] = field(default_factory=list)

    @property
    def vehicle(self) -> Autopilot:
        return self.runner.autopilots[0]

    def now_s(self) -> float:
        """True simulation time (the vehicles' clock)."""
        return self.runner.clock.now_s

    def bridge(self, m: int = 0, **overrides: Any) -> VehicleBridge:
        settings = BridgeSettings(
            index=m, port=self.bridge_ports[m], v_max_mps=V_MAX_MPS, **overrides
        )
        bridge = VehicleBridge(settings, ClockSimTime(), KEYS, self.hub)
        self.bridges.append(bridge)
        return bridge

    def recorder(self) -> BoundaryRecorder:
        rec = BoundaryRecorder(self.runner, self.bridges)
        self.runner.call(lambda: self.runner.clock.add_tick_callback(rec))
        return rec


@pytest.fixture
def rig(sim_runner: Callable[..., SimRunner], hub: ZenohBus) -> Callable[..., Rig]:
    """Factory: `rig(spawn_xy_m=[(x, y)], **autopilot_settings)` starts the vehicles."""

    def make(spawn_xy_m: list[tuple[float, float]], slot_s: float = 1.0, **overrides: Any) -> Rig:
        n = len(spawn_xy_m)
        ports = free_udp_ports(2 * n)
        settings = [
            AutopilotSettings(
                index=m,
                offboard_port=ports[m],
                gcs_port=ports[n + m],
                spawn_xy_m=spawn_xy_m[m],
                **overrides,
            )
            for m in range(n)
        ]
        runner = sim_runner(settings, speed=SPEED)
        clock = ClockPublisher(hub, slot_s)
        runner.call(lambda: runner.clock.add_tick_callback(clock))
        return Rig(runner, hub, clock, ports[:n])

    return make


async def next_telemetry(
    sub: Any, condition: Callable[[TelemetryMsg], bool] = lambda t: True
) -> TelemetryMsg:
    """The next telemetry message satisfying `condition` (TimeoutError after TIMEOUT_S)."""
    deadline = time.monotonic() + TIMEOUT_S
    while True:
        _, payload = await sub.get(max(0.01, deadline - time.monotonic()))
        msg = decode_telemetry(payload)
        if condition(msg):
            return msg


def distance_m(a: Any, b: Any) -> float:
    return float(np.hypot(*(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))))


# --------------------------------------------------------------------------- one vehicle


async def test_prepare_arms_takes_off_enters_offboard_and_reaches_the_start_point(
    rig: Callable[..., Rig],
) -> None:
    r = rig([(50.0, 80.0)])
    start = np.array([58.0, 74.0])  # 10 m from the spawn point
    async with r.bridge() as bridge:
        t0 = r.now_s()
        await asyncio.wait_for(bridge.prepare(start, ALTITUDE_M), TIMEOUT_S)
        st = r.vehicle.state
        assert st.armed
        assert not st.landed
        assert st.mode is FlightMode.OFFBOARD
        assert abs(st.altitude_m - ALTITUDE_M) <= bridge.settings.altitude_tolerance_m
        assert distance_m(st.position_xy_m, start) <= bridge.settings.arrive_tolerance_m
        assert bridge.ready
        assert bridge.streaming
        # Taking off took simulation time (no shortcut): at least the climb at <= 3 m/s.
        assert r.now_s() - t0 >= ALTITUDE_M / 3.0
        # No setpoint had to be clamped or dropped by the vehicle (e.g. below its minimum
        # altitude while still on the ground).
        assert not r.vehicle.rejected


async def test_telemetry_on_zenoh_matches_the_vehicle_in_the_scenario_frame(
    rig: Callable[..., Rig], hub: ZenohBus
) -> None:
    origin = (100.0, 50.0)  # the vehicle's local NED origin in the scenario plane
    spawn = (130.0, 90.0)  # local NED: north 40, east 30
    r = rig([spawn], local_origin_xy_m=origin)
    # The constant-speed carrot (not the smooth legs), so that the cruise velocity is known.
    bridge_cm = r.bridge(origin_xy_m=origin, smooth_legs=False)
    async with bridge_cm as bridge, hub.subscribe(KEYS.telemetry(0)) as sub:
        await asyncio.wait_for(bridge.prepare(spawn, ALTITUDE_M), TIMEOUT_S)

        # Hovering: position, altitude and state agree with the vehicle's own.
        t_ready = bridge.time.now_s()
        tel = await next_telemetry(sub, lambda t: t.t_s >= t_ready)
        st = r.vehicle.state
        assert tel.uav == 0
        np.testing.assert_allclose(tel.position_xy_m, st.position_xy_m, atol=0.1)
        assert tel.altitude_m == pytest.approx(st.altitude_m, abs=0.1)
        assert (tel.mode, tel.armed, tel.landed, tel.link) == ("offboard", True, False, "ok")

        # Rate: >= 10 Hz of simulation time over a 3 s window (one message of quantisation).
        t_start = r.now_s()
        count = 0
        while r.now_s() < t_start + 3.0:
            await next_telemetry(sub)
            count += 1
        window_s = r.now_s() - t_start
        assert count >= MIN_RATE_HZ * window_s - 1, f"{count} messages in {window_s:.2f} s"

        # Cruising east then north-east: velocity (east, north) and position agree.
        goal = np.array([spawn[0] + 40.0, spawn[1] + 20.0])
        leg_s = 10.0
        t_leg = r.now_s()
        bridge.set_waypoint(goal, t_leg + leg_s)
        await async_wait_until(lambda: r.now_s() >= t_leg + leg_s / 2, TIMEOUT_S, "mid-leg")
        t_mid = bridge.time.now_s()
        tel = await next_telemetry(sub, lambda t: t.t_s >= t_mid)
        st = r.vehicle.state
        v_en = np.array([st.velocity_ned_mps[1], st.velocity_ned_mps[0]])
        np.testing.assert_allclose(v_en, [4.0, 2.0], atol=0.3)  # 44.7 m in 10 s
        np.testing.assert_allclose(tel.velocity_xy_mps, v_en, atol=0.3)
        # tel is up to a few hundredths of a simulation second older than st.
        expected = st.position_xy_m - v_en * (st.time_s - tel.t_s)
        np.testing.assert_allclose(tel.position_xy_m, expected, atol=1.0)


async def test_two_successive_plans_are_reached_at_their_slot_boundaries(
    rig: Callable[..., Rig],
) -> None:
    slot_s = 4.0
    start = np.array([200.0, 200.0])
    r = rig([tuple(start)], slot_s=slot_s)
    async with r.bridge() as bridge:
        await asyncio.wait_for(bridge.prepare(start, ALTITUDE_M), TIMEOUT_S)
        waypoints = [
            start + np.array([20.0, 0.0]),
            start + np.array([20.0, -16.0]),
        ]  # 5 m/s, then 4 m/s
        rec = r.recorder()
        t0 = math.ceil(r.now_s()) + 1.0
        boundaries = [rec.watch(t0 + k * slot_s) for k in range(3)]
        r.clock.mission_t0_s = t0
        for k, wp in enumerate(waypoints):
            await asyncio.wait_for(boundaries[k].wait(), TIMEOUT_S)  # slot k measured
            bridge.set_waypoint(wp, t0 + (k + 1) * slot_s)  # plan k + 1 arrives
        await asyncio.wait_for(boundaries[2].wait(), TIMEOUT_S)

    snaps = [rec.snapshots[t0 + k * slot_s] for k in range(3)]
    for k, wp in enumerate(waypoints):
        st = snaps[k + 1].states[0]
        assert st.mode is FlightMode.OFFBOARD
        err = distance_m(st.position_xy_m, wp)
        assert err <= ARRIVE_TOL_M, f"plan {k + 1}: {err:.2f} m from the waypoint at the boundary"
    sent = snaps[2].setpoints_sent[0] - snaps[0].setpoints_sent[0]
    rate_hz = sent / (snaps[2].time_s - snaps[0].time_s)
    assert rate_hz >= MIN_RATE_HZ, f"setpoints at {rate_hz:.1f} Hz of simulation time"


async def test_land_lands_and_disarms(rig: Callable[..., Rig], hub: ZenohBus) -> None:
    r = rig([(10.0, 10.0)])
    async with r.bridge() as bridge, hub.subscribe(KEYS.telemetry(0)) as sub:
        await asyncio.wait_for(bridge.prepare((10.0, 10.0), ALTITUDE_M), TIMEOUT_S)
        assert r.vehicle.state.altitude_m > ALTITUDE_M - 1.0
        await asyncio.wait_for(bridge.land(), TIMEOUT_S)
        st = r.vehicle.state
        assert st.landed
        assert not st.armed
        assert st.altitude_m < 0.1
        assert bridge.phase == "landed"
        assert not bridge.streaming
        tel = await next_telemetry(sub, lambda t: t.landed and not t.armed)
        assert tel.altitude_m < 0.1


async def test_link_lost_is_reported_and_offboard_resumes_when_heartbeats_return(
    rig: Callable[..., Rig], hub: ZenohBus
) -> None:
    # No wall-clock keep-alive: a vehicle that stops its HEARTBEAT stream is silent.
    r = rig([(300.0, 300.0)], heartbeat_keepalive_wall_s=None)
    tester = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tester.bind(("127.0.0.1", 0))
    encoder = new_encoder(200, 190)

    def to_vehicle(msg: Any) -> None:
        tester.sendto(pack(msg, encoder), r.vehicle.offboard_address)

    try:
        async with r.bridge() as bridge, hub.subscribe(KEYS.telemetry(0)) as sub:
            await asyncio.wait_for(bridge.prepare((300.0, 300.0), ALTITUDE_M), TIMEOUT_S)
            goal = np.array([330.0, 300.0])
            bridge.set_waypoint(goal, r.now_s() + 20.0)

            # The vehicle stops sending HEARTBEAT (everything else keeps flowing).
            to_vehicle(message_interval_command(Target(1), 0, None))
            lost = await next_telemetry(sub, lambda t: t.link == "lost")
            assert lost.mode == "offboard"  # the last mode heard
            # Meanwhile it takes its loss action (HOLD), which the bridge cannot see yet.
            to_vehicle(hold_mode_command(Target(1)))
            await async_wait_until(
                lambda: r.vehicle.state.mode is FlightMode.HOLD, TIMEOUT_S, "HOLD"
            )
            assert bridge.counters.link_losses == 1

            # Heartbeats return: link ok, and the bridge takes the vehicle back to OFFBOARD.
            to_vehicle(message_interval_command(Target(1), 0, 0.0))
            await next_telemetry(sub, lambda t: t.link == "ok")
            await next_telemetry(sub, lambda t: t.mode == "offboard" and t.link == "ok")
            assert r.vehicle.state.mode is FlightMode.OFFBOARD
            assert bridge.counters.offboard_reentries == 1
            # ... and it carries on to the waypoint from where it held.
            await async_wait_until(
                lambda: distance_m(r.vehicle.state.position_xy_m, goal) < 1.0,
                TIMEOUT_S,
                "arrival at the waypoint after the link came back",
            )
    finally:
        tester.close()


# --------------------------------------------------------------------------- the fleet


def free_udp_port_block(n: int) -> int:
    """A base port b with b .. b + n - 1 all free on 127.0.0.1 a moment ago."""
    rng = random.Random()
    for _ in range(100):
        base = rng.randrange(20_000, 60_000)
        socks: list[socket.socket] = []
        try:
            for i in range(n):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind(("127.0.0.1", base + i))
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
        return base
    raise RuntimeError(f"no block of {n} free UDP ports")


def plan_msg(slot: int, waypoints: np.ndarray) -> PlanMsg:
    m = len(waypoints)
    plan = SlotPlan(
        uav_xy_m=waypoints,
        bs_of_uav=np.zeros(m, dtype=np.int64),
        bandwidth_share=np.full(m, 1.0 / m),
        pcrb_trace=1.0,
        report=SolveReport(status="ok"),
    )
    return PlanMsg(slot=slot, t_s=0.0, plan=plan)


async def test_fleet_prepares_follows_plans_and_lands_three_vehicles_of_the_world(
    paper: Scenario, hub: ZenohBus, free_tcp_port: int
) -> None:
    scenario = paper.with_changes(H=ALTITUDE_M, dt=2.0, mission_id=KEYS.mission)
    n_uavs = scenario.M
    assert n_uavs == 3
    endpoint = hub.settings.listen[0]
    options = WorldOptions(
        speed=SPEED,
        bus=BusSettings(connect=(endpoint,)),
        mavlink_base_port=free_udp_port_block(n_uavs),
        gcs_base_port=free_udp_port_block(n_uavs),
        start="offboard",
    )
    world = World(scenario, options)
    stop = asyncio.Event()
    world_task: asyncio.Task[None] | None = None
    time_source = ClockSimTime()
    fleet = BridgeFleet.from_scenario(
        scenario, time_source, hub, base_port=options.mavlink_base_port
    )
    try:
        await world.open()
        world_task = asyncio.create_task(world.run(stop))
        async with fleet, hub.subscribe(KEYS.detections_all) as detections:
            follow = asyncio.create_task(fleet.follow_plans())
            # The ground loop, running from the start: after slot n's detections, publish
            # plan n + 1; collect where the vehicles were measured.
            starts = scenario.uav_start_xy
            plans = {1: starts + np.array([6.0, 0.0]), 2: starts + np.array([6.0, 5.0])}
            seen: dict[int, dict[int, np.ndarray]] = {}

            async def ground() -> None:
                while len(seen.get(2, {})) < n_uavs:
                    _, payload = await detections.get(TIMEOUT_S)
                    det = decode_detection(payload, n_uavs=n_uavs)
                    seen.setdefault(det.slot, {})[det.uav] = det.uav_xy_m
                    if len(seen[det.slot]) == n_uavs and det.slot + 1 in plans:
                        plan = plan_msg(det.slot + 1, plans[det.slot + 1])
                        hub.publish(KEYS.plan, encode_plan(plan))

            ground_task = asyncio.create_task(ground())
            await asyncio.wait_for(fleet.prepare_all(), TIMEOUT_S)
            for v in world.vehicles:
                assert v.state.mode is FlightMode.OFFBOARD
                assert abs(v.state.altitude_m - ALTITUDE_M) <= 1.0
            await asyncio.wait_for(ground_task, TIMEOUT_S)

            for n, waypoints in plans.items():
                for m in range(n_uavs):
                    err = distance_m(seen[n][m], waypoints[m])
                    assert err <= ARRIVE_TOL_M, f"slot {n}, UAV {m}: {err:.2f} m off"
            assert fleet.counters.plans_applied == 2

            await asyncio.wait_for(fleet.land_all(), TIMEOUT_S)
            for v in world.vehicles:
                assert v.state.landed
                assert not v.state.armed
            follow.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await follow
    finally:
        stop.set()
        if world_task is not None:
            await asyncio.wait_for(world_task, TIMEOUT_S)
        await world.close()
