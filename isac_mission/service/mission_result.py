"""What a live mission produced (`LiveResult`) and its end-of-run figures (`summarize_live`):
the ground loop's report, the bridges' counters and wall timestamps, gathered when the mission
ends (`record_fleet`), and the fleet's MAVLink signing rejections kept in the ground loop's health
counters while it flies (`mirror_signing_counters`)."""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from isac_mission.mavwire.signing import SIGNATURE_REJECTIONS
from isac_mission.records.tracks import TracksSlot
from isac_mission.service.bridge.fleet import BridgeFleet
from isac_mission.service.ground.report import GroundReport

SIGNING_MIRROR_PERIOD_S = 0.2
"""Wall seconds between two refreshes of the signing counters in the ground loop's report."""


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
    multi_target_slots: list[TracksSlot] = field(default_factory=list)
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


def signing_counters(fleet: BridgeFleet) -> dict[str, int]:
    """The bridges' MAVLink signing rejections, summed over the fleet, as health counters:
    `mavlink unsigned`, `mavlink bad_signature`, `mavlink replayed` (0 with signing off)."""
    return {
        f"mavlink {reason}": sum(b.link.errors[reason] for b in fleet.bridges)
        for reason in SIGNATURE_REJECTIONS
    }


async def mirror_signing_counters(fleet: BridgeFleet, report: GroundReport) -> None:
    """Keep `signing_counters` in the ground loop's counters (published in every `health`),
    refreshed every SIGNING_MIRROR_PERIOD_S wall seconds until cancelled."""
    while True:
        for name, n in signing_counters(fleet).items():
            report.counters[name] = n
        await asyncio.sleep(SIGNING_MIRROR_PERIOD_S)


def record_fleet(result: LiveResult, fleet: BridgeFleet) -> None:
    """Put the fleet's end-of-mission figures in `result`: its counters (plans, vehicles landed
    or never heard, link losses and interruptions, offboard re-entries) and, from the bridges'
    wall timestamps, the detection-to-setpoint latencies (s) and the setpoint periods (s)."""
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
    c = fleet.counters
    result.fleet_counters = {
        "plans applied": c.plans_applied,
        "plans invalid": c.plans_invalid,
        "vehicles landed": sum(b.phase == "landed" for b in fleet.bridges),
        "vehicles never heard": sum(b.link.status().heartbeat_s is None for b in fleet.bridges),
        "link losses": sum(b.counters.link_losses for b in fleet.bridges),
        "link interruptions": sum(b.counters.link_interruptions for b in fleet.bridges),
        "offboard re-entries": sum(b.counters.offboard_reentries for b in fleet.bridges),
    }


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
