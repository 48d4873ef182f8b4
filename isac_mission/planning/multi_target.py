"""Planning for several tracks with the single-target methods (docs/model.md, "Planning for
several targets"): the offline multi-target loop and the live ground loop plan through here.

Every per-slot method plans for the sum of the confirmed tracks' tr(PCRB)
(`SlotInput.other_targets`); the confirmed track nearest to the fleet is the target the plan's
safety rule follows along each leg, and every other track, confirmed or tentative, is a keep-out
point at its predicted position that every UAV keeps D_s from (the nearest
`KEEP_OUT_CAPACITY`). With no confirmed track the fleet holds where it is.
"""

from __future__ import annotations

import numpy as np

from isac_mission.config import Scenario
from isac_mission.errors import ConfigError
from isac_mission.planning.association import association_costs, optimal_assignment
from isac_mission.planning.slot import Method, SlotInput, SolverKit, plan_slot
from isac_mission.tracking.multi_target import TrackPrediction
from isac_mission.types import FloatArray, IntArray, SlotPlan, SolveReport

KEEP_OUT_CAPACITY = 8
"""How many tracks besides the planned-around one every UAV keeps D_s from (the nearest to the
fleet); the kit's problems are built for this many keep-out points."""

FAR_AWAY_M = -1e6
"""Where the unused keep-out points are (no UAV comes near)."""

SINGLE_TARGET_METHODS = ("horizon",)
"""Methods that plan for one target only (their NLPs are one target's): refused on this path."""


def multi_target_kit(s: Scenario) -> SolverKit:
    """A SolverKit for planning several tracks (KEEP_OUT_CAPACITY keep-out points)."""
    return SolverKit(s, n_keep_out=KEEP_OUT_CAPACITY)


def check_multi_target_method(method: str) -> None:
    """Raise ConfigError for a method that cannot plan for several targets."""
    if method in SINGLE_TARGET_METHODS:
        raise ConfigError(
            f"method {method!r} plans for one target (its NLP is one target's bound); on the "
            "multi-target path plan with proposed, proposed-sca, sd, aba, crb or comm"
        )


def plan_for_tracks(
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
) -> tuple[int, SlotPlan]:
    """(the ID of the track planned around, 0 when the fleet holds; the slot's plan) for the
    tracks' predictions, from the UAVs at uav_xy [M, 2] (m) with velocities [M, 2] (m/s),
    last slot's shares eta [M] and BSs assoc [M] (None: none yet). extra_keep_out_xy [E, 2]:
    more points every UAV keeps D_s from (the vehicles outside the plan). `kit` from
    `multi_target_kit` (E = 0), or built with KEEP_OUT_CAPACITY + E keep-out points."""
    extra = np.zeros((0, 2)) if extra_keep_out_xy is None else np.asarray(extra_keep_out_xy)
    if kit.n_keep_out != KEEP_OUT_CAPACITY + len(extra):
        raise ValueError(
            f"the kit must be built with n_keep_out={KEEP_OUT_CAPACITY} + {len(extra)}"
        )
    confirmed = [p for p in predictions if p.confirmed]
    if not confirmed:
        return 0, hold_without_track(s, uav_xy, eta, assoc)

    def fleet_distance(p: TrackPrediction) -> float:
        return float(np.min(np.linalg.norm(uav_xy - p.prediction.x[:2], axis=1)))

    primary = min(confirmed, key=fleet_distance)
    others = sorted((p for p in predictions if p is not primary), key=fleet_distance)
    keep_out = np.full((KEEP_OUT_CAPACITY + len(extra), 2), FAR_AWAY_M)
    for i, p in enumerate(others[:KEEP_OUT_CAPACITY]):
        keep_out[i] = p.prediction.x[:2]
    keep_out[KEEP_OUT_CAPACITY:] = extra
    inp = SlotInput(
        prev_xy_m=uav_xy,
        prev_bandwidth_share=eta,
        prev_bs_of_uav=assoc,
        target_state_pred=primary.prediction.x,
        prior_information=primary.prior_information,
        prev_velocity_mps=velocity,
        keep_out_xy_m=keep_out,
        target_cov_pred=primary.prediction.P,
        prev_plan=prev_plan,
        other_targets=tuple(
            (p.prediction.x, p.prior_information) for p in confirmed if p is not primary
        ),
    )
    return primary.track_id, plan_slot(inp, kit, method)


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
