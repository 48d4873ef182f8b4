"""Planning for several tracks with the single-target methods (docs/model.md, "Planning for
several targets"): the offline multi-target loop and the live ground loop plan through here.

Every per-slot method plans for the sum of the confirmed tracks' tr(PCRB)
(`SlotInput.targets`, the first the primary); the confirmed track nearest to the fleet is the target the plan's
safety rule follows along each leg, and every other track, confirmed or tentative, is a keep-out
point at its predicted position that every UAV keeps D_s from (the nearest
`KEEP_OUT_CAPACITY`). With no confirmed track the fleet holds where it is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.errors import ConfigError
from isac_mission.planning.association import association_costs, optimal_assignment
from isac_mission.planning.registry import METHODS, max_targets
from isac_mission.planning.slot import Method, SlotInput, SolverKit, plan_slot
from isac_mission.tracking.factory import KEEP_OUT_TRACKS
from isac_mission.tracking.tracker import TrackPrediction
from isac_mission.types import FloatArray, IntArray, SlotPlan, SolveReport

KEEP_OUT_CAPACITY = KEEP_OUT_TRACKS
"""How many tracks besides the planned-around one every UAV keeps D_s from (the nearest to the
fleet); the kit's problems are built for this many keep-out points."""

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
            f"method {method!r} plans for one target (its NLP is one target's bound); on the "
            f"multi-target path plan with {several}"
        )


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
) -> TracksPlan:
    """The slot's plan for the tracks' predictions, from the UAVs at uav_xy [M, 2] (m) with
    velocities [M, 2] (m/s), last slot's shares eta [M] and BSs assoc [M] (None: none yet).
    extra_keep_out_xy [E, 2]: more points every UAV keeps D_s from (the vehicles outside the
    plan); keep_out_tracks: how many other tracks the kit keeps D_s from (0: a tracker of one
    target); `kit` built with keep_out_tracks + E keep-out points."""
    extra = np.zeros((0, 2)) if extra_keep_out_xy is None else np.asarray(extra_keep_out_xy)
    if kit.n_keep_out != keep_out_tracks + len(extra):
        raise ValueError(f"the kit must be built with n_keep_out={keep_out_tracks} + {len(extra)}")
    confirmed = [p for p in predictions if p.confirmed]
    if not confirmed:
        return TracksPlan(0, None, hold_without_track(s, uav_xy, eta, assoc))

    def fleet_distance(p: TrackPrediction) -> float:
        return float(np.min(np.linalg.norm(uav_xy - p.prediction.x[:2], axis=1)))

    primary = min(confirmed, key=fleet_distance)
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
        targets=tuple(
            p.belief(s.motion) for p in (primary, *(p for p in confirmed if p is not primary))
        ),
        prev_velocity_mps=velocity,
        keep_out_xy_m=keep_out,
        prev_plan=prev_plan,
    )
    return TracksPlan(primary.track_id, inp, plan_slot(inp, kit, method))


def hold_without_track(
    s: Scenario, uav_xy: FloatArray, eta: FloatArray, assoc: IntArray | None
) -> SlotPlan:
    """Every UAV holds where it is with last slot's shares and BSs (the communication-optimal
    BSs at the first slot): no confirmed track to plan for."""
    if assoc is None:
        costs = association_costs(uav_xy, s.bs_xy, dH=s.dH, rho0=s.rho0, B=s.B)
        assoc = optimal_assignment(costs, s.n_a)
    report = SolveReport("ok", "no confirmed track: the fleet holds", fallback="no track")
    return SlotPlan(uav_xy.copy(), assoc, eta.copy(), float("nan"), report)
