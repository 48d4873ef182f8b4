"""One slot's planning for the vehicles that can follow a plan, without I/O.

A vehicle whose link is lost (or whose telemetry went stale) still flies: it holds where it was
last seen. The slot is then planned for the others only: association, bandwidth and positions
over the active vehicles (a planner kit for that sub-fleet, built once per set and cached), with
the excluded vehicles' last known positions as keep-out points (D_s, like 14i). The plan is then
widened back to all M vehicles: an excluded vehicle gets its hold position as waypoint, no
bandwidth (eta = 0, so it takes no measurement) and no BS (-1).

`PlanningJob.run` may be called on a worker thread (the ground loop's time budget); it touches
nothing but the job and its kit. `hold` is the plan of last resort: no solver at all.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from isac_mission.config import Scenario
from isac_mission.planning.decomposed import DECOMPOSED_KEY, DecomposedHorizon, use_group_executor
from isac_mission.planning.fallback import NO_BS, OPERATOR_HOLD, hold_plan
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.registry import planner
from isac_mission.planning.slot import Method, plan_slot, warm_up
from isac_mission.planning.tracks import Planner as Planner
from isac_mission.planning.tracks import TracksPlan, plan_tracks, planned_beliefs
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.priorities import Priorities
from isac_mission.tracking.tracker import TrackPrediction
from isac_mission.types import FloatArray, HorizonPlan, IntArray, SlotPlan

OPERATOR_HOLD_REASON = "operator hold: every vehicle held or landed by an operator"

SOLVER_ERROR = "solver error"
"""Status and fallback of a plan made after the planner failed (`after_solver_error`)."""

BUILD_AHEAD_BUDGET_S = 10.0
"""Start-up seconds `prepare_fleet` may spend on the fleets with two or more vehicles out (the
one-out fleet is always built). With the horizon, interpreted: every size at M = 6 (4 s for
the five), at M = 12 the one-out fleet only (8 s)."""


class KitCache:
    """Solver kits per set of active vehicles (the full fleet's kit is given). Kits of the same
    size share their IPOPT problems (they depend on the fleet's size and the number of keep-out
    points, not on which vehicles), kept in the full kit so that renewed kits keep them too.

    A sub-fleet's kit solves the decomposed horizon's groups where the full kit does: the
    full kit's executor (`decomposed.use_group_executor`: a planner cluster, or None for this
    process) is passed to every kit `for_active` returns, as of that call. The full kit is the
    one place the executor is set: every KitCache made on it or on a kit renewed from it (an
    operator's R_th, a timed-out plan's renewal: they share its DecomposedHorizon) follows it."""

    def __init__(
        self, full: SolverKit, method: Method = "proposed", base_keep_out: int = 0
    ) -> None:
        """method: what the kits are warmed up for (the mission's planning method);
        base_keep_out: the keep-out points every kit has besides the excluded vehicles (the
        full kit's own: the other tracks of a multi-target mission, planning/tracks.py)."""
        self.full = full
        self.method: Method = method
        self.base_keep_out = base_keep_out
        self._kits: dict[tuple[int, ...], SolverKit] = {}

    @property
    def scenario(self) -> Scenario:
        return self.full.scenario

    def for_active(self, active: tuple[int, ...]) -> SolverKit:
        """The kit planning `active` (sorted vehicle indices) with the others as keep-out points.
        Warmed up on first use (one plan; its IPOPT problems built then unless `build_ahead`
        built them for this size), then reused."""
        s = self.full.scenario
        if len(active) == s.M:
            return self.full
        kit = self._kits.get(active)
        if kit is None:
            kit = self._sub_kit(active)
            warm_up(kit, self.method)
            self._kits[active] = kit
        self._groups_where_the_full_kit_solves_them(kit)
        return kit

    def _groups_where_the_full_kit_solves_them(self, kit: SolverKit) -> None:
        """Set the full kit's group executor on the sub-fleet's kit `kit` (class doc); nothing
        for a scenario whose horizon is not decomposed (no executor to pass)."""
        if self.full.scenario.planner.horizon.decompose != "targets":
            return
        executor = self.full.built(DECOMPOSED_KEY, DecomposedHorizon).executor
        use_group_executor(kit, executor)

    def build_ahead(self, budget_s: float = BUILD_AHEAD_BUDGET_S) -> list[int]:
        """Build the IPOPT problems of the fleets with one, two, ... vehicles out (an operator's
        HOLD, a lost link), so that the first plan without them builds none: the one-out fleet
        always, each smaller one while the time spent, plus the last build's, stays within
        budget_s (smaller fleets build faster). Returns the fleet sizes built; the others are
        built on their first plan."""
        s = self.full.scenario
        built: list[int] = []
        started_s = last_s = time.perf_counter()
        for size in range(s.M - 1, 0, -1):
            now_s = time.perf_counter()
            if built and (now_s - started_s) + (now_s - last_s) > budget_s:
                break
            last_s = now_s
            planner(self.method).prepare(self._sub_kit(tuple(range(size))))
            built.append(size)
        return built

    def _sub_kit(self, active: tuple[int, ...]) -> SolverKit:
        s = self.full.scenario
        idx = list(active)
        sub = s.with_changes(M=len(idx), uav_start_xy=s.uav_start_xy[idx])
        n_keep_out = self.base_keep_out + s.M - len(idx)
        kit = SolverKit(
            sub,
            fast=self.full.fast,
            n_keep_out=n_keep_out,
            solve_lock=self.full.solve_lock,
            ipopt=self.full.ipopt,
        )
        shared = f"problems of {len(idx)} of {s.M} vehicles, {n_keep_out} keep-out points"
        kit.share_built(self.full.built(shared, dict))
        return kit


@dataclass(frozen=True)
class PlanningJob:
    """Everything needed to plan slot `slot` (arrays over all M vehicles).

    uav_xy [M, 2], uav_v [M, 2]: positions and velocities now (m, m/s); prev_eta [M];
    prev_assoc [M] or None; predictions: the tracker's tracks predicted to the slot's end
    (tracking/tracker.py; none confirmed: the fleet holds); excluded: vehicles outside the plan
    (sorted); operator_held: those of them an operator's `hold` or `land` took out; prev_plan:
    last slot's plan of the same active vehicles, over those vehicles only (`active_part`), None
    when there is none or the active set changed; priorities: the operator's priority of each
    track (tracking/priorities.py; the default: every track 1).
    """

    slot: int
    method: Method
    kits: KitCache
    uav_xy: FloatArray
    uav_v: FloatArray | None
    prev_eta: FloatArray
    prev_assoc: IntArray | None
    predictions: tuple[TrackPrediction, ...]
    excluded: tuple[int, ...] = ()
    prev_plan: SlotPlan | None = None
    operator_held: tuple[int, ...] = ()
    priorities: Priorities = field(default_factory=Priorities)

    @property
    def active(self) -> tuple[int, ...]:
        M = self.kits.scenario.M
        return tuple(m for m in range(M) if m not in self.excluded)

    @property
    def targets(self) -> tuple[TargetBelief, ...]:
        """The confirmed tracks planned for, weighed as the planner weighs them (what a hold is
        judged by; `tracks.planned_beliefs`)."""
        return planned_beliefs(self.kits.scenario, self.predictions, self.priorities)

    def run(self, planner: Planner = plan_slot) -> SlotPlan:
        """The plan of `run_tracks`."""
        return self.run_tracks(planner).plan

    def run_tracks(self, planner: Planner = plan_slot) -> TracksPlan:
        """Plan the active vehicles for the tracks (planning/tracks.plan_tracks) and widen
        the plan to all of them (see the module doc)."""
        active = self.active
        if not active:
            if set(self.excluded) <= set(self.operator_held):
                return TracksPlan(0, None, self.hold(OPERATOR_HOLD_REASON, OPERATOR_HOLD))
            why = "hold: no vehicle can follow a plan (all excluded)"
            return TracksPlan(0, None, self.hold(why, "no vehicles"))
        idx = list(active)
        kit = self.kits.for_active(active)
        eta = self.prev_eta[idx]
        if self.excluded or not eta.sum() > 0:  # the sub-fleet's shares, summing to 1
            eta = eta / eta.sum() if eta.sum() > 0 else np.full(len(idx), 1.0 / len(idx))
        assoc = None if self.prev_assoc is None else self.prev_assoc[idx]
        if assoc is not None and np.any(assoc < 0):
            assoc = None
        planned = plan_tracks(
            kit.scenario,
            self.method,
            kit,
            self.predictions,
            self.uav_xy[idx],
            eta,
            assoc,
            None if self.uav_v is None else self.uav_v[idx],
            self.prev_plan,
            extra_keep_out_xy=self.uav_xy[list(self.excluded)] if self.excluded else None,
            keep_out_tracks=self.kits.base_keep_out,
            planner=planner,
            priorities=self.priorities,
        )
        if not self.excluded:
            return planned
        return replace(planned, plan=widen_plan(planned.plan, self.uav_xy, self.excluded))

    def hold(self, reason: str, status: str, solve_s: float = 0.0) -> SlotPlan:
        """Every vehicle holds where it is (planning/fallback.hold_plan)."""
        return hold_plan(
            self.kits.scenario,
            self.kits.full.sensing,
            self.uav_xy,
            self.prev_eta,
            self.prev_assoc,
            self.excluded,
            self.targets,
            reason,
            status,
            solve_s,
        )

    def fallback_after_error(self, reason: str, solve_s: float) -> TracksPlan:
        """After a planner error: the communication-optimal plan (method "comm") for the active
        vehicles; if that fails too, hold. Status "solver error" either way, with the reason."""
        planned_for = 0

        def comm() -> SlotPlan:
            nonlocal planned_for
            planned = replace(self, method="comm").run_tracks()
            planned_for = planned.planned_for
            return planned.plan

        def hold(why: str) -> SlotPlan:
            nonlocal planned_for
            planned_for = 0
            return self.hold(why, SOLVER_ERROR, solve_s)

        plan = after_solver_error(reason, solve_s, comm, hold)
        return TracksPlan(planned_for, None, plan)


def after_solver_error(
    reason: str,
    solve_s: float,
    comm: Callable[[], SlotPlan],
    hold: Callable[[str], SlotPlan],
) -> SlotPlan:
    """The plan after a planner error: comm(), the communication-optimal
    plan, with status and fallback "solver error", `reason` and the time spent before it
    (solve_s, s); if comm() raises too, hold(why) (a hold plan with status "solver error")."""
    try:
        plan = comm()
    except Exception as err:  # the fallback must not raise: hold instead
        return hold(f"{reason}; communication-optimal fallback failed too: {err}; hold")
    note = f"{reason}; fell back to the communication-optimal plan"
    return replace(
        plan,
        report=replace(
            plan.report,
            status=SOLVER_ERROR,
            reason=note,
            solve_s=solve_s,
            fallback=SOLVER_ERROR,
        ),
    )


def widen_plan(sub: SlotPlan, uav_xy: FloatArray, excluded: tuple[int, ...]) -> SlotPlan:
    """A plan of the active vehicles (all but the sorted `excluded`) widened to the whole fleet
    at uav_xy [M, 2] (m): an excluded vehicle holds where it is (its waypoint its position, no
    share, no BS, velocity 0), and the reason says which vehicles are out. The inverse of
    `active_part`."""
    M = len(uav_xy)
    idx = [m for m in range(M) if m not in excluded]
    xy = np.array(uav_xy, dtype=float)
    xy[idx] = sub.uav_xy_m
    eta = np.zeros(M)
    eta[idx] = sub.bandwidth_share
    assoc = np.full(M, NO_BS, dtype=np.int64)
    assoc[idx] = sub.bs_of_uav
    note = f"vehicles {list(excluded)} excluded (health says why), holding"
    reason = f"{sub.report.reason}; {note}" if sub.report.reason else note
    velocity = None
    if sub.uav_velocity_mps is not None:  # a holding vehicle's planned velocity is 0
        velocity = np.zeros((M, 2))
        velocity[idx] = sub.uav_velocity_mps
    horizon = None
    if sub.horizon is not None:
        h = sub.horizon
        L = h.uav_xy_m.shape[0]
        h_xy = np.repeat(np.asarray(uav_xy, dtype=float)[None], L, axis=0)
        h_xy[:, idx] = h.uav_xy_m
        h_eta = np.zeros((L, M))
        h_eta[:, idx] = h.bandwidth_share
        h_v = None
        if h.uav_velocity_mps is not None:
            h_v = np.zeros((L, M, 2))
            h_v[:, idx] = h.uav_velocity_mps
        horizon = HorizonPlan(h_xy, h_v, h_eta, h.pcrb_trace, h.duals)
    return SlotPlan(
        xy, assoc, eta, sub.pcrb_trace, replace(sub.report, reason=reason), velocity, horizon
    )


def active_part(plan: SlotPlan, active: tuple[int, ...]) -> SlotPlan:
    """The part of a plan over all M vehicles that concerns the `active` ones (sorted indices):
    the inverse of PlanningJob's widening, so that the planner's prev_plan is over the vehicles
    it plans (waypoints, shares, association, velocities and the horizon, indexed by vehicle)."""
    idx = list(active)
    if len(idx) == len(plan.bandwidth_share):
        return plan
    h = plan.horizon
    horizon = (
        None
        if h is None
        else HorizonPlan(
            h.uav_xy_m[:, idx],
            None if h.uav_velocity_mps is None else h.uav_velocity_mps[:, idx],
            h.bandwidth_share[:, idx],
            h.pcrb_trace,
            h.duals,
        )
    )
    v = plan.uav_velocity_mps
    return SlotPlan(
        plan.uav_xy_m[idx],
        plan.bs_of_uav[idx],
        plan.bandwidth_share[idx],
        plan.pcrb_trace,
        plan.report,
        None if v is None else v[idx],
        horizon,
    )


def prepare_fleet(
    kit: SolverKit,
    method: Method,
    base_keep_out: int = 0,
    budget_s: float = BUILD_AHEAD_BUDGET_S,
) -> list[int]:
    """Warm the full fleet's kit up for `method` and build, ahead, the problems of the smaller
    fleets the mission can reach when vehicles leave the plan (KitCache.build_ahead, within
    budget_s; base_keep_out as KitCache's). Returns the fleet sizes built ahead: no plan of the
    mission builds an IPOPT problem until more vehicles than those leave the plan."""
    warm_up(kit, method)
    return KitCache(kit, method, base_keep_out).build_ahead(budget_s)
