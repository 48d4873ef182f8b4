"""One offline run of one method, for any number of targets: flown by the one loop
(`closed_loop.fly_offline`) on the scenario's scene and tracker (`tracking/factory.py`), measured,
and traced.

What a run carries comes from what it flew, not from asking how many targets the scenario has:
every run has its tracks' figures (`track_metrics`: GOSPA, each target's error against its
track's bound); a run whose one track is labelled (a single track in every slot, updated with
its own measurement variances: `TrackEstimate.variances`) also has that track's per-slot arrays
(`closed_loop.RunResult`), and its trace is the slot records of docs/trace.md. A run whose
tracks are found and followed from unlabelled reports is traced as docs/trace.md, "Lines of a
tracker of several tracks", describes (records/tracks.py). Each track of a line carries the
operator's priority the slot's plan was made with (the scenario's scripted `priorities:`, the
same table `closed_loop.fly_offline` plans with: `tracking/priorities.scripted_priorities`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from isac_mission.config import Scenario
from isac_mission.experiment.closed_loop import RunResult, SlotOutcome, fly_offline
from isac_mission.experiment.track_metrics import RunFigures, track_figures
from isac_mission.nlp_cache import CompiledNlpCache
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method
from isac_mission.records import SlotRecord, TraceWriter
from isac_mission.records import tracks as tracks_trace
from isac_mission.tracking.factory import draw_noise, keep_out_tracks, scene_for, tracker_for
from isac_mission.tracking.priorities import Priorities, PriorityChange, scripted_priorities
from isac_mission.types import FloatArray


@dataclass(frozen=True)
class MissionRun:
    """One run of one method: solve_s [N] the plan times (s) of slots 1..N; tracking: its tracks'
    figures (any number of targets); labelled: the labelled track's per-slot arrays when the run
    had one (None: its tracks were found from unlabelled reports)."""

    method: str
    seed: int
    solve_s: FloatArray
    tracking: RunFigures
    labelled: RunResult | None


def labelled_arrays(run: MissionRun | RunResult) -> RunResult:
    """The labelled track's arrays of a run (a RunResult is one already); ValueError for a run
    that had no labelled track."""
    if isinstance(run, RunResult):
        return run
    if run.labelled is None:
        raise ValueError(f"run {run.seed} of {run.method} has no labelled track")
    return run.labelled


def has_labelled_track(outcomes: Sequence[SlotOutcome]) -> bool:
    """Whether every slot had one track, updated with its own measurement variances (the
    labelled tracker's) and planned for (or held because its priority was 0)."""
    return all(
        len(o.tracking.tracks) == 1
        and o.tracking.tracks[0].variances is not None
        and (o.slot_input is not None or o.planned_for == 0)
        for o in outcomes
    )


def labelled_result(method: str, seed: int, outcomes: Sequence[SlotOutcome]) -> RunResult:
    """The per-slot arrays of a run's labelled track (as `closed_loop.run_closed_loop` gives)."""
    return RunResult.of_outcomes(method, seed, outcomes)


def outcome_record(o: SlotOutcome, priorities: Priorities | None = None) -> SlotRecord:
    """The trace line of one slot of the labelled target (docs/trace.md); priorities: those
    the slot's plan was made with (None: every track 1). A slot the fleet held (the target at
    priority 0) has no planner input: no plan_start_xy."""
    rep = o.plan.report
    inp = o.slot_input
    return SlotRecord(
        slot=o.slot,
        method=o.method,
        status=rep.status,
        uav_xy_m=o.uav_xy,
        bandwidth_share=o.plan.bandwidth_share,
        assoc=o.plan.bs_of_uav,
        target_true=o.target_true,
        target_est=o.target_est,
        target_pred=o.target_pred,
        r_diag=o.r_diag,
        pcrb_trace=o.bound.trace,
        solve_ms=rep.solve_s * 1e3,
        P=o.P,
        J=o.bound.J,
        plan_xy=o.plan.uav_xy_m,
        plan_pcrb_trace=o.plan.pcrb_trace,
        plan_velocity=o.plan.uav_velocity_mps,
        reason=rep.reason,
        fallback=rep.fallback or None,
        plan_start_xy=None if inp is None else inp.prev_xy_m,
        plan_start_velocity=None if inp is None else inp.prev_velocity_mps,
        extra={
            "pcrb_pos": o.bound.position_trace,
            "pcrb_vel": o.bound.velocity_trace,
            "ao_iterations": rep.ao_iterations,
            "position_iterations": rep.position_iterations,
            "bandwidth_iterations": rep.bandwidth_iterations,
        }
        | tracks_trace.tracks_fields(
            o.planned_for, o.truth, o.tracking.tracks, o.reports, priorities
        ),
    )


def tracks_slot(o: SlotOutcome, priorities: Priorities | None = None) -> tracks_trace.TracksSlot:
    """A slot as the tracks trace records it (records/tracks.py); priorities: those the slot's
    plan was made with (None: every track 1)."""
    inp = o.slot_input
    return tracks_trace.TracksSlot(
        o.slot,
        o.method,
        o.plan,
        o.uav_xy,
        o.eta,
        o.truth,
        o.reports,
        o.tracking.tracks,
        o.planned_for,
        start_xy=None if inp is None else inp.prev_xy_m,
        start_velocity=None if inp is None else inp.prev_velocity_mps,
        priorities=priorities,
    )


def trace_path(trace_dir: Path, method: str, run: int) -> Path:
    """Where run `run` of `method` is traced."""
    return trace_dir / f"{method}_run{run:03d}.jsonl"


def write_trace(
    path: Path,
    config: dict[str, Any],
    outcomes: Sequence[SlotOutcome],
    priority_changes: Sequence[PriorityChange] = (),
) -> None:
    """The run's trace: the labelled track's slot records, or the lines of tracks (module
    doc); priority_changes: the scenario's scripted priorities the run was flown with."""
    labelled = has_labelled_track(outcomes)
    with TraceWriter(path, config) as writer:
        for o in outcomes:
            table = scripted_priorities(priority_changes, o.slot)
            writer.write_slot(outcome_record(o, table) if labelled else tracks_slot(o, table))


def scenario_kit(s: Scenario) -> SolverKit:
    """A new SolverKit of the scenario (building one compiles the cvxpy problems), with the
    keep-out points its tracker needs (`factory.keep_out_tracks`); its IPOPT problems compiled
    where the cache has them (isac_mission/nlp_cache.py: the same numbers, faster;
    `isac-mission compile CONFIG --scenario-settings` fills it)."""
    return SolverKit(s, n_keep_out=keep_out_tracks(s), ipopt=CompiledNlpCache(compile="never"))


_KITS: dict[int, SolverKit] = {}


def kit_for(s: Scenario) -> SolverKit:
    """One `scenario_kit` per scenario per process (the last scenario's kept)."""
    key = id(s)
    if key not in _KITS:
        _KITS.clear()
        _KITS[key] = scenario_kit(s)
    return _KITS[key]


def fly_outcomes(s: Scenario, method: Method, seed: int, kit: SolverKit) -> tuple[SlotOutcome, ...]:
    """One mission of `method` (`closed_loop.fly_offline`) in the scenario's scene drawn from
    noise seed `seed` (`factory.draw_noise`, `scene_for`), tracked by a new tracker of the
    scenario (`factory.tracker_for`); `kit` as `scenario_kit` builds it."""
    scene = scene_for(s, draw_noise(s, seed))
    return fly_offline(s, method, scene, tracker_for(s), kit)


def mission_run(s: Scenario, method: str, seed: int, outcomes: Sequence[SlotOutcome]) -> MissionRun:
    """What a run flown with noise seed `seed` measured (`MissionRun`): its tracks' figures
    (the scenario's GOSPA cut-off), and its labelled track's arrays when it had one
    (`has_labelled_track`)."""
    return MissionRun(
        method=method,
        seed=seed,
        solve_s=np.array([o.plan.report.solve_s for o in outcomes], dtype=float),
        tracking=track_figures([tracks_slot(o) for o in outcomes], s.multi_tracker.gospa_cutoff_m),
        labelled=labelled_result(method, seed, outcomes) if has_labelled_track(outcomes) else None,
    )


def fly_run(s: Scenario, method: Method, run: int, seed: int, trace_dir: Path | None) -> MissionRun:
    """Run `run` of `method` (noise seed = seed + run), traced under trace_dir when given."""
    outcomes = fly_outcomes(s, method, seed + run, kit_for(s))
    if trace_dir is not None:
        config = s.trace_config() | {"seed": seed + run, "method": method}
        write_trace(trace_path(trace_dir, method, run), config, outcomes, s.priority_changes)
    return mission_run(s, method, seed + run, outcomes)
