"""A slot planned for the tracker's tracks, one or several (docs/model.md, "Planning for
several targets"): the offline loop and the live ground loop plan through here.

Every method plans for the weighted sum of the confirmed tracks' tr(PCRB) (`SlotInput.targets`,
the first the primary; one track: the paper's objective), each weighed by the operator's
priority of its track relative to the others' (tracking/priorities.py: `planning_weights`; all
1 by default); the exact check keeps every confirmed track's 14j clearance along each leg, the
confirmed track nearest to the fleet among those planned for (priority > 0) is the one the
solvers' 14j rows follow, and every other track, confirmed or tentative, is also a keep-out point
at its predicted position that every UAV keeps D_s from (the nearest `KEEP_OUT_CAPACITY`). A
confirmed track at priority 0 stays in the targets with weight 0: the objective does not depend
on it, its clearance is kept as every other's. With no confirmed track to plan for the fleet
holds where it is. A method that plans for one target only (the registry's max_targets) is
refused for a tracker that may hold several tracks (`method_problem`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from isac_mission.config import Scenario
from isac_mission.errors import ConfigError
from isac_mission.planning.association import association_costs, optimal_assignment
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.registry import METHODS, live_default_method, max_targets
from isac_mission.planning.slot import Method, SlotInput, plan_slot
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.factory import KEEP_OUT_TRACKS, keep_out_tracks
from isac_mission.tracking.priorities import Priorities
from isac_mission.tracking.tracker import TrackPrediction
from isac_mission.types import FloatArray, IntArray, SlotPlan, SolveReport

KEEP_OUT_CAPACITY = KEEP_OUT_TRACKS
"""How many tracks besides the planned-around one every UAV keeps D_s from (the nearest to the
fleet); the kit's problems are built for this many keep-out points."""

Planner = Callable[[SlotInput, SolverKit, Method], SlotPlan]
"""A per-slot planning function (plan_slot; replaceable to inject faults)."""

FAR_AWAY_M = -1e6
"""Where the unused keep-out points are (no UAV comes near)."""


def multi_target_kit(s: Scenario) -> SolverKit:
    """A SolverKit for planning several tracks (KEEP_OUT_CAPACITY keep-out points)."""
    return SolverKit(s, n_keep_out=KEEP_OUT_CAPACITY)


def check_multi_target_method(method: str) -> None:
    """Raise ConfigError for a method that cannot plan for several targets (the registry's
    max_targets)."""
    if max_targets(method) == 1:
        several = ", ".join(m for m in METHODS if max_targets(m) != 1)
        raise ConfigError(
            f"method {method!r} plans for one target (the registry's max_targets); on the "
            f"multi-target path plan with {several}"
        )


def method_problem(s: Scenario, method: str) -> str | None:
    """Why `method` cannot plan for the scenario's tracks (None: it can): the scenario's
    tracker may hold several tracks (its plans keep other tracks apart:
    `tracking/factory.keep_out_tracks`) and the method plans for one target (the registry's
    max_targets)."""
    if keep_out_tracks(s) == 0:
        return None
    try:
        check_multi_target_method(method)
    except ConfigError as err:
        return str(err)
    return None


def live_method(s: Scenario) -> Method:
    """The live service's default method for the scenario's tracks (the registry's
    live_default_method: the receding horizon where the tracker has one track)."""
    return live_default_method(keep_out_tracks(s) > 0)


def check_method(s: Scenario, method: str) -> None:
    """Raise ConfigError with `method_problem`'s reason when there is one."""
    problem = method_problem(s, method)
    if problem is not None:
        raise ConfigError(problem)


@dataclass(frozen=True)
class TracksPlan:
    """A slot planned for the tracks: planned_for, the ID of the track the plan's safety rule
    follows (0 when the fleet holds); slot_input, what the planner was given (None when it was
    not asked: no confirmed track); plan."""

    planned_for: int
    slot_input: SlotInput | None
    plan: SlotPlan


def plan_tracks(
    s: Scenario,
    method: Method,
    kit: SolverKit,
    predictions: tuple[TrackPrediction, ...],
    uav_xy: FloatArray,
    eta: FloatArray,
    assoc: IntArray | None,
    velocity: FloatArray | None,
    prev_plan: SlotPlan | None,
    extra_keep_out_xy: FloatArray | None = None,
    keep_out_tracks: int = KEEP_OUT_CAPACITY,
    planner: Planner = plan_slot,
    priorities: Priorities | None = None,
) -> TracksPlan:
    """The slot's plan for the tracks' predictions, from the UAVs at uav_xy [M, 2] (m) with
    velocities [M, 2] (m/s), last slot's shares eta [M] and BSs assoc [M] (None: none yet).
    extra_keep_out_xy [E, 2]: more points every UAV keeps D_s from (the vehicles outside the
    plan); keep_out_tracks: how many other tracks the kit keeps D_s from (0: a tracker of one
    target); `kit` built with keep_out_tracks + E keep-out points; priorities: the operator's
    priority of each track ID (None: every track 1), which weighs its bound in the objective
    (module doc)."""
    extra = np.zeros((0, 2)) if extra_keep_out_xy is None else np.asarray(extra_keep_out_xy)
    if kit.n_keep_out != keep_out_tracks + len(extra):
        raise ValueError(f"the kit must be built with n_keep_out={keep_out_tracks} + {len(extra)}")
    table = Priorities() if priorities is None else priorities
    confirmed = [p for p in predictions if p.confirmed]
    planned = [p for p in confirmed if table[p.track_id] > 0]
    if not planned:
        note = None if not confirmed else ZERO_PRIORITY_HOLD
        return TracksPlan(0, None, hold_without_track(s, uav_xy, eta, assoc, note))

    def fleet_distance(p: TrackPrediction) -> float:
        return float(np.min(np.linalg.norm(uav_xy - p.prediction.x[:2], axis=1)))

    primary = min(planned, key=fleet_distance)
    others = sorted((p for p in predictions if p is not primary), key=fleet_distance)
    if others and keep_out_tracks == 0:
        raise ValueError("several tracks, but the kit keeps no track apart")
    keep_out: FloatArray | None = None
    if kit.n_keep_out:
        keep_out = np.full((keep_out_tracks + len(extra), 2), FAR_AWAY_M)
        for i, p in enumerate(others[:keep_out_tracks]):
            keep_out[i] = p.prediction.x[:2]
        keep_out[keep_out_tracks:] = extra
    inp = SlotInput(
        prev_xy_m=uav_xy,
        prev_bandwidth_share=eta,
        prev_bs_of_uav=assoc,
        targets=weighted_beliefs(s, (primary, *(p for p in confirmed if p is not primary)), table)
        + newcomer_beliefs(s, predictions, table),
        prev_velocity_mps=velocity,
        keep_out_xy_m=keep_out,
        prev_plan=prev_plan,
    )
    return TracksPlan(primary.track_id, inp, planner(inp, kit, method))


def weighted_beliefs(
    s: Scenario, tracks: Sequence[TrackPrediction], priorities: Priorities
) -> tuple[TargetBelief, ...]:
    """The tracks as the planner takes them (`TrackPrediction.belief`), in the given order, each
    weighed by its priority relative to the others' (`Priorities.planning_weights`: 0 for a
    track at priority 0; every weight exactly 1 when the priorities are equal)."""
    weights = priorities.planning_weights([p.track_id for p in tracks])
    out = []
    for p, w in zip(tracks, weights, strict=True):
        belief = p.belief(s.motion)
        out.append(belief if w == belief.weight else replace(belief, weight=w))
    return tuple(out)


def newcomer_beliefs(
    s: Scenario, predictions: Sequence[TrackPrediction], priorities: Priorities
) -> tuple[TargetBelief, ...]:
    """The tentative tracks as targets of the objective (`planner.newcomer_weight` > 0; none
    otherwise), each weighed newcomer_weight x its existence x its priority: the fleet spends
    geometry and bandwidth on placing a newcomer before its confirmation instead of leaving it
    to whichever UAV happens to range it (docs/model.md, "Planning for several targets")."""
    share = s.planner.newcomer_weight
    if share == 0.0:
        return ()
    return tuple(
        replace(p.belief(s.motion), weight=share * p.existence * priorities[p.track_id])
        for p in predictions
        if not p.confirmed and priorities[p.track_id] > 0
    )


def planned_beliefs(
    s: Scenario, predictions: Sequence[TrackPrediction], priorities: Priorities | None = None
) -> tuple[TargetBelief, ...]:
    """The confirmed tracks planned for (priority > 0), weighed as `plan_tracks` weighs them, in
    the predictions' order: what a plan (a hold) is judged by."""
    table = Priorities() if priorities is None else priorities
    tracks = [p for p in predictions if p.confirmed and table[p.track_id] > 0]
    return weighted_beliefs(s, tracks, table)


NO_TRACK_HOLD = "no confirmed track: the fleet holds"
"""The note of a hold without a confirmed track."""

ZERO_PRIORITY_HOLD = "no track to plan for: every confirmed track has priority 0; the fleet holds"
"""The note of a hold whose confirmed tracks are all at priority 0."""


def hold_without_track(
    s: Scenario,
    uav_xy: FloatArray,
    eta: FloatArray,
    assoc: IntArray | None,
    note: str | None = None,
) -> SlotPlan:
    """Every UAV holds where it is with last slot's shares and BSs (the communication-optimal
    BSs at the first slot): no confirmed track to plan for (note: why, NO_TRACK_HOLD by
    default)."""
    if assoc is None:
        costs = association_costs(uav_xy, s.bs_xy, dH=s.dH, rho0=s.rho0, B=s.B)
        assoc = optimal_assignment(costs, s.n_a)
    report = SolveReport("ok", note or NO_TRACK_HOLD, fallback="no track")
    return SlotPlan(uav_xy.copy(), assoc, eta.copy(), float("nan"), report)
