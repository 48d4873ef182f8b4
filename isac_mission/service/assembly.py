"""The live mission's composition root: what `run` and `serve` build and fly, from the settings
the command line parsed (`LiveOptions`).

`run_mission` opens the ground's Zenoh session, starts the world beside the service when it runs
in this process (`WorldBeside`: `run`'s simulator, given by the command line), and flies the
mission on that session (`fly_mission`): the solver kit with its compiled-problem cache, the
clock, the MAVLink bridges and the ground loop (service/ground/loop.py, for any number of
targets). Whoever runs it reaches the mission through two ports: `Progress` (what it
reports while it flies) and `Stopping` (how it is ended early: the command line's Ctrl-C).

Everything talks over real loopback UDP MAVLink and a real Zenoh session. Mission start
(docs/service.md): the bridges arm the vehicles, take off to H, fly to the start points and enter
offboard; the world starts slot 0 when all of them are there (`start="offboard"`); the ground
loop then plans slot 1, and so on to slot N. At the end, or on a stop request, the vehicles land.

The planner cluster (`LiveOptions.planner_cluster`, `--planner-workers/--planner-scheduler`;
isac_mission/planner_cluster.py): `run_mission` starts it (or connects to the scheduler)
before anything else of the mission and closes it after everything, the landing included,
however the mission ends (`_planner_executor`); `fly_mission` sets its executor on the full
fleet's kit, where every kit the ground loop plans with finds it (the kits renewed for an
operator's R_th or after a timeout share it: SolverKit.renewed; a sub-fleet's kit takes it from
the full kit: planning/fleet.KitCache). Its deadline defaults to `live_deadline_s` of the
slot's planning budget.
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import logging
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from isac_mission.bus import ZenohBus
from isac_mission.bus.security import default_endpoint, secured_settings
from isac_mission.config import Scenario
from isac_mission.config.live_settings import LIVE_SETTINGS, LiveSettings
from isac_mission.errors import IsacError
from isac_mission.mavwire.ports import (
    GCS_LOCAL_BASE_PORT,
    GCS_PORT,
    OFFBOARD_BASE_PORT,
    OFFBOARD_LOCAL_BASE_PORT,
)
from isac_mission.mavwire.serial_link import parse_vehicle_links
from isac_mission.nlp_cache import CompiledNlpCache
from isac_mission.planner_cluster import DaskGroupExecutor, PlannerCluster, cluster_description
from isac_mission.planning.decomposed import GroupExecutor, use_group_executor
from isac_mission.planning.fleet import prepare_fleet
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method
from isac_mission.records.tracks import TracksSlot
from isac_mission.service.bridge.clock_time import ClockSimTime
from isac_mission.service.bridge.fleet import BridgeFleet
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.planner_thread import SOLVE_LOCK
from isac_mission.service.ground.report import GroundReport, SlotEvent
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.service.mission_result import LiveResult, mirror_signing_counters, record_fleet
from isac_mission.tracking.factory import keep_out_tracks
from isac_mission.types import FloatArray

log = logging.getLogger(__name__)

WAITING = "waiting for the clock and the vehicles"
"""The mission's status while nothing has been told to take off yet."""
TAKING_OFF = "arming, taking off and flying to the start points"
"""The mission's status once the fleet has been told to take off."""
CLOCK_WAIT_S = 60.0
"""Wall seconds the mission waits for the world's clock before it gives up."""
WORLD_STOP_S = 30.0
"""Wall seconds a world beside the service may take to stop once the mission has ended."""
CLUSTER_SLOTS = "planner cluster slots"
"""The report's counter of the slots whose groups were all solved on the planner cluster."""
CLUSTER_FALLBACKS = "planner cluster fallbacks"
"""The report's counter of the slots the planner cluster failed (a job raised, a worker died,
the deadline passed): each flew the per-slot plan, fallback `horizon: decomposed worker lost`."""


@dataclass(frozen=True)
class LiveOptions:
    """speed: simulation seconds per wall second; lockstep: the world waits for each slot's plan;
    method: planning strategy; seed: world noise seed (None: the scenario's); out_dir: trace and
    plots; zenoh_endpoint: where the ground loop listens (the world and observers connect; None:
    `tcp/127.0.0.1:7447`, or `tls/...` when the scenario's security.zenoh has TLS on);
    mavlink_base_port, mavlink_local_base_port, gcs_port, gcs_local_base_port: PX4 SITL's port
    layout (vehicle m: offboard link from 14580 + m to 14540 + m, where the bridges listen;
    ground-station link from 18570 + m to 14550; local ports of the embedded world only);
    vehicle_links: `M=URL` per vehicle (serve): vehicle M's link URL instead of UDP
    base + M (`isac_mission.mavwire.serial_link`, e.g. `1=serial:/dev/ttyUSB0:57600`);
    resume: continue an existing trace (serve); plan_speed_fraction: the planner's speed budget
    as a fraction of V_max, the headroom a vehicle with finite acceleration needs to be at each
    waypoint by the slot's end; plan_rate_factor, plan_safety_margin_m: the planner asks for
    R_th x factor and D_s + margin, so that a vehicle a few metres off its waypoint still meets
    14a, 14i and 14j; plan_accel_fraction: the planner keeps each waypoint reachable with this
    fraction of the vehicles' acceleration limit a_max (0: off, the paper's kinematics);
    plan_vehicle_model: plan on the vehicles' dynamics (planner.vehicle_model). Defaults:
    isac_mission.config.live_settings.LIVE_SETTINGS (docs/model.md, "Live service")."""

    speed: float = 1.0
    lockstep: bool = False
    method: Method = "proposed"
    seed: int | None = None
    out_dir: Path = Path("out/run")
    zenoh_endpoint: str | None = None
    zenoh_connect: tuple[str, ...] = ()
    mavlink_base_port: int = OFFBOARD_BASE_PORT
    mavlink_local_base_port: int = OFFBOARD_LOCAL_BASE_PORT
    gcs_port: int = GCS_PORT
    gcs_local_base_port: int = GCS_LOCAL_BASE_PORT
    vehicle_links: tuple[str, ...] = ()
    resume: bool = False
    plan_speed_fraction: float = LIVE_SETTINGS.speed_fraction
    plan_rate_factor: float = LIVE_SETTINGS.rate_factor
    plan_safety_margin_m: float = LIVE_SETTINGS.safety_margin_m
    plan_accel_fraction: float = LIVE_SETTINGS.accel_fraction
    plan_vehicle_model: bool = LIVE_SETTINGS.vehicle_model
    link_outages: tuple[str, ...] = ()
    """Embedded world only: scheduled radio failures `VEHICLE:START_S:DURATION_S`
    (sim.world_options)."""
    link_impairment: tuple[str, ...] = ()
    """Embedded world only: `--impair-link` specs over the scenario's `impairment` section
    (isac_mission.config.impairment)."""
    plan_budget_s: float | None = 1.0
    """Wall seconds a slot's planning may take (GroundSettings.plan_budget_s)."""
    planner_cluster: PlannerCluster | None = None
    """Where the decomposed horizon's groups are solved (None: in this process, one after the
    other): a local Dask cluster or a scheduler's, for the mission (module doc); its deadline,
    when not given, `live_deadline_s(plan_budget_s)`."""

    @property
    def trace_path(self) -> Path:
        return self.out_dir / f"trace_{self.method}.jsonl"

    @property
    def live_settings(self) -> LiveSettings:
        """The planning margins of these options (isac_mission.config.live_settings)."""
        return LiveSettings(
            speed_fraction=self.plan_speed_fraction,
            rate_factor=self.plan_rate_factor,
            safety_margin_m=self.plan_safety_margin_m,
            accel_fraction=self.plan_accel_fraction,
            vehicle_model=self.plan_vehicle_model,
        )


@dataclass(frozen=True)
class Progress:
    """What a mission reports while it flies (each one optional): on_status(phase), the phase
    it is in (WAITING, TAKING_OFF, "mission running", "landing", ...); on_slot(event), after each
    slot of a one-target mission; on_tracks(slot, latency_s), after each slot of a multi-target
    mission, latency_s: wall seconds from the slot's last detection to its plan."""

    on_status: Callable[[str], None] | None = None
    on_slot: Callable[[SlotEvent], None] | None = None
    on_tracks: Callable[[TracksSlot, float], None] | None = None

    def status(self, phase: str) -> None:
        """Report the mission's phase, if anyone listens."""
        if self.on_status is not None:
            self.on_status(phase)


SILENT = Progress()
"""No one listens to the mission's progress."""


@dataclass(frozen=True)
class Stopping:
    """How a mission is ended early (the command line's Ctrl-C and SIGTERM set these:
    cli/stopping.py). stop: the mission ends after the slot in flight and the fleet lands;
    leave, set while the fleet lands: the service stops waiting for touchdown (the vehicles were
    sent LAND and land on their own)."""

    stop: asyncio.Event = field(default_factory=asyncio.Event)
    leave: asyncio.Event = field(default_factory=asyncio.Event)


@dataclass(frozen=True)
class WorldBeside:
    """A world flown in this process beside the service (the command line's embedded simulator,
    cli/embedded.py). run(stop): the world, until `stop` is set; initial_x [4] (m, m/s): the
    initial_errors [T, 4] (m, m/s): added to each known target's configured state to start its
    track (the world's draw of the offline twin's x_hat - x; None: the configured state)."""

    run: Callable[[asyncio.Event], Coroutine[Any, Any, object]]
    initial_errors: FloatArray | None = None


def planning_scenario(s: Scenario, opts: LiveOptions) -> Scenario:
    """The scenario the live planner plans with: `opts.live_settings` applied to `s`
    (isac_mission.config.live_settings; `simulate --live-settings` plans on the same)."""
    return opts.live_settings.apply(s)


def ground_endpoint(s: Scenario, opts: LiveOptions) -> str:
    """Where the ground loop listens: the option, else the default for the scenario's security."""
    return opts.zenoh_endpoint or default_endpoint(s.security.zenoh)


def land_budget_s(height_m: float, speed: float) -> float:
    """Wall seconds the service waits for the fleet to land from `height_m` (m) at `speed`
    (simulation seconds per wall second): about 1 m/s of descent, three times over, plus 60 s."""
    return 60.0 + 3.0 * height_m / max(speed, 1e-3)


async def run_mission(
    s: Scenario,
    opts: LiveOptions,
    stopping: Stopping,
    progress: Progress = SILENT,
    world: WorldBeside | None = None,
    executor: GroupExecutor | None = None,
) -> LiveResult:
    """The live mission: the planner cluster of `opts.planner_cluster` started (module doc),
    the ground's Zenoh session listening on `ground_endpoint` (and connecting to
    `opts.zenoh_connect`), `world` beside the service when given (None: the world, or real
    vehicles and sensing, run elsewhere: `serve`), and `fly_mission` on the session; then the
    cluster closed. executor: where the decomposed horizon's groups are solved, owned by the
    caller (a notebook's, a test's), instead of opts.planner_cluster (ValueError with both).
    A Dask executor's tally is put in the report's counters at the end (CLUSTER_SLOTS,
    CLUSTER_FALLBACKS)."""
    if executor is not None and opts.planner_cluster is not None:
        raise ValueError("give the mission an executor or a planner cluster, not both")
    hub = secured_settings(
        s.security.zenoh,
        s.mission_id,
        "ground",
        listen=(ground_endpoint(s, opts),),
        connect=opts.zenoh_connect,
    )
    async with _planner_executor(opts, progress) as opened:
        groups = executor if executor is not None else opened
        with ZenohBus.open(hub) as bus:
            if world is None:
                result = await fly_mission(s, opts, bus, stopping, progress, executor=groups)
            else:
                world_stop = asyncio.Event()
                world_task = asyncio.create_task(world.run(world_stop))
                try:
                    result = await fly_mission(s, opts, bus, stopping, progress, world, groups)
                finally:
                    world_stop.set()
                    async with asyncio.timeout(WORLD_STOP_S):
                        await world_task
        if isinstance(groups, DaskGroupExecutor):
            result.report.counters[CLUSTER_SLOTS] = groups.slots
            result.report.counters[CLUSTER_FALLBACKS] = groups.failures
        return result


@contextlib.asynccontextmanager
async def _planner_executor(
    opts: LiveOptions, progress: Progress
) -> AsyncIterator[GroupExecutor | None]:
    """The executor of `opts.planner_cluster` for the mission (None without one): the local
    cluster started, or the scheduler connected to, on a thread (it takes seconds; a scheduler
    off this machine is a warning in the log), and closed on the way out whatever ended the
    mission (a failure, a stop, a cancellation), with a line of what it solved."""
    cluster = opts.planner_cluster
    if cluster is None:
        yield None
        return
    deadline_s = cluster.deadline_for(opts.plan_budget_s)
    if cluster.leaves_the_machine:
        log.warning(
            "planner cluster: %s is not on this machine's loopback: the decomposed horizon's "
            "groups (their inputs and plans) leave this machine, unencrypted",
            cluster.scheduler,
        )
    progress.status(f"starting the planner cluster: {cluster.where}")
    loop = asyncio.get_running_loop()
    stack = contextlib.ExitStack()
    # Opened and closed on threads, in one context (the Client keeps a context variable that
    # it resets where it was set); shielded: a cancellation while the cluster starts still
    # closes it once it is up.
    context = contextvars.copy_context()

    def close() -> Awaitable[None]:
        return asyncio.shield(loop.run_in_executor(None, context.run, stack.close))

    starting = loop.run_in_executor(
        None, context.run, stack.enter_context, cluster.executor(opts.plan_budget_s)
    )
    try:
        executor = await asyncio.shield(starting)
    except BaseException:
        with contextlib.suppress(BaseException):
            await starting
        await close()
        raise
    try:
        where = await asyncio.to_thread(cluster_description, executor.client)
        log.info("planner cluster: %s, deadline %g s a slot", where, deadline_s)
        progress.status(f"planner cluster: {where}, deadline {deadline_s:g} s a slot")
        yield executor
    finally:
        try:
            await close()
        except Exception as err:  # the mission's own outcome stands; say what was left
            log.warning("planner cluster: closing it failed (%s: %s)", type(err).__name__, err)
        lost = f", last: {executor.last_error}" if executor.failures else ""
        log.info(
            "planner cluster closed: %d slots' groups solved on it, %d flew the per-slot plan "
            "(decomposed worker lost)%s",
            executor.slots,
            executor.failures,
            lost,
        )


async def run_serve(
    s: Scenario,
    opts: LiveOptions,
    stop: asyncio.Event,
    on_slot: Callable[[SlotEvent], None] | None = None,
    on_status: Callable[[str], None] | None = None,
    on_tracks: Callable[[TracksSlot, float], None] | None = None,
    leave: asyncio.Event | None = None,
    world: WorldBeside | None = None,
    executor: GroupExecutor | None = None,
) -> LiveResult:
    """`run_mission` with the world elsewhere (or `world` beside it), its ports given as plain
    events and callbacks (for scripts and tests; `leave` None: the landing is always waited
    for; executor: as `run_mission`'s)."""
    stopping = Stopping(stop, leave or asyncio.Event())
    progress = Progress(on_status, on_slot, on_tracks)
    return await run_mission(s, opts, stopping, progress, world, executor)


async def fly_mission(
    s: Scenario,
    opts: LiveOptions,
    bus: ZenohBus,
    stopping: Stopping,
    progress: Progress = SILENT,
    world: WorldBeside | None = None,
    executor: GroupExecutor | None = None,
) -> LiveResult:
    """Bridges + ground loop on `bus`; the world (or real vehicles and sensing) elsewhere, or
    `world` beside it (its tracker start is taken); the decomposed horizon's groups solved on
    `executor` (None: in this process), set on the full fleet's kit (module doc)."""
    planning = planning_scenario(s, opts)
    kit, compiled, ahead = await _solver_kit(planning, opts.method)
    if executor is not None:
        use_group_executor(kit, executor)
    progress.status(f"planner problems built for {planning.M} vehicles and, ahead, for {ahead}")
    time_source = ClockSimTime()
    fleet = BridgeFleet.from_scenario(
        s,
        time_source,
        bus,
        base_port=opts.mavlink_base_port,
        links=parse_vehicle_links(opts.vehicle_links, s.M),
    )
    ground = _ground_loop(s, planning, opts, bus, kit, progress, world)
    result = LiveResult(GroundReport(), opts.trace_path)
    # The list itself: a background compile appends to it while the mission flies.
    result.sizes_built_ahead = ahead
    result.planner_problems = compiled.events
    async with fleet:
        # The ground loop and the plan follower listen from the start: the world announces slot 0
        # as soon as every vehicle is in place, and in lockstep it then waits for plan 1.
        follower = asyncio.create_task(fleet.follow_plans())
        mirror = asyncio.create_task(mirror_signing_counters(fleet, ground.report))
        ground_task = asyncio.create_task(ground.run(stopping.stop))
        try:
            progress.status(WAITING)
            await _until_stopped(time_source.wait_ready(timeout_s=CLOCK_WAIT_S), stopping.stop)
            progress.status(TAKING_OFF)
            await _until_stopped(fleet.prepare_all(), stopping.stop)
            progress.status("mission running")
            result.report = await ground_task
            result.interrupted = not ground.state.done
        finally:
            stopping.stop.set()
            for task in (follower, mirror, ground_task):
                if not task.done():
                    task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
            result.multi_target_slots = list(getattr(ground.output, "slots", ()))
            progress.status("landing")
            await _land(fleet, land_budget_s(s.H, opts.speed), stopping, result)
            record_fleet(result, fleet)
    return result


async def _solver_kit(
    planning: Scenario, method: Method
) -> tuple[SolverKit, CompiledNlpCache, list[int]]:
    """The planner's kit for `planning` (keep-out points for its tracker's other tracks), its
    compiled-problem cache, and the smaller fleets whose problems were built ahead
    (prepare_fleet)."""
    n_keep_out = keep_out_tracks(planning)
    # IPOPT problems compiled and cached on disk (isac_mission/nlp_cache.py): loaded when there,
    # else interpreted until a background compile has written them.
    compiled = CompiledNlpCache()
    kit = SolverKit(planning, n_keep_out=n_keep_out, solve_lock=SOLVE_LOCK, ipopt=compiled)
    # On a thread: the event loop meanwhile opens an embedded world's vehicles (ground stations
    # see them at once) and the bus; the kit is not used by anything else until it returns.
    ahead = await asyncio.to_thread(prepare_fleet, kit, method, n_keep_out)
    return kit, compiled, ahead


def live_trace_limits(s: Scenario, planning: Scenario) -> dict[str, object]:
    """What a live trace's config line states over the planning scenario's: the vehicles' real
    limits (v_max, r_th, d_safe), and the planner's budget beside them (plan_*)."""
    return {
        "v_max": s.v_max,
        "r_th": s.r_th,
        "d_safe": s.d_safe,
        "plan_v_max": planning.v_max,
        "plan_r_th": planning.r_th,
        "plan_d_safe": planning.d_safe,
    }


def _ground_loop(
    s: Scenario,
    planning: Scenario,
    opts: LiveOptions,
    bus: ZenohBus,
    kit: SolverKit,
    progress: Progress,
    world: WorldBeside | None,
) -> GroundLoop:
    """The ground loop for `s`, planning on `planning` with `kit`, its trace stating the
    vehicles' real limits beside the planner's."""
    settings = GroundSettings(
        method=opts.method,
        trace_path=opts.trace_path,
        resume=opts.resume,
        plan_rate_factor=opts.plan_rate_factor,
        plan_budget_s=opts.plan_budget_s,
        wait_for_telemetry=True,  # the bridges publish it (ground/startup.py)
        trace_config=live_trace_limits(s, planning),
    )
    initial_errors = world.initial_errors if world is not None else None
    return GroundLoop(
        planning, bus, settings, kit, progress.on_slot, initial_errors, progress.on_tracks
    )


async def _land(
    fleet: BridgeFleet, budget_s: float, stopping: Stopping, result: LiveResult
) -> None:
    """Land the fleet, waiting at most `budget_s` wall seconds, or until `stopping.leave`; a
    landing that fails or times out is the report's last error."""
    try:
        async with asyncio.timeout(budget_s):
            await _until_stopped(fleet.land_all(), stopping.leave)
        result.landing_abandoned = stopping.leave.is_set()
    except (IsacError, TimeoutError) as err:
        log.error("landing: %s", err)
        result.report.last_error = f"landing: {err}"


async def _until_stopped(aw: object, stop: asyncio.Event) -> None:
    """Await `aw` unless `stop` is set first (then cancel it)."""
    task = asyncio.ensure_future(aw)  # type: ignore[call-overload]
    stopper = asyncio.ensure_future(stop.wait())
    done, _ = await asyncio.wait({task, stopper}, return_when=asyncio.FIRST_COMPLETED)
    stopper.cancel()
    if task in done:
        task.result()
        return
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError, IsacError):
        await task
