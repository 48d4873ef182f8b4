"""Soak harness: a long live mission in this process, sampled slot by slot.

`run_soak` flies `slots` slots of the paper's mission live, as `isac-mission run` does (the
simulated world, the MAVLink bridges and the ground loop, over loopback UDP MAVLink and a real
Zenoh session; here the world runs as a task next to `run_serve`, so that the target can be
chosen), and records after every slot: wall time, this process's CPU time (all threads), its
resident set size (VmRSS) and the slot's planning time. `quarter_table` reduces the samples to
per-quarter medians and the first-vs-last-quarter ratios the soak test asserts on.

Target: by default a scripted loop, a circle of radius 450 m around (1500, 1600) m flown at
15 m/s (a lap of about 188 s), clockwise from its west point (1050, 1600) m heading north: it
turns at 15² / 450 = 0.5 m/s² all the time, within the scenario's manoeuvre bound
(`target_motion.max_accel_mps2`, 2 m/s²), so that the four quarters of a long run are
statistically the same mission, and slower than the UAVs, which must keep D_s from it. The circle is flown as a
360-gon (sides 7.9 m, 0.02 m inside the circle), whose corners step the velocity by 0.26 m/s
twice a slot. An earlier loop, a 24-gon of radius 900 m, stepped it by 3.9 m/s at each corner,
an acceleration beyond any bound, and most of its infeasible slots came right after a corner
(docs/performance.md, "The soak: safety over 3600 slots"). The scenario's own CV target
(`target="cv"`) reflects off the area's walls, but its velocity is a random walk (kappa = 0.5
m^2/s^3: an rms speed of about 67 m/s after 3600 s), so its later quarters are a harder problem
and their planning time says nothing about leaks.

Optionally (`trace_malloc=True`) tracemalloc starts at the end of the first quarter and the
allocations still alive at the end are listed by line, largest growth first.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import re
import resource
import socket
import statistics
import time
import tracemalloc
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import Scenario
from isac_mission.config.targets import Leg
from isac_mission.errors import MessageError
from isac_mission.planning.registry import live_default_method
from isac_mission.planning.slot import Method
from isac_mission.records.tracks import TracksSlot
from isac_mission.service.assembly import LiveOptions, run_serve
from isac_mission.service.ground.report import SlotEvent
from isac_mission.service.mission_result import LiveResult
from isac_mission.types import FloatArray
from isac_mission.wire import Keys, TelemetryMsg, TruthMsg, TruthSetMsg, decode
from sim.world import run_world
from sim.world_options import WorldOptions
from tests.support.ports import free_port_block, sitl_ports
from tests.support.soak_safety import ProximityCounter, ProximityCounts

TargetKind = Literal["loop", "cv", "racetrack"]

LOOP_CENTRE_XY_M = (1500.0, 1600.0)
LOOP_RADIUS_M = 450.0
LOOP_SPEED_MPS = 15.0
LOOP_SIDES = 360
"""The polygon that flies the circle (module docstring)."""


def loop_corners(radius_m: float = LOOP_RADIUS_M) -> tuple[tuple[float, float], ...]:
    """The scripted target's loop: a LOOP_SIDES-gon of circumradius `radius_m` around
    LOOP_CENTRE_XY_M, clockwise from its west point (for the default radius (1050, 1600) m),
    heading north."""
    cx, cy = LOOP_CENTRE_XY_M
    return tuple(
        (
            cx + radius_m * math.cos(math.pi - 2 * math.pi * k / LOOP_SIDES),
            cy + radius_m * math.sin(math.pi - 2 * math.pi * k / LOOP_SIDES),
        )
        for k in range(LOOP_SIDES)
    )


RACETRACK_START_XY_M = (1300.0, 1400.0)
RACETRACK_SPEED_MPS = (10.0, 20.0, 30.0)
"""The racetrack's slowest, turning and fastest speeds (m/s)."""
RACETRACK_ALONG_MPS2 = 2.0
"""Its speed changes' along-track acceleration (m/s^2)."""


def racetrack_legs(laps: int, max_accel_mps2: float) -> tuple[Leg, ...]:
    """`laps` closed laps of a racetrack flown from RACETRACK_START_XY_M heading east at the
    turning speed v_t: on each straight v_t -> v_max -> v_min -> v_t at +-RACETRACK_ALONG_MPS2
    (400 m at the defaults), then a half circle to the left at v_t and the manoeuvre bound,
    omega = a_T / v_t (0.2 rad/s, radius 100 m at 4 m/s^2). Each lap ends where and as it began."""
    v_min, v_turn, v_max = RACETRACK_SPEED_MPS
    a = RACETRACK_ALONG_MPS2
    omega = max_accel_mps2 / v_turn
    straight = (
        Leg("accelerate", (v_max - v_turn) / a, accel_mps2=a),
        Leg("accelerate", (v_max - v_min) / a, accel_mps2=-a),
        Leg("accelerate", (v_turn - v_min) / a, accel_mps2=a),
    )
    half_circle = Leg("turn", math.pi / omega, turn_rate_radps=omega)
    return (*straight, half_circle, *straight, half_circle) * laps


def racetrack_lap_s(max_accel_mps2: float) -> float:
    """One racetrack lap's duration (s) at the manoeuvre bound max_accel_mps2 (m/s^2)."""
    return sum(leg.duration_s for leg in racetrack_legs(1, max_accel_mps2))


def loop_radius_for_lap(lap_s: float) -> float:
    """The circumradius whose loop takes `lap_s` seconds at LOOP_SPEED_MPS."""
    return LOOP_SPEED_MPS * lap_s / (2 * LOOP_SIDES * math.sin(math.pi / LOOP_SIDES))


@dataclass(frozen=True)
class SoakSample:
    """Taken right after slot `slot` was processed: wall (time.monotonic) and process CPU
    (time.process_time) seconds, resident set size in bytes, the slot's planning time (ms), the
    nearest UAV's distance to the nearest true target at the slot's measurements (m; NaN without
    truth)
    and the largest entry of the slot's PCRB information J."""

    slot: int
    wall_s: float
    cpu_s: float
    rss_bytes: int
    solve_ms: float
    target_distance_m: float = math.nan
    j_max: float = math.nan


@dataclass
class SoakResult:
    """Per-slot samples of one soak run, the live result and the setup time (wall s until the
    first slot). `heap_growth` lists (site, bytes, blocks) of tracemalloc's comparison between
    the end of the first quarter and the end, when asked for."""

    samples: list[SoakSample]
    live: LiveResult
    setup_s: float
    heap_growth: list[tuple[str, int, int]] = field(default_factory=list)
    proximity: ProximityCounts = field(default_factory=ProximityCounts)
    """Telemetry samples closer than D_s to the true target or another UAV (soak_safety.py)."""

    @property
    def infeasible_slots(self) -> int:
        """Slots whose plan came back infeasible (status "infeasible")."""
        return self.live.report.counters.get("slots infeasible", 0)


def rss_bytes() -> int:
    """This process's resident set size now (VmRSS of /proc/self/status), bytes; where /proc is
    missing, the peak (ru_maxrss)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            m = re.search(r"^VmRSS:\s+(\d+)\s+kB", f.read(), re.MULTILINE)
        if m is not None:
            return int(m.group(1)) * 1024
    except OSError:
        pass
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def soak_scenario(
    base: Scenario, slots: int, target: TargetKind = "loop", loop_radius_m: float = LOOP_RADIUS_M
) -> Scenario:
    """`base` for `slots` slots; for the loop target, the tracker's prior is the loop's start
    (west point, heading north) so that the first slots do not start from a wrong cue; for the
    racetrack, base's first target flies `racetrack_legs` at base's manoeuvre bound a_T to the
    end (a known target, as the loop's), the only target."""
    s = base.with_changes(N=slots)
    if target == "racetrack":
        laps = math.ceil(slots * s.dt / racetrack_lap_s(s.a_target)) + 1
        x0 = (*RACETRACK_START_XY_M, RACETRACK_SPEED_MPS[1], 0.0)
        spec = replace(
            s.targets[0],
            x0=x0,
            motion="legs",
            legs=racetrack_legs(laps, s.a_target),
            first_slot=0,
            last_slot=slots,
            prior_known=True,
        )
        return s.with_changes(targets=(spec,), x0=np.array(x0))
    if target == "loop":
        corners = loop_corners(loop_radius_m)
        first, second = np.array(corners[0]), np.array(corners[1])
        heading = (second - first) / np.linalg.norm(second - first)
        x0 = np.array([*first, *(LOOP_SPEED_MPS * heading)])
        s = s.with_changes(x0=x0)
    return s


def loop_waypoints(
    slots: int, dt_s: float, radius_m: float = LOOP_RADIUS_M
) -> tuple[tuple[float, float], ...]:
    """Enough laps of the loop to cover `slots` slots at LOOP_SPEED_MPS (plus one)."""
    c = np.array(loop_corners(radius_m))
    lap_m = float(np.sum(np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1)))
    laps = math.ceil(slots * dt_s * LOOP_SPEED_MPS / lap_m) + 1
    corners = [(float(x), float(y)) for x, y in c]
    return tuple(corners * laps + corners[:1])


async def run_soak(
    s: Scenario,
    out_dir: Path,
    *,
    speed: float = 20.0,
    lockstep: bool = True,
    target: TargetKind = "loop",
    loop_radius_m: float = LOOP_RADIUS_M,
    seed: int = 1,
    method: Method | None = None,
    trace_malloc: bool = False,
    on_sample: Callable[[SoakSample], None] | None = None,
    path: tuple[tuple[tuple[float, float], ...], float] | None = None,
) -> SoakResult:
    """Fly `s` (use `soak_scenario`) live for s.N slots with `method` (None: what `run` flies
    by default, `live_default_method`) and sample every slot
    (module docstring); an observer session counts the telemetry samples closer than D_s to
    the true target or another UAV (soak_safety.py).

    Free loopback ports for Zenoh and MAVLink; `lockstep_timeout` of the world 60 wall s.
    Give `soak_scenario` and `run_soak` the same `loop_radius_m`. path: (waypoints [P, 2] m,
    speed m/s), a scripted target path instead of `target` (its start is s.x0's).
    """
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    # The observer listens too, and the world connects to it: Zenoh peers do not forward each
    # other's samples, so the world's truth must reach the observer directly.
    observer_endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    ports = sitl_ports(s.M)
    opts = LiveOptions(
        speed=speed,
        lockstep=lockstep,
        method=method or live_default_method(multi_target=s.multi_target),
        seed=seed,
        out_dir=out_dir,
        zenoh_endpoint=endpoint,
        **ports.world_kwargs(),
    )
    world_opts = WorldOptions(
        speed=speed,
        lockstep=lockstep,
        lockstep_timeout_s=60.0,
        seed=seed,
        bus=BusSettings(connect=(endpoint, observer_endpoint)),
        **ports.world_kwargs(),
        start="offboard",
        target_waypoints_xy_m=path[0]
        if path is not None
        else loop_waypoints(s.N, s.dt, loop_radius_m)
        if target == "loop"
        else None,
        target_speed_mps=path[1]
        if path is not None
        else LOOP_SPEED_MPS
        if target == "loop"
        else None,
    )
    samples: list[SoakSample] = []
    quarter = max(1, s.N // 4)
    heap: dict[str, tracemalloc.Snapshot] = {}
    t_start = time.monotonic()

    def take(
        slot: int, solve_ms: float, uav_xy_m: FloatArray, truth: FloatArray, j_max: float
    ) -> None:
        """Sample slot `slot` (truth [T, 4], NaN rows: not in the scene)."""
        present = truth[np.all(np.isfinite(truth), axis=1), :2]
        gaps = np.linalg.norm(uav_xy_m[:, None, :] - present[None, :, :], axis=2)
        distance = float(np.min(gaps)) if gaps.size else math.nan
        sample = SoakSample(
            slot, time.monotonic(), time.process_time(), rss_bytes(), solve_ms, distance, j_max
        )
        samples.append(sample)
        if trace_malloc and slot == quarter:
            tracemalloc.start(1)
        if trace_malloc and slot == s.N and tracemalloc.is_tracing():
            heap["end"] = tracemalloc.take_snapshot()
            tracemalloc.stop()
        if on_sample is not None:
            on_sample(sample)

    def on_slot(ev: SlotEvent) -> None:
        rec = ev.record
        truth = np.full((1, 4), np.nan) if rec.target_true is None else rec.target_true[None]
        xy = np.asarray(rec.uav_xy_m, dtype=float)
        take(rec.slot, rec.solve_ms, xy, truth, float(np.max(np.abs(rec.J))))

    def on_tracks(slot: TracksSlot, _latency_s: float) -> None:
        solve_ms = 1e3 * slot.plan.report.solve_s
        take(slot.slot, solve_ms, np.asarray(slot.uav_xy_m), np.asarray(slot.truth), math.nan)

    counter = ProximityCounter(s.d_safe, s.N)
    observer_up = asyncio.Event()
    observer = asyncio.create_task(
        _observe(s, BusSettings.hub(observer_endpoint), endpoint, counter, observer_up)
    )
    await observer_up.wait()
    world_stop = asyncio.Event()
    world = asyncio.create_task(run_world(s, world_opts, world_stop))
    try:
        live = await run_serve(s, opts, asyncio.Event(), on_slot, on_tracks=on_tracks)
    finally:
        world_stop.set()
        await asyncio.wait_for(world, timeout=60.0)
        observer.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await observer
        if tracemalloc.is_tracing():
            tracemalloc.stop()
    growth: list[tuple[str, int, int]] = []
    if "end" in heap:
        stats = heap["end"].statistics("lineno")
        for st in stats[:25]:
            frame = st.traceback[0]
            growth.append((f"{frame.filename}:{frame.lineno}", st.size, st.count))
    setup_s = samples[0].wall_s - t_start if samples else math.nan
    return SoakResult(samples, live, setup_s, growth, counter.counts)


async def _observe(
    s: Scenario,
    hub: BusSettings,
    ground_endpoint: str,
    counter: ProximityCounter,
    up: asyncio.Event,
) -> None:
    """Feed `counter` the telemetry (from the ground's bridges) and the truth (from the world) of
    the mission, until cancelled; `up` is set once the subscription is declared."""
    keys = Keys(s.mission_id)
    telemetry, truth = f"{keys.prefix}/telemetry/", keys.truth
    truth_type = TruthSetMsg if s.multi_target else TruthMsg
    settings = hub.model_copy(update={"connect": (ground_endpoint,)})
    with ZenohBus.open(settings) as bus:
        async with bus.subscribe(keys.everything, maxsize=65536) as sub:
            up.set()
            async for key, payload in sub:
                try:
                    if key.startswith(telemetry):
                        counter.on_telemetry(decode(TelemetryMsg, payload, n_uavs=s.M))
                    elif key == truth:
                        counter.on_truth(decode(truth_type, payload))
                except MessageError:
                    continue


@dataclass(frozen=True)
class QuarterRow:
    """Medians of one quarter: wall and CPU seconds per slot, planning ms; RSS at its end."""

    quarter: int
    slots: tuple[int, int]
    wall_ms: float
    cpu_ms: float
    solve_ms: float
    rss_mib: float


@dataclass(frozen=True)
class QuarterTable:
    """Per-quarter rows and the last-over-first ratios (RSS: end of Q4 over end of Q1)."""

    rows: list[QuarterRow]
    wall_ratio: float
    cpu_ratio: float
    solve_ratio: float
    rss_ratio: float

    def render(self) -> str:
        """A plain-text table."""
        head = (
            f"{'quarter':<8} {'slots':>11} {'wall ms/slot':>13} {'CPU ms/slot':>12} "
            f"{'solve ms':>9} {'RSS MiB at end':>15}"
        )
        lines = [head]
        for r in self.rows:
            lines.append(
                f"Q{r.quarter:<7} {r.slots[0]:>5}-{r.slots[1]:<5} {r.wall_ms:>13.1f} "
                f"{r.cpu_ms:>12.1f} {r.solve_ms:>9.1f} {r.rss_mib:>15.1f}"
            )
        lines.append(
            f"{'Q4/Q1':<8} {'':>11} {self.wall_ratio:>13.3f} {self.cpu_ratio:>12.3f} "
            f"{self.solve_ratio:>9.3f} {self.rss_ratio:>15.3f}"
        )
        return "\n".join(lines)


def quarter_table(samples: Sequence[SoakSample], warmup: int = 0) -> QuarterTable:
    """Split the per-slot samples after the first `warmup` into four quarters by slot order:
    per-slot wall and CPU time are differences between consecutive samples (the first slot has
    none), medians per quarter; RSS is the value at the quarter's last slot (so warm-up within
    Q1 does not count)."""
    n = len(samples)
    if n - warmup < 8 or warmup < 0:
        raise ValueError(f"need at least 8 slots after {warmup} of warm-up, got {n}")
    bounds = [warmup + round((n - warmup) * q / 4) for q in range(5)]
    rows: list[QuarterRow] = []
    for q in range(4):
        part = list(samples[bounds[q] : bounds[q + 1]])
        prev = samples[bounds[q] - 1] if bounds[q] > 0 else None
        pairs = list(zip([prev, *part[:-1]], part, strict=True))
        wall = [1e3 * (b.wall_s - a.wall_s) for a, b in pairs if a is not None]
        cpu = [1e3 * (b.cpu_s - a.cpu_s) for a, b in pairs if a is not None]
        rows.append(
            QuarterRow(
                quarter=q + 1,
                slots=(part[0].slot, part[-1].slot),
                wall_ms=statistics.median(wall),
                cpu_ms=statistics.median(cpu),
                solve_ms=statistics.median(p.solve_ms for p in part),
                rss_mib=part[-1].rss_bytes / 2**20,
            )
        )
    first, last = rows[0], rows[-1]
    return QuarterTable(
        rows=rows,
        wall_ratio=last.wall_ms / first.wall_ms,
        cpu_ratio=last.cpu_ms / first.cpu_ms,
        solve_ratio=last.solve_ms / first.solve_ms,
        rss_ratio=last.rss_mib / first.rss_mib,
    )


def pursuit_path(
    x0: FloatArray, aims_xy_m: FloatArray, a_target_mps2: float, dt_s: float, steps: int = 20
) -> FloatArray:
    """[len(aims), 2]: the positions at the slot instants of a target starting at x0 [4] at
    constant speed, turning toward aims_xy_m[n] [N + 1, 2] during slot n at up to a_target_mps2
    (integrated in `steps` steps a slot): a manoeuvre at the bound."""
    p, v = np.array(x0[:2], dtype=float), np.array(x0[2:4], dtype=float)
    speed = float(np.linalg.norm(v))
    out = [p.copy()]
    h = dt_s / steps
    for aim in aims_xy_m[1:]:
        for _ in range(steps):
            heading = math.atan2(v[1], v[0])
            want = math.atan2(aim[1] - p[1], aim[0] - p[0])
            turn = (want - heading + math.pi) % (2 * math.pi) - math.pi
            heading += float(np.clip(turn, -a_target_mps2 / speed * h, a_target_mps2 / speed * h))
            v_next = speed * np.array([math.cos(heading), math.sin(heading)])
            p = p + 0.5 * (v + v_next) * h
            v = v_next
        out.append(p.copy())
    return np.asarray(out)
