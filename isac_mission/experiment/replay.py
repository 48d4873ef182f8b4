"""Replay a trace's slot inputs through the offline planner: does the service plan what its
offline twin would?

A trace records, slot by slot, what the planner was given (`plan_start_xy`,
`plan_start_velocity`, the prediction through `target_pred` and the previous slot's `P`, `J`,
shares and association) and what it returned (`plan_xy`, `plan_velocity`, `fallback`). For every
slot n with a plan this module rebuilds the planner's input and answers three questions:

1. *The inputs.* Where did the planner start from, against where the offline loop
   (experiment/closed_loop.py) starts: the previous plan's waypoint and end velocity
   (`start_gap_m`, `start_velocity_gap_mps`; at slot 1 the scenario's start points at rest)?
   Is the prediction the one the previous slot's belief gives (`prediction_gap`; slot 1's
   initial estimate is not traced, so slot 1's prediction is taken as recorded)?
2. *The planner.* Does the same planner on the same input make the same plan (`replay_gap_m`,
   the replayed waypoints against the recorded ones)? A live plan that differs was made on other
   settings, another kit or another previous plan.
3. *What the gap costs.* The plan made from the offline start instead (`offline_step_m`,
   against the recorded `planned_step_m`, both from the previous plan's waypoint).

The replay plans as the live ground loop does (planning/fleet.py, PlanningJob: the vehicles a plan left
out, `planned_around`, held and kept out; the operator's priorities each track's `priority` in the
line records, `line_priorities`), chaining its own replayed plans as each slot's previous plan.
Pure computation on a trace and a scenario (no I/O: `read_trace` is the caller's).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from isac_mission.config import Scenario
from isac_mission.planning.fleet import KitCache, PlanningJob, active_part
from isac_mission.planning.registry import METHODS
from isac_mission.planning.slot import Method, SolverKit
from isac_mission.records import SlotRecord, Trace
from isac_mission.records.tracks import TracksLine, resume_point
from isac_mission.tracking.cycle import CycleModel, TrackState, predict
from isac_mission.tracking.factory import keep_out_tracks, restored_tracker
from isac_mission.tracking.pcrb import Bound
from isac_mission.tracking.priorities import Priorities, scripted_priorities
from isac_mission.tracking.tracker import LABELLED_TRACK_ID, TrackPrediction
from isac_mission.types import FloatArray, Gaussian, SlotPlan

PLANNING_KEYS_REPLACED = {"v_max": "plan_v_max", "r_th": "plan_r_th", "d_safe": "plan_d_safe"}
"""A live trace states the vehicles' real limits under these names and what the planner planned
with under the plan_* ones (cli/mission.py)."""

IGNORED_KEYS = frozenset(("seed", "method", "mission_id", *PLANNING_KEYS_REPLACED.values()))
"""Trace config keys that do not change what the planner does."""


@dataclass(frozen=True)
class ReplayedSlot:
    """One slot of a replay (m, m/s; arrays [M] over the vehicles).

    start_gap_m, start_velocity_gap_mps: the recorded start against the offline loop's;
    prediction_gap: max |target_pred - F x_est| over the 4 components (m, m/s); replay_gap_m:
    replayed against recorded waypoints; planned_step_m: recorded waypoint from the previous
    one; offline_step_m: the same for the plan made from the offline start; fallback,
    replay_fallback: the recorded and the replayed plan's (SolveReport.fallback, "" = none).
    """

    slot: int
    status: str
    start_gap_m: FloatArray
    start_velocity_gap_mps: FloatArray
    prediction_gap: float
    replay_gap_m: FloatArray
    planned_step_m: FloatArray
    offline_step_m: FloatArray
    fallback: str
    replay_fallback: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (arrays as lists)."""
        return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in self.__dict__.items()}


def config_differences(trace_config: dict[str, Any], s: Scenario) -> list[str]:
    """The planner-relevant trace config entries `s` does not reproduce ("key: trace x, here y").
    A live trace's plan_* entries are compared with s's v_max, r_th and d_safe."""
    want = {k: v for k, v in trace_config.items() if k not in IGNORED_KEYS}
    for key, planned in PLANNING_KEYS_REPLACED.items():
        if planned in trace_config:
            want[key] = trace_config[planned]
    return _differences(want, s.trace_config(), "")


def _differences(want: dict[str, Any], mine: dict[str, Any], prefix: str) -> list[str]:
    """Entries of `want` that `mine` has with another value, nested keys dotted."""
    out: list[str] = []
    for key, value in want.items():
        if key not in mine:
            continue
        here = mine[key]
        if isinstance(value, dict) and isinstance(here, dict):
            out += _differences(value, here, f"{prefix}{key}.")
        elif not _same(value, here):
            out.append(f"{prefix}{key}: trace {value!r}, here {here!r}")
    return out


def _same(a: Any, b: Any) -> bool:
    """Equal as the trace holds them: numbers as np.isclose (1e-9 relative), lists (tuples) and mappings
    entry by entry."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    numbers = (int, float)
    if isinstance(a, numbers) and isinstance(b, numbers) and not isinstance(a, bool):
        return bool(np.isclose(float(a), float(b), rtol=1e-9))
    return bool(a == b)


def _method(trace: Trace) -> Method:
    for m in METHODS:
        if m == trace.method:
            return m
    raise ValueError(f"the trace's method {trace.method!r} is not one of {', '.join(METHODS)}")


def replay_trace(
    trace: Trace, s: Scenario, slots: Sequence[int] | None = None, kit: SolverKit | None = None
) -> list[ReplayedSlot]:
    """Replay `trace` (its method) on the planning scenario `s`, slot by slot (all slots with a
    recorded start, or those listed in `slots`), for any number of targets: the labelled
    target's prediction from the previous line's estimate and bound, a tracker of several
    tracks restored from the previous line's `tracker` (docs/trace.md; a trace without it, an
    offline one, has no slot to replay). ValueError when `s` is not the scenario the trace was
    planned with (config_differences) or the trace records no planner inputs."""
    diff = config_differences(trace.config, s)
    if diff:
        raise ValueError(
            "the scenario is not the one the trace was planned with: " + "; ".join(diff)
        )
    method = _method(trace)
    keep_out = keep_out_tracks(s)
    kits = KitCache(kit if kit is not None else SolverKit(s, n_keep_out=keep_out), method, keep_out)
    model = CycleModel.from_scenario(s)
    wanted = None if slots is None else set(slots)
    records = {r.slot: r for r in trace.slots}
    lines = {line.slot: line for line in trace.lines}
    out: list[ReplayedSlot] = []
    replayed: dict[int, tuple[tuple[int, ...], SlotPlan]] = {}
    for line in trace.lines:
        raw = _fields(line, records)
        if raw.get("plan_start_xy") is None or raw.get("plan_xy") is None:
            continue
        prev = lines.get(line.slot - 1)
        if line.slot > 1 and prev is None:
            continue  # the trace starts later (a resume): no previous belief to start from
        predictions = _predictions(line, prev, records, s, model)
        if predictions is None:
            continue
        priorities = line_priorities(line, prev, s)
        job = _live_job(line, prev, records, s, kits, method, predictions, replayed, priorities)
        plan = job.run()
        replayed[line.slot] = (job.active, plan)
        if wanted is not None and line.slot not in wanted:
            continue
        start_xy, start_v = _offline_start(prev, records, s)
        offline = replace(job, uav_xy=start_xy, uav_v=start_v).run()
        rec = records.get(line.slot)
        gap = float("nan")  # a line of tracks records no prediction
        if rec is not None:
            predicted = job.predictions[0].prediction.x
            gap = float(np.max(np.abs(np.asarray(rec.target_pred) - predicted)))
        plan_xy = _array(raw, "plan_xy")
        start_v_live = _array(raw, "plan_start_velocity", np.zeros((s.M, 2)))
        out.append(
            ReplayedSlot(
                slot=line.slot,
                status=line.status,
                start_gap_m=_norms(_array(raw, "plan_start_xy") - start_xy),
                start_velocity_gap_mps=_norms(start_v_live - start_v),
                prediction_gap=gap,
                replay_gap_m=_norms(plan.uav_xy_m - plan_xy),
                planned_step_m=_norms(plan_xy - start_xy),
                offline_step_m=_norms(offline.uav_xy_m - start_xy),
                fallback=line.fallback,
                replay_fallback=plan.report.fallback,
            )
        )
    return out


def line_priorities(line: TracksLine, prev: TracksLine | None, s: Scenario) -> Priorities:
    """The operator's priorities slot line.slot was planned with: each track's `priority` in the
    line (what the slot's plan was made with), for a track the line no longer has (deleted by
    the slot's update) the previous line's, and for any other the scenario's script at the
    slot (`scripted_priorities`; 1 without one)."""
    table = scripted_priorities(s.priority_changes, line.slot)
    for source in (prev, line):
        if source is not None:
            for t in source.tracks:
                table = table.with_priority(t.track_id, t.priority)
    return table


def _fields(line: TracksLine, records: dict[int, SlotRecord]) -> dict[str, Any]:
    """A slot line's fields: its SlotRecord's for the labelled target, else the line as read."""
    rec = records.get(line.slot)
    return line.line if rec is None else rec.to_dict()


def _array(raw: dict[str, Any], key: str, default: FloatArray | None = None) -> FloatArray:
    """A line's array field (null entries NaN); `default` when absent or null."""
    value = raw.get(key)
    if value is None:
        if default is None:
            raise ValueError(f"the line has no {key}")
        return default
    return np.array([[np.nan if v is None else v for v in row] for row in value], dtype=float)


def _norms(d: FloatArray) -> FloatArray:
    return np.asarray(np.linalg.norm(np.asarray(d, dtype=float), axis=-1))


def _predictions(
    line: TracksLine,
    prev: TracksLine | None,
    records: dict[int, SlotRecord],
    s: Scenario,
    model: CycleModel,
) -> tuple[TrackPrediction, ...] | None:
    """The tracks slot line.slot was planned for, as the ground loop predicted them: the
    labelled target's from the previous line's estimate and bound (slot 1: the initial estimate
    whose prediction is the recorded one); a tracker of several tracks restored from the
    previous line (None: the line does not carry the tracker, or slot 1, whose initial
    estimates are not traced)."""
    rec = records.get(line.slot)
    if rec is not None:
        before = None if prev is None else records.get(prev.slot)
        if before is None:
            # The initial estimate is not traced (offline it is x0 plus the run's drawn error):
            # the one whose prediction is slot 1's target_pred, with the scenario's P0.
            x_init = np.linalg.solve(model.F, np.asarray(rec.target_pred, dtype=float))
            belief, bound = Gaussian(x_init, s.P0.copy()), Bound.from_covariance(s.P0.copy())
        else:
            belief = Gaussian(np.asarray(before.target_est), np.asarray(before.P))
            bound = Bound.from_information(np.asarray(before.J))
        predicted = predict(model, TrackState(belief, bound))
        return (TrackPrediction(LABELLED_TRACK_ID, True, predicted.prediction, predicted.prior),)
    if prev is None or "tracker" not in prev.line:
        return None
    tracker = restored_tracker(s, resume_point(prev.line).tracker)
    for spec in s.targets:  # a known target entering after the previous slot (at its cue)
        if spec.prior_known and spec.first_slot == prev.slot:
            tracker.add_confirmed(Gaussian(np.array(spec.x0, dtype=float), s.P0.copy()))
    return tracker.predict()


def _live_job(
    line: TracksLine,
    prev: TracksLine | None,
    records: dict[int, SlotRecord],
    s: Scenario,
    kits: KitCache,
    method: Method,
    predictions: tuple[TrackPrediction, ...],
    replayed: dict[int, tuple[tuple[int, ...], SlotPlan]],
    priorities: Priorities,
) -> PlanningJob:
    """The planning job of slot line.slot as the ground loop built it (mission.next_job): the
    recorded start, the previous plan's shares and BSs, the vehicles it planned around, the
    operator's priorities."""
    raw = _fields(line, records)
    if prev is None:
        eta, assoc = np.full(s.M, 1.0 / s.M), None
    else:
        before = _fields(prev, records)
        shares = before.get("plan_eta") if "tracker" in before else None
        eta = np.asarray(before["eta"] if shares is None else shares, dtype=float)
        assoc = np.asarray([-1 if a is None else a for a in before["assoc"]], dtype=np.int64)
    excluded = tuple(sorted(int(m) for m in raw.get("planned_around", [])))
    active = tuple(m for m in range(s.M) if m not in excluded)
    prev_plan = None
    last = replayed.get(line.slot - 1)
    if last is not None and last[0] == active:
        prev_plan = active_part(last[1], active)
    return PlanningJob(
        slot=line.slot,
        method=method,
        kits=kits,
        uav_xy=_array(raw, "plan_start_xy"),
        uav_v=None
        if raw.get("plan_start_velocity") is None
        else _array(raw, "plan_start_velocity"),
        prev_eta=eta,
        prev_assoc=assoc,
        predictions=predictions,
        excluded=excluded,
        prev_plan=prev_plan,
        priorities=priorities,
    )


def _offline_start(
    prev: TracksLine | None, records: dict[int, SlotRecord], s: Scenario
) -> tuple[FloatArray, FloatArray]:
    """Where the offline loop starts slot n: the previous plan's waypoint [M, 2] and end
    velocity [M, 2] (the mean leg velocity with the paper's kinematics); the start points at
    rest at slot 1, and the measured positions after a slot without a plan of the loop."""
    if prev is None:
        return np.array(s.uav_start_xy, dtype=float), np.zeros((s.M, 2))
    raw = _fields(prev, records)
    if raw.get("plan_xy") is None:
        return np.array(prev.uav_xy, dtype=float), np.zeros((s.M, 2))
    xy = _array(raw, "plan_xy")
    if raw.get("plan_velocity") is not None:
        return xy, _array(raw, "plan_velocity")
    start = _array(raw, "plan_start_xy", xy)
    return xy, (xy - start) / s.dt


@dataclass(frozen=True)
class ReplaySummary:
    """Means over a range of slots (m, m/s), per UAV-slot; counts of fallbacks."""

    slots: int
    start_gap_m: float
    start_gap_max_m: float
    start_velocity_gap_mps: float
    prediction_gap_max: float
    replay_gap_m: float
    replay_gap_max_m: float
    planned_step_m: float
    offline_step_m: float
    fallbacks: int
    replay_fallbacks: int


def summarize_replay(rows: Sequence[ReplayedSlot], first_slot: int = 1) -> ReplaySummary:
    """Means (and maxima) over the rows of slots >= first_slot."""
    rows = [r for r in rows if r.slot >= first_slot]
    if not rows:
        nan = float("nan")
        return ReplaySummary(0, nan, nan, nan, nan, nan, nan, nan, nan, 0, 0)

    def stack(name: str) -> FloatArray:
        return np.concatenate([getattr(r, name) for r in rows])

    return ReplaySummary(
        slots=len(rows),
        start_gap_m=float(stack("start_gap_m").mean()),
        start_gap_max_m=float(stack("start_gap_m").max()),
        start_velocity_gap_mps=float(stack("start_velocity_gap_mps").mean()),
        prediction_gap_max=max(r.prediction_gap for r in rows),
        replay_gap_m=float(stack("replay_gap_m").mean()),
        replay_gap_max_m=float(stack("replay_gap_m").max()),
        planned_step_m=float(stack("planned_step_m").mean()),
        offline_step_m=float(stack("offline_step_m").mean()),
        fallbacks=sum(bool(r.fallback) for r in rows),
        replay_fallbacks=sum(bool(r.replay_fallback) for r in rows),
    )
