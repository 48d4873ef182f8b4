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
out, `planned_around`, held and kept out), chaining its own replayed plans as each slot's previous
plan. Pure computation on a trace and a scenario (no I/O: `read_trace` is the caller's).
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
from isac_mission.tracking.cycle import CycleModel, TrackState, predict
from isac_mission.tracking.pcrb import Bound
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
    if isinstance(a, (int, float, list)) and isinstance(b, (int, float, list)):
        try:
            return bool(np.allclose(np.asarray(a, float), np.asarray(b, float), rtol=1e-9))
        except ValueError:  # shapes differ
            return False
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
    recorded start, or those listed in `slots`). ValueError when `s` is not the scenario the
    trace was planned with (config_differences) or the trace records no planner inputs."""
    diff = config_differences(trace.config, s)
    if diff:
        raise ValueError(
            "the scenario is not the one the trace was planned with: " + "; ".join(diff)
        )
    method = _method(trace)
    kits = KitCache(kit if kit is not None else SolverKit(s), method)
    model = CycleModel.from_scenario(s)
    wanted = None if slots is None else set(slots)
    records = {r.slot: r for r in trace.slots}
    out: list[ReplayedSlot] = []
    replayed: dict[int, tuple[tuple[int, ...], SlotPlan]] = {}
    for rec in trace.slots:
        if rec.plan_start_xy is None or rec.plan_xy is None:
            continue
        prev = records.get(rec.slot - 1)
        if rec.slot > 1 and prev is None:
            continue  # the trace starts later (a resume): no previous belief to start from
        job = _live_job(rec, prev, s, model, kits, method, replayed)
        plan = job.run()
        replayed[rec.slot] = (job.active, plan)
        if wanted is not None and rec.slot not in wanted:
            continue
        start_xy, start_v = _offline_start(prev, s)
        offline = replace(job, uav_xy=start_xy, uav_v=start_v).run()
        x_pred = job.targets[0].state_pred
        start_v_live = (
            np.zeros((s.M, 2)) if rec.plan_start_velocity is None else rec.plan_start_velocity
        )
        out.append(
            ReplayedSlot(
                slot=rec.slot,
                status=rec.status,
                start_gap_m=_norms(rec.plan_start_xy - start_xy),
                start_velocity_gap_mps=_norms(start_v_live - start_v),
                prediction_gap=float(np.max(np.abs(np.asarray(rec.target_pred) - x_pred))),
                replay_gap_m=_norms(plan.uav_xy_m - rec.plan_xy),
                planned_step_m=_norms(rec.plan_xy - start_xy),
                offline_step_m=_norms(offline.uav_xy_m - start_xy),
                fallback=rec.fallback or "",
                replay_fallback=plan.report.fallback,
            )
        )
    return out


def _norms(d: FloatArray) -> FloatArray:
    return np.asarray(np.linalg.norm(np.asarray(d, dtype=float), axis=-1))


def _live_job(
    rec: SlotRecord,
    prev: SlotRecord | None,
    s: Scenario,
    model: CycleModel,
    kits: KitCache,
    method: Method,
    replayed: dict[int, tuple[tuple[int, ...], SlotPlan]],
) -> PlanningJob:
    """The planning job of slot rec.slot as the ground loop built it (mission.next_job)."""
    if prev is None:
        # The initial estimate is not traced (offline it is x0 plus the run's drawn error): the
        # one whose prediction is slot 1's target_pred, with the scenario's P0.
        x_init = np.linalg.solve(model.F, np.asarray(rec.target_pred, dtype=float))
        belief, bound = Gaussian(x_init, s.P0.copy()), Bound.from_covariance(s.P0.copy())
        eta, assoc = np.full(s.M, 1.0 / s.M), None
    else:
        belief = Gaussian(np.asarray(prev.target_est), np.asarray(prev.P))
        bound = Bound.from_information(np.asarray(prev.J))
        eta, assoc = (
            np.asarray(prev.bandwidth_share, dtype=float),
            np.asarray(prev.assoc, dtype=np.int64),
        )
    predicted = predict(model, TrackState(belief, bound))
    excluded = tuple(sorted(int(m) for m in rec.extra.get("planned_around", [])))
    active = tuple(m for m in range(s.M) if m not in excluded)
    prev_plan = None
    last = replayed.get(rec.slot - 1)
    if last is not None and last[0] == active:
        prev_plan = active_part(last[1], active)
    return PlanningJob(
        slot=rec.slot,
        method=method,
        kits=kits,
        uav_xy=np.asarray(rec.plan_start_xy, dtype=float),
        uav_v=None if rec.plan_start_velocity is None else np.asarray(rec.plan_start_velocity),
        prev_eta=eta,
        prev_assoc=assoc,
        predictions=(
            TrackPrediction(LABELLED_TRACK_ID, True, predicted.prediction, predicted.prior),
        ),
        excluded=excluded,
        prev_plan=prev_plan,
    )


def _offline_start(prev: SlotRecord | None, s: Scenario) -> tuple[FloatArray, FloatArray]:
    """Where the offline loop starts slot n: the previous plan's waypoint [M, 2] and end
    velocity [M, 2] (the mean leg velocity with the paper's kinematics); the start points at
    rest at slot 1, and the measured positions after a slot without a plan of the loop."""
    if prev is None:
        return np.array(s.uav_start_xy, dtype=float), np.zeros((s.M, 2))
    if prev.plan_xy is None:
        return np.array(prev.uav_xy_m, dtype=float), np.zeros((s.M, 2))
    xy = np.array(prev.plan_xy, dtype=float)
    if prev.plan_velocity is not None:
        return xy, np.array(prev.plan_velocity, dtype=float)
    start = prev.plan_start_xy if prev.plan_start_xy is not None else xy
    return xy, (xy - np.asarray(start)) / s.dt


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
