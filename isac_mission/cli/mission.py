"""The live mission on the service side: options, the bridges + ground loop runner (`serve`, and
the service half of `run`), and the end-of-run summary. The embedded world is in
`isac_mission.cli.embedded`, the only module that imports both `sim` and the service.

Everything talks over real loopback UDP MAVLink and a real Zenoh session. Mission start
(docs/service.md): the bridges arm the vehicles, take off to H, fly to the start points and enter
offboard; the world starts slot 0 when all of them are there (`start="offboard"`); the ground loop then plans
slot 1, and so on to slot N. At the end, or on a stop request, the vehicles land.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from isac_mission.bus import ZenohBus
from isac_mission.bus.security import default_endpoint, secured_settings
from isac_mission.cli.stopping import land_budget_s
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
from isac_mission.mavwire.signing import SIGNATURE_REJECTIONS
from isac_mission.nlp_cache import CompiledNlpCache
from isac_mission.planning.fleet import prepare_fleet
from isac_mission.planning.multi_target import KEEP_OUT_CAPACITY
from isac_mission.planning.slot import Method, SolverKit
from isac_mission.records.multi_target import MultiTargetSlot
from isac_mission.service.bridge.clock_time import ClockSimTime
from isac_mission.service.bridge.fleet import BridgeFleet
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.multi_target import MultiTargetGround
from isac_mission.service.ground.planner_thread import SOLVE_LOCK
from isac_mission.service.ground.report import GroundReport, SlotEvent
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.types import FloatArray

log = logging.getLogger(__name__)

WAITING = "waiting for the clock and the vehicles"
"""fly_mission's status while nothing has been told to take off yet."""
TAKING_OFF = "arming, taking off and flying to the start points"
"""fly_mission's status once the fleet has been told to take off."""


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


@dataclass
class LiveResult:
    """What a live mission produced."""

    report: GroundReport
    trace_path: Path
    phases: dict[str, float] = field(default_factory=dict)
    fleet_counters: dict[str, int] = field(default_factory=dict)
    detection_to_setpoint_s: list[float] = field(default_factory=list)
    """Per slot n: wall time from slot n's last detection to the first setpoint of plan n+1
    (the latest bridge.TIMESTAMPS_KEPT plans of a long mission)."""
    setpoint_periods_s: dict[int, list[float]] = field(default_factory=dict)
    """Per vehicle: wall intervals between the stream's periodic setpoints during the mission
    (its latest bridge.TIMESTAMPS_KEPT setpoints)."""
    multi_target_slots: list[MultiTargetSlot] = field(default_factory=list)
    """A multi-target mission's slots (the ground loop's last SLOTS_KEPT); empty otherwise."""
    sizes_built_ahead: list[int] = field(default_factory=list)
    """The smaller fleets whose planner problems were built before the mission (prepare_fleet)."""
    planner_problems: list[str] = field(default_factory=list)
    """How each IPOPT problem was built: interpreted, loaded compiled, or compiled in the
    background (nlp_cache.py's events; the cache's own list, appended to while the mission flies)."""
    interrupted: bool = False
    """The mission was asked to stop (Ctrl-C, SIGTERM) before slot N was done."""
    landing_abandoned: bool = False
    """A second request to stop came while the fleet was landing: the service stopped waiting
    for touchdown (the vehicles were sent LAND and land on their own)."""


def planning_scenario(s: Scenario, opts: LiveOptions) -> Scenario:
    """The scenario the live planner plans with: `opts.live_settings` applied to `s`
    (isac_mission.config.live_settings; `simulate --live-settings` plans on the same)."""
    return opts.live_settings.apply(s)


async def fly_mission(
    s: Scenario,
    opts: LiveOptions,
    bus: ZenohBus,
    stop: asyncio.Event,
    on_slot: Callable[[SlotEvent], None] | None,
    on_status: Callable[[str], None] | None,
    initial_x: FloatArray | None = None,
    on_tracks: Callable[[MultiTargetSlot, float], None] | None = None,
    initial_errors: FloatArray | None = None,
    leave: asyncio.Event | None = None,
) -> LiveResult:
    """Bridges + ground loop on `bus`; the world (or real vehicles and sensing) elsewhere.
    initial_x [4]: the tracker's initial estimate (None: the scenario's x0). On a multi-target
    scenario the multi-target ground loop runs instead (service/ground/multi_target.py):
    on_tracks(slot, latency_s) after each slot; initial_errors [T, 4]: added to each known
    target's configured state to start its track (None: none). `stop` ends the mission and
    lands the fleet; `leave`, set while it lands, stops waiting for touchdown."""
    say = on_status or (lambda _msg: None)
    planning = planning_scenario(s, opts)
    n_keep_out = KEEP_OUT_CAPACITY if s.multi_target else 0
    # IPOPT problems compiled and cached on disk (isac_mission/nlp_cache.py): loaded when there,
    # else interpreted until a background compile has written them.
    compiled = CompiledNlpCache()
    kit = SolverKit(planning, n_keep_out=n_keep_out, solve_lock=SOLVE_LOCK, ipopt=compiled)
    # On a thread: the event loop meanwhile opens an embedded world's vehicles (ground stations
    # see them at once) and the bus; the kit is not used by anything else until it returns.
    ahead = await asyncio.to_thread(prepare_fleet, kit, opts.method, n_keep_out)
    say(f"planner problems built for {planning.M} vehicles and, ahead, for {ahead}")
    time_source = ClockSimTime()
    fleet = BridgeFleet.from_scenario(
        s,
        time_source,
        bus,
        base_port=opts.mavlink_base_port,
        links=parse_vehicle_links(opts.vehicle_links, s.M),
    )
    settings = GroundSettings(
        method=opts.method,
        trace_path=opts.trace_path,
        resume=opts.resume,
        plan_rate_factor=opts.plan_rate_factor,
        plan_budget_s=opts.plan_budget_s,
        wait_for_telemetry=True,  # the bridges publish it (ground/startup.py)
        # The trace states the vehicles' real limit; the planner's budget goes beside it.
        trace_config={
            "v_max": s.v_max,
            "r_th": s.r_th,
            "d_safe": s.d_safe,
            "plan_v_max": planning.v_max,
            "plan_r_th": planning.r_th,
            "plan_d_safe": planning.d_safe,
        },
    )
    ground: GroundLoop | MultiTargetGround
    if s.multi_target:
        ground = MultiTargetGround(planning, bus, settings, kit, on_tracks, initial_errors)
    else:
        ground = GroundLoop(planning, bus, settings, kit, on_slot, initial_x)
    result = LiveResult(GroundReport(), opts.trace_path)
    # The list itself: a background compile appends to it while the mission flies.
    result.sizes_built_ahead = ahead
    result.planner_problems = compiled.events
    async with fleet:
        # The ground loop and the plan follower listen from the start: the world announces slot 0
        # as soon as every vehicle is in place, and in lockstep it then waits for plan 1.
        follower = asyncio.create_task(fleet.follow_plans())
        mirror = asyncio.create_task(mirror_signing_counters(fleet, ground.report))
        ground_task = asyncio.create_task(ground.run(stop))
        try:
            say(WAITING)
            await _until_stopped(time_source.wait_ready(timeout_s=60.0), stop)
            say(TAKING_OFF)
            await _until_stopped(fleet.prepare_all(), stop)
            say("mission running")
            result.report = await ground_task
            result.interrupted = not ground.state.done
        finally:
            stop.set()
            for task in (follower, mirror, ground_task):
                if not task.done():
                    task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
            if isinstance(ground, MultiTargetGround):
                result.multi_target_slots = list(ground.slots)
            say("landing")
            try:
                async with asyncio.timeout(land_budget_s(s.H, opts.speed)):
                    await _until_stopped(fleet.land_all(), leave or asyncio.Event())
                result.landing_abandoned = leave is not None and leave.is_set()
            except (IsacError, TimeoutError) as err:
                log.error("landing: %s", err)
                result.report.last_error = f"landing: {err}"
            _timing_figures(result, fleet, opts.speed)
            c = fleet.counters
            result.fleet_counters = {
                "plans applied": c.plans_applied,
                "plans invalid": c.plans_invalid,
                "vehicles landed": sum(b.phase == "landed" for b in fleet.bridges),
                "vehicles never heard": sum(
                    b.link.status().heartbeat_s is None for b in fleet.bridges
                ),
                "link losses": sum(b.counters.link_losses for b in fleet.bridges),
                "link interruptions": sum(b.counters.link_interruptions for b in fleet.bridges),
                "offboard re-entries": sum(b.counters.offboard_reentries for b in fleet.bridges),
            }
    return result


def signing_counters(fleet: BridgeFleet) -> dict[str, int]:
    """The bridges' MAVLink signing rejections, summed over the fleet, as health counters:
    `mavlink unsigned`, `mavlink bad_signature`, `mavlink replayed` (0 with signing off)."""
    return {
        f"mavlink {reason}": sum(b.link.errors[reason] for b in fleet.bridges)
        for reason in SIGNATURE_REJECTIONS
    }


async def mirror_signing_counters(fleet: BridgeFleet, report: GroundReport) -> None:
    """Keep `signing_counters` in the ground loop's counters (published in every `health`),
    refreshed every 0.2 wall seconds until cancelled."""
    while True:
        for name, n in signing_counters(fleet).items():
            report.counters[name] = n
        await asyncio.sleep(0.2)


def _timing_figures(result: LiveResult, fleet: BridgeFleet, speed: float) -> None:
    """Detection-to-setpoint latency and setpoint periods, from the bridges' wall timestamps."""
    last_det = result.report.last_detection_wall_s
    firsts = [b.first_setpoint_wall_s for b in fleet.bridges]
    for n, t_det in sorted(last_det.items()):
        sent = [f[n + 1] for f in firsts if n + 1 in f]
        if sent:
            result.detection_to_setpoint_s.append(min(sent) - t_det)
    if last_det:
        t0, t1 = min(last_det.values()), max(last_det.values())
        for b in fleet.bridges:
            times = [w for w in b.setpoint_wall_s if t0 <= w <= t1]
            result.setpoint_periods_s[b.index] = list(np.diff(times))


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


async def run_serve(
    s: Scenario,
    opts: LiveOptions,
    stop: asyncio.Event,
    on_slot: Callable[[SlotEvent], None] | None = None,
    on_status: Callable[[str], None] | None = None,
    on_tracks: Callable[[MultiTargetSlot, float], None] | None = None,
    leave: asyncio.Event | None = None,
) -> LiveResult:
    """Bridges and ground loop only: the world (or vehicles and sensing) runs elsewhere
    (on_tracks, leave: fly_mission's)."""
    settings = secured_settings(
        s.security.zenoh,
        s.mission_id,
        "ground",
        listen=(ground_endpoint(s, opts),),
        connect=opts.zenoh_connect,
    )
    with ZenohBus.open(settings) as bus:
        return await fly_mission(
            s, opts, bus, stop, on_slot, on_status, on_tracks=on_tracks, leave=leave
        )


def ground_endpoint(s: Scenario, opts: LiveOptions) -> str:
    """Where the ground loop listens: the option, else the default for the scenario's security."""
    return opts.zenoh_endpoint or default_endpoint(s.security.zenoh)


@dataclass(frozen=True)
class LiveSummary:
    """End-of-run figures (m, m/s, m^2, ms)."""

    slots: int
    loc_rmse: float
    vel_rmse: float
    pcrb_mean: float
    solve_median_ms: float
    solve_p95_ms: float
    latency_median_ms: float
    latency_p99_ms: float
    infeasible: int
    fallbacks: dict[str, int]
    """Slots whose method's answer was not flown, by kind (docs/trace.md, "Fallbacks")."""


def summarize_live(result: LiveResult) -> LiveSummary:
    """RMSE against the world's truth and mean bound over the whole run; planning and
    detection-to-plan times over the slots the report keeps (the last SLOTS_KEPT)."""
    tot = result.report.totals
    recs = result.report.records
    solve = np.array([r.solve_ms for r in recs]) if recs else np.array([math.nan])
    lat = (
        np.array(result.report.latencies_s) * 1e3
        if result.report.latencies_s
        else np.array([math.nan])
    )
    n_truth = tot.with_truth
    return LiveSummary(
        slots=tot.slots,
        loc_rmse=math.sqrt(tot.position_sq_error_m2 / n_truth) if n_truth else math.nan,
        vel_rmse=math.sqrt(tot.velocity_sq_error_m2ps2 / n_truth) if n_truth else math.nan,
        pcrb_mean=tot.pcrb_trace_sum / tot.slots if tot.slots else math.nan,
        solve_median_ms=float(np.median(solve)),
        solve_p95_ms=float(np.percentile(solve, 95)),
        latency_median_ms=float(np.median(lat)),
        latency_p99_ms=float(np.percentile(lat, 99)),
        infeasible=tot.statuses["infeasible"],
        fallbacks=dict(tot.fallbacks),
    )
