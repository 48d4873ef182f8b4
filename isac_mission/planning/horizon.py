"""Method `horizon`: plan slots n..n+L-1 together, fly the first, re-plan every slot.

Each slot (docs/model.md, "Receding horizon"):
1. the polished per-slot plan (`proposed`, planning/per_slot.py) is computed: it fixes slot n's association, which
   the horizon keeps over all L slots, it is one start point, and it is the fallback;
2. the horizon NLP (planning/horizon_nlp.py) is solved from the better (lower horizon objective)
   of two starts: last slot's horizon shifted by one slot (the warm start), and the per-slot plan
   continued at constant velocity;
3. the answer's first slot is kept if IPOPT succeeded (or stopped at its iteration cap on an
   iterate that meets every horizon constraint below the start's objective, `kept_at_cap`) and
   it passes the exact checks of 14a-14j on the slot (SlotConstraints.feasible, which every
   other method's plan passes too) and the vehicle model's leg limits; otherwise the per-slot
   plan is returned, saying why.

Several targets (SlotInput.targets): the NLP is the one built for their count T, planning the
sum over the targets of weight times each one's horizon objective and keeping 14j from each along
its own predicted path; the targets enter it ordered by track ID (`nlp_targets`), so that last
slot's multipliers still belong to their targets when the lead changes. A changed count is
another NLP: its start is cold (docs/model.md, "Receding horizon", "Several targets").

Pure: no clock, no RNG, no I/O.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.channel import min_share
from isac_mission.model.vehicle import end_accelerations, velocity_control_points
from isac_mission.planning.fallback import per_slot_instead
from isac_mission.planning.feasibility import SlotConstraints, operating_area
from isac_mission.planning.horizon_nlp import HorizonNLP, HorizonSlotData, HorizonSolution
from isac_mission.planning.horizon_problem import horizon_weights
from isac_mission.planning.legs import chord_point_clearance_m
from isac_mission.planning.margins import (
    LEG_LIMIT_TOLERANCE,
    RATE_MARGIN,
    sag_m,
    target_clearance_m,
)
from isac_mission.planning.pairs import (
    banded_order,
    horizon_reach_m,
    pair_bands,
    pairs_within_reach,
)
from isac_mission.planning.per_slot import Proposed
from isac_mission.planning.problem import (
    SlotInput,
    moving_targets,
    slot_association,
    with_end_velocity,
)
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.pcrb import (
    SensingParams,
    bound_along,
    scaled_inverse,
)
from isac_mission.types import (
    FloatArray,
    HorizonDuals,
    HorizonPlan,
    IntArray,
    SlotPlan,
    SolveReport,
)

if TYPE_CHECKING:
    from isac_mission.planning.kit import SolverKit


def horizon_bound_traces(
    s: Scenario,
    J_pred: FloatArray,
    x_pred: FloatArray,
    xy: FloatArray,
    eta: FloatArray,
    sensing: SensingParams,
    offsets: FloatArray | None = None,
) -> FloatArray:
    """tr(PCRB) [L] along a horizon plan xy [L, M, 2], eta [L, M] by the bound's recursion
    (tracking/pcrb.bound_along), every J_M at the predicted state of its slot (plus its path
    offset [L, 4], a manoeuvring belief's: `TargetBelief.path_offsets`; None: none)."""
    return bound_along(s.motion, s.dt, x_pred, J_pred, xy, eta, sensing, offsets).traces


def predicted_clearances(s: Scenario, target_cov_pred: FloatArray, length: int) -> FloatArray:
    """clearance_m [L]: target_clearance_m for the covariance predicted l slots further (no
    measurement in between: the largest the tracker's uncertainty can be there)."""
    F, W = s.motion.transition(s.dt), s.motion.process_noise(s.dt)
    P = np.asarray(target_cov_pred, dtype=float)
    out = []
    for _ in range(length):
        out.append(target_clearance_m(s, P))
        P = F @ P @ F.T + W
    return np.asarray(out)


def _continue(
    xy1: FloatArray, v1: FloatArray, eta1: FloatArray, length: int, dt: float, s: Scenario
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A horizon start from a first slot (xy1 [M, 2], v1 [M, 2], eta1 [M]): constant velocity
    (clipped into the area), the same shares."""
    lo, hi = operating_area(s)
    xy = np.array([np.clip(xy1 + h * dt * v1, lo, hi) for h in range(length)])
    v = np.repeat(v1[None], length, axis=0)
    return xy, v, np.repeat(eta1[None], length, axis=0)


def _shares_meeting_rates(
    s: Scenario, xy: FloatArray, eta: FloatArray, serving_xy: FloatArray, link_m: float
) -> FloatArray:
    """A horizon start's shares eta [L, M] moved, on the slots where some UAV at xy [L, M, 2]
    misses 14a on its BS at serving_xy [M, 2], to its minimum share (the NLP's rate row, link_m
    farther away) plus the rest in proportion to the start's surplus over the minimum. A start
    continued at constant velocity flies the UAVs away from their BSs: its later slots missed
    the rate by 1-3 %, and IPOPT spent its first iterations restoring it (or all 60 of them)."""
    out = np.array(eta, dtype=float)
    d_m = np.linalg.norm(xy - serving_xy[None], axis=-1) + link_m
    floor = (1 + 2 * RATE_MARGIN) * min_share(d_m, s.r_th, s.dH, s.rho0, s.B)
    for h in range(len(out)):
        if np.all(out[h] >= floor[h]) or floor[h].sum() >= 1.0:
            continue
        surplus = np.maximum(out[h] - floor[h], 0.0)
        weights = (
            surplus / surplus.sum()
            if surplus.sum() > 0
            else np.full(len(surplus), 1 / len(surplus))
        )
        out[h] = floor[h] + (1.0 - floor[h].sum()) * weights
    return out


def _shifted(
    prev: HorizonPlan, length: int, M: int, dt: float, s: Scenario
) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """Last slot's horizon shifted by one slot, its end continued at constant velocity; None if
    its shape does not match (fleet or length changed)."""
    if prev.uav_xy_m.shape != (length, M, 2):
        return None
    xy = prev.uav_xy_m
    if prev.uav_velocity_mps is not None:
        v = prev.uav_velocity_mps
    else:
        steps = np.diff(np.concatenate([xy[:1], xy]), axis=0) / dt
        v = steps
    lo, hi = operating_area(s)
    xy_new = np.concatenate([xy[1:], np.clip(xy[-1:] + dt * v[-1:], lo, hi)])
    v_new = np.concatenate([v[1:], v[-1:]])
    eta_new = np.concatenate([prev.bandwidth_share[1:], prev.bandwidth_share[-1:]])
    return xy_new, v_new, eta_new


def belief_cov_pred(belief: TargetBelief) -> FloatArray:
    """The target's predicted covariance [4, 4] for its clearances: the tracker's, or the bound's
    own (prior_information^-1) without one."""
    cov = belief.cov_pred
    return scaled_inverse(belief.prior_information) if cov is None else cov


def nlp_targets(inp: SlotInput) -> tuple[TargetBelief, ...]:
    """The slot's targets in the NLP's order: by track ID (stable from slot to slot when the lead
    changes, so that last slot's multipliers stay with their targets)."""
    return tuple(sorted(inp.targets, key=lambda b: b.track_id))


def horizon_slot_data(
    s: Scenario,
    inp: SlotInput,
    start_velocity_mps: FloatArray,
    target_cov_pred: FloatArray,
    bs_of_uav: IntArray,
    waypoints_xy_m: FloatArray,
    length: int,
    targets: tuple[TargetBelief, ...] | None = None,
) -> HorizonSlotData:
    """The horizon NLP's data for this slot: the association bs_of_uav [M] kept (serving BS),
    the BS nearest waypoints_xy_m [M, 2] (the first slot's of the start) as the control BS
    (14b), the clearances along the horizon; start_velocity_mps [M, 2]: what the first legs
    start with (`planned_start_velocity`). targets: with several, the NLP's targets in its order
    (`nlp_targets`; each its state, prior, clearances from its own covariance and weight);
    None: the lead alone, its covariance target_cov_pred [4, 4]."""
    nearest = np.argmin(np.linalg.norm(waypoints_xy_m[:, None, :] - s.bs_xy[None], axis=-1), axis=1)
    keep_out, x_pred = inp.keep_out_xy_m, inp.lead.state_pred
    data = HorizonSlotData(
        rate_min_bps=s.r_th,
        prev_xy=np.asarray(inp.prev_xy_m, dtype=float),
        prev_velocity=np.asarray(start_velocity_mps, dtype=float)
        if s.planner.vehicle_model
        else np.zeros((s.M, 2)),
        serving_xy=s.bs_xy[bs_of_uav],
        control_xy=s.bs_xy[nearest],
        keep_out_xy=np.zeros((0, 2)) if keep_out is None else np.asarray(keep_out),
        x_pred=np.asarray(x_pred, dtype=float),
        J_pred=np.asarray(inp.lead.prior_information, dtype=float),
        clearance_m=sample_clearances(s, predicted_clearances(s, target_cov_pred, length), x_pred),
        path_offset=inp.lead.path_offsets(length),
    )
    if targets is None or len(targets) == 1:
        return data
    clearances = [
        sample_clearances(s, predicted_clearances(s, belief_cov_pred(b), length), b.state_pred)
        for b in targets
    ]
    return replace(
        data,
        x_pred=np.array([b.state_pred for b in targets], dtype=float),
        J_pred=np.array([b.prior_information for b in targets], dtype=float),
        clearance_m=np.array(clearances),
        target_weight=np.array([b.weight for b in targets], dtype=float),
        path_offset=target_offsets(targets, length),
    )


def target_offsets(targets: tuple[TargetBelief, ...], length: int) -> FloatArray | None:
    """[T, length, 4] (m, m/s): every target's path offsets (`TargetBelief.path_offsets`, zeros
    for a target without a manoeuvre); None when none has one."""
    if all(b.manoeuvre is None for b in targets):
        return None
    zeros = np.zeros((length, 4))
    return np.array([o if (o := b.path_offsets(length)) is not None else zeros for b in targets])


def sample_clearances(s: Scenario, clearance_m: FloatArray, x_pred: FloatArray) -> FloatArray:
    """[L] the distance the horizon's leg samples keep from the predicted target so that the
    whole leg keeps clearance_m [L]: the chord between samples (relative speed at most
    V_max + |v_target|) and, on the vehicle model's curved legs, their sag a_max h^2 / 8."""
    gap_s = s.dt / s.planner.horizon.leg_samples
    chord = (s.v_max + float(np.linalg.norm(np.asarray(x_pred)[2:4]))) * gap_s
    sag = sag_m(s.a_max, gap_s) if s.planner.vehicle_model else 0.0
    return np.asarray(chord_point_clearance_m(clearance_m, chord) + sag)


def planned_start_velocity(
    s: Scenario, prev_xy: FloatArray, measured_v: FloatArray, prev_plan: SlotPlan | None
) -> FloatArray:
    """The velocity [M, 2] the horizon's first legs start with: last plan's end velocity where
    the vehicle is within 2 tracking margins (and at least 2 m) of last plan's waypoint, else the
    measured one. The bridge starts each leg from the plan's own end state (position and
    velocity), not from the vehicle's (docs/service.md), so that is what the next leg flies
    from; a measured velocity a few m/s off a hard turn's planned one made the start
    infeasible and IPOPT hit its cap on about a quarter of the live slots."""
    if prev_plan is None or prev_plan.uav_velocity_mps is None:
        return measured_v
    planned_v = np.asarray(prev_plan.uav_velocity_mps, dtype=float)
    if planned_v.shape != measured_v.shape:
        return measured_v
    near = np.linalg.norm(np.asarray(prev_xy) - prev_plan.uav_xy_m, axis=1) <= max(
        2.0, 2 * s.planner.tracking_margin_m
    )
    return np.asarray(np.where(near[:, None], planned_v, measured_v))


def legs_ok(
    s: Scenario, prev_xy: FloatArray, prev_v: FloatArray, xy: FloatArray, v: FloatArray
) -> bool:
    """True if the Hermite legs (prev_xy, prev_v) -> (xy, v) [M, 2] are within a_max and V_max
    (the vehicle model's exact limits, with relative slack LEG_LIMIT_TOLERANCE)."""
    a0, a1 = end_accelerations(prev_xy, prev_v, xy, v, s.dt)
    _, mid, v_end = velocity_control_points(prev_xy, prev_v, xy, v, s.dt)
    acc_ok = max(np.max(np.linalg.norm(a0, axis=1)), np.max(np.linalg.norm(a1, axis=1)))
    speed = max(np.max(np.linalg.norm(mid, axis=1)), np.max(np.linalg.norm(v_end, axis=1)))
    return bool(
        acc_ok <= s.a_max * (1 + LEG_LIMIT_TOLERANCE)
        and speed <= s.v_max * (1 + LEG_LIMIT_TOLERANCE)
    )


AT_CAP_NOTE = "its last iterate kept (feasible, lower)"
"""In a slot's note: IPOPT stopped at its cap on an iterate that is a better horizon plan."""

START_FEASIBILITY_TOL = 1e-9
"""Slack (the NLP's scaled units) within which a start meets the horizon's rows."""

CAP_FEASIBILITY_TOL = 1e-7
"""Slack (the NLP's scaled units) of a capped iterate's horizon constraints: IPOPT's converged
answers meet them to its constr_viol_tol, 1e-8; the flown slot meets the exact check."""


def kept_at_cap(
    nlp: HorizonNLP,
    sol: HorizonSolution,
    data: HorizonSlotData,
    start_infeasible: bool,
    start_value: float,
    value: Callable[[FloatArray, FloatArray], float],
) -> bool:
    """Whether IPOPT's last iterate at its iteration cap is kept: it meets every horizon
    constraint and is below a feasible start's objective. IPOPT's iterates keep the variable
    bounds but may leave the constraint rows; from the acceleration phase's starts it often makes
    most of its descent inside them and then creeps, and where its last iterate meets them it is
    a better plan than the start (the flown slot still passes the exact check, as a converged
    answer does)."""
    if sol.status != "Maximum_Iterations_Exceeded":
        return False
    velocity = sol.uav_velocity_mps if nlp.vehicle_model else None
    if not nlp.satisfies(sol.uav_xy_m, velocity, sol.bandwidth_share, data, CAP_FEASIBILITY_TOL):
        return False
    return start_infeasible or value(sol.uav_xy_m, sol.bandwidth_share) < start_value


def horizon_nlp(kit: SolverKit, pair_band: int | None = None, n_targets: int = 1) -> HorizonNLP:
    """The kit's receding-horizon NLP (planning/horizon_nlp.py) with the UAV-UAV rows of
    pair_band (None: every pair) for n_targets targets, built on first use and kept."""
    M = kit.scenario.M
    band = M - 1 if pair_band is None else min(pair_band, M - 1)
    key = "horizon" if band == M - 1 else f"horizon-band{band}"
    if n_targets > 1:
        key += f"-targets{n_targets}"
    return kit.built(
        key,
        lambda: HorizonNLP(
            kit.scenario, kit.n_keep_out, kit.solve_lock, kit.ipopt, band, n_targets
        ),
    )


def kit_pair_bands(kit: SolverKit) -> tuple[int, ...]:
    """The bands of the kit's horizon NLPs (planning/pairs.py, `pair_bands`)."""
    s = kit.scenario
    return pair_bands(s.M, s.planner.horizon.pair_band)


def ordered_nlp(
    kit: SolverKit, *, prev_xy_m: FloatArray, prev_velocity_mps: FloatArray, n_targets: int = 1
) -> tuple[HorizonNLP | None, IntArray, int]:
    """(the NLP for n_targets targets of the narrowest band that the pairs within reach of the
    UAVs at prev_xy_m [M, 2] flying prev_velocity_mps [M, 2] fit, or None if none does; the
    fleet's order for it: UAV order[a] in the NLP's UAV slot a; the order's bandwidth). A fleet
    with the full problem alone keeps its own order."""
    s = kit.scenario
    bands = kit_pair_bands(kit)
    if bands == (s.M - 1,):
        return horizon_nlp(kit, n_targets=n_targets), np.arange(s.M), s.M - 1
    narrowest = horizon_nlp(kit, bands[0], n_targets)
    velocity = prev_velocity_mps if s.planner.vehicle_model else np.zeros((s.M, 2))
    reach = horizon_reach_m(velocity, s.v_max, s.dt, narrowest.length)
    within = pairs_within_reach(prev_xy_m, reach, narrowest.pair_clearance_m)
    order, width = banded_order(within)
    fits = [band for band in bands if band >= width]
    return (horizon_nlp(kit, fits[0], n_targets) if fits else None), order, width


Start = tuple[FloatArray, FloatArray, FloatArray]
"""A horizon start: waypoints [L, M, 2] (m), velocities [L, M, 2] (m/s), shares [L, M]."""


class PerSlotPlan:
    """The slot's per-slot plan (`proposed`), computed on first need and kept: a start of the
    horizon and its fallback (docs/model.md, "Start points")."""

    def __init__(self, compute: Callable[[], SlotPlan], started_s: float) -> None:
        """compute: plans it; started_s: the perf_counter time the slot's planning started."""
        self._compute = compute
        self._started_s = started_s
        self.computed: SlotPlan | None = None
        """The plan, once computed (None: it was not needed)."""

    def get(self) -> SlotPlan:
        """The plan, computed now if it was not yet."""
        if self.computed is None:
            self.computed = self._compute()
        return self.computed

    def instead(self, why: str, kind: str) -> SlotPlan:
        """The plan flown instead of the horizon's answer, saying why (planning/fallback.py,
        `per_slot_instead`; kind: the fallback kind the summaries count)."""
        plan = self.get()
        return per_slot_instead(plan, "horizon", why, kind, time.perf_counter() - self._started_s)


@dataclass(frozen=True)
class HorizonValue:
    """The horizon objective of a plan (xy [L, M, 2] m, eta [L, M]): sum_l weights_l tr(PCRB_l)
    by the bound's recursion (`horizon_bound_traces`) from each target's prediction x_pred
    [T, 4] and prior information J_pred [T, 4, 4] (and path offsets [T, L, 4], None: none),
    the targets' traces summed with their weights target_weight [T] (None: one target,
    unweighted)."""

    s: Scenario
    weights: FloatArray
    x_pred: FloatArray
    J_pred: FloatArray
    sensing: SensingParams
    target_weight: FloatArray | None = None
    offsets: FloatArray | None = None

    @classmethod
    def of(
        cls,
        s: Scenario,
        x_pred: FloatArray,
        J_pred: FloatArray,
        sensing: SensingParams,
        offsets: FloatArray | None = None,
    ) -> HorizonValue:
        """The value of s's horizon (its weights, `horizon_weights`) for the lead target's
        prediction x_pred [4], prior information J_pred [4, 4] and path offsets [L, 4]."""
        cfg = s.planner.horizon
        weights = horizon_weights(cfg.length, cfg.discount, cfg.terminal_weight)
        return cls(s, weights, x_pred, J_pred, sensing, None, offsets)

    @classmethod
    def of_targets(
        cls, s: Scenario, targets: tuple[TargetBelief, ...], sensing: SensingParams
    ) -> HorizonValue:
        """The value for the targets: one target's `of` (its weight not applied: it scales
        the objective only, which the NLP divides by its start value), several weighted."""
        cfg = s.planner.horizon
        if len(targets) == 1:
            b = targets[0]
            offsets = b.path_offsets(cfg.length)
            return cls.of(s, b.state_pred, b.prior_information, sensing, offsets)
        weights = horizon_weights(cfg.length, cfg.discount, cfg.terminal_weight)
        return cls(
            s,
            weights,
            np.array([b.state_pred for b in targets], dtype=float),
            np.array([b.prior_information for b in targets], dtype=float),
            sensing,
            np.array([b.weight for b in targets], dtype=float),
            target_offsets(targets, cfg.length),
        )

    def target_traces(self, xy: FloatArray, eta: FloatArray) -> FloatArray:
        """tr(PCRB) [T, L] of each target along the plan."""
        x_pred = np.asarray(self.x_pred, dtype=float).reshape(-1, 4)
        J_pred = np.asarray(self.J_pred, dtype=float).reshape(-1, 4, 4)
        offsets: list[FloatArray | None] = [None] * len(x_pred)
        if self.offsets is not None:
            offsets = list(np.asarray(self.offsets, dtype=float).reshape(len(x_pred), -1, 4))
        return np.array(
            [
                horizon_bound_traces(self.s, J, x, xy, eta, self.sensing, o)
                for x, J, o in zip(x_pred, J_pred, offsets, strict=True)
            ]
        )

    def traces(self, xy: FloatArray, eta: FloatArray) -> FloatArray:
        """tr(PCRB) [L] along the plan: one target's, or the targets' weighted sum."""
        if self.target_weight is None:
            return horizon_bound_traces(
                self.s, self.J_pred, self.x_pred, xy, eta, self.sensing, self.offsets
            )
        return np.asarray(self.target_weight @ self.target_traces(xy, eta))

    def __call__(self, xy: FloatArray, eta: FloatArray) -> float:
        return float(self.weights @ self.traces(xy, eta))


@dataclass(frozen=True)
class RankedStarts:
    """A slot's horizon starts, ranked. starts: each with shares that meet 14a (the fleet's
    order); in_order: the same in the NLP's order; data, ordered: the slot's NLP data in the
    fleet's and the NLP's order; bs_of_uav [M]: the association the horizon keeps; scores:
    (rank, value, index) sorted, feasible starts first (rank 0), then, under the vehicle model,
    the nearer to feasible (rank: the largest row missed), else the lower objective
    (docs/model.md, "Start points"); shifted: the index of last slot's horizon shifted among
    the starts, None if it is not one."""

    starts: list[Start]
    in_order: list[Start]
    data: HorizonSlotData
    ordered: HorizonSlotData
    bs_of_uav: IntArray
    scores: list[tuple[float, float, int]]
    shifted: int | None


@dataclass(frozen=True)
class HorizonSlot:
    """What each step of one slot's horizon plan reads: the scenario s, the slot's input inp,
    the NLP and the fleet's order for it (UAV order[a] in the NLP's UAV slot a), the velocity
    [M, 2] (m/s) the first legs start with (`planned_start_velocity`), the lead target's
    predicted covariance [4, 4], the horizon objective and the targets in the NLP's order
    (`nlp_targets`)."""

    s: Scenario
    inp: SlotInput
    nlp: HorizonNLP
    order: IntArray
    start_velocity_mps: FloatArray
    target_cov_pred: FloatArray
    value: HorizonValue
    targets: tuple[TargetBelief, ...] | None = None

    def slot_data(self, bs_of_uav: IntArray, waypoints_xy_m: FloatArray) -> HorizonSlotData:
        """The NLP's data with the association bs_of_uav [M] and the control BSs nearest
        waypoints_xy_m [M, 2] (`horizon_slot_data`)."""
        inp, velocity, cov = self.inp, self.start_velocity_mps, self.target_cov_pred
        length = self.nlp.length
        return horizon_slot_data(
            self.s, inp, velocity, cov, bs_of_uav, waypoints_xy_m, length, self.targets
        )

    def velocities(self, v: FloatArray | None) -> FloatArray | None:
        """v for the NLP: itself under the vehicle model, else None."""
        return v if self.nlp.vehicle_model else None

    def ranked(
        self,
        candidates: list[Start],
        data: HorizonSlotData,
        bs_of_uav: IntArray,
        shifted: int | None,
    ) -> RankedStarts:
        """The candidates, their shares moved to meet 14a (`_shares_meeting_rates`), ranked."""
        s, nlp, order = self.s, self.nlp, self.order
        link_m = nlp.margins.link_m
        starts = [
            (q, v, _shares_meeting_rates(s, q, e, data.serving_xy, link_m))
            for q, v, e in candidates
        ]
        # A permutation of the UAV axis, which the value ignores.
        in_order = [(q[:, order], v[:, order], e[:, order]) for q, v, e in starts]
        ordered = data.in_order(order)
        scores = []
        for i, (q, v, e) in enumerate(in_order):
            miss = nlp.violation(q, self.velocities(v), e, ordered)
            rank = 0.0 if miss <= START_FEASIBILITY_TOL else miss if nlp.vehicle_model else 1.0
            scores.append((rank, self.value(q, e), i))
        return RankedStarts(starts, in_order, data, ordered, bs_of_uav, sorted(scores), shifted)


def shifted_alone(slot: HorizonSlot, kit: SolverKit, shifted: Start) -> RankedStarts | None:
    """Last slot's horizon shifted as the only start, with the slot's own association, where
    it meets the rows (None otherwise): the per-slot plan was the lower start on few slots
    (docs/model.md, "Start points") and costs a third of a slot."""
    assoc = slot_association(slot.inp, kit)
    ranked = slot.ranked([shifted], slot.slot_data(assoc, shifted[0][0]), assoc, 0)
    return None if ranked.scores[0][0] > 0 else ranked


def with_per_slot(slot: HorizonSlot, base: SlotPlan, shifted: Start | None) -> RankedStarts:
    """The per-slot plan `base` continued at constant velocity (`_continue`) and, if there is
    one, last slot's horizon shifted, ranked, with base's association. An infeasible per-slot
    plan (its best effort) is a start too: the horizon's legs reach farther in one slot than
    the per-slot method's (a_max against a_max / 4 of velocity change), and its answer flies
    only if its first slot passes the exact check."""
    s = slot.s
    L, dt = slot.nlp.length, s.dt
    data = slot.slot_data(base.bs_of_uav, base.uav_xy_m)
    v1 = (
        base.uav_velocity_mps
        if base.uav_velocity_mps is not None
        else (base.uav_xy_m - data.prev_xy) / dt
    )
    candidates = [_continue(base.uav_xy_m, v1, base.bandwidth_share, L, dt, s)]
    if shifted is None:
        return slot.ranked(candidates, data, base.bs_of_uav, None)
    return slot.ranked([*candidates, shifted], data, base.bs_of_uav, len(candidates))


def solve_best(slot: HorizonSlot, ranked: RankedStarts) -> HorizonSolution:
    """The NLP solved from the best-ranked start (in its order), from last slot's multipliers
    when that start is last slot's horizon shifted and they are of the same order."""
    first = ranked.scores[0][2]
    start = ranked.in_order[first]
    prev_plan = slot.inp.prev_plan
    duals = None
    if ranked.shifted == first and prev_plan is not None and prev_plan.horizon is not None:
        duals = prev_plan.horizon.duals
    if duals is not None and not np.array_equal(duals.order, slot.order):
        duals = None
    return slot.nlp.solve(start[0], slot.velocities(start[1]), start[2], ranked.ordered, duals)


@dataclass(frozen=True)
class HorizonAnswer:
    """The horizon plan to fly if its first slot passes the checks: sol in the fleet's order,
    the multipliers for the next slot's warm start (None when the start was kept), and what the
    report says of the solve."""

    sol: HorizonSolution
    duals: HorizonDuals | None
    note: str


@dataclass(frozen=True)
class Refusal:
    """Why the horizon's answer is not flown (per_slot_instead's why and kind)."""

    why: str
    kind: str


def answer(
    slot: HorizonSlot, ranked: RankedStarts, sol: HorizonSolution
) -> HorizonAnswer | Refusal:
    """IPOPT's answer sol (the NLP's order) kept if it succeeded or stopped at its cap on a
    better feasible iterate (`kept_at_cap`), in the fleet's order; its start instead where it
    ended above a feasible start (a local solver may: the start is a valid horizon then)."""
    nlp, order = slot.nlp, slot.order
    start_miss, start_value, first = ranked.scores[0]
    start_infeasible = start_miss > 0
    note = f"IPOPT {sol.status} in {sol.iterations} it"
    if not sol.success:
        if not kept_at_cap(nlp, sol, ranked.ordered, start_infeasible, start_value, slot.value):
            return Refusal(f"IPOPT {sol.status} after {sol.iterations} it", f"IPOPT {sol.status}")
        note += f", {AT_CAP_NOTE}"
    duals: HorizonDuals | None = HorizonDuals(
        sol.lam_x, sol.lam_g, sol.f_scale, nlp.pair_band, order
    )
    sol = sol.in_order(np.argsort(order))
    start = ranked.starts[first]
    if not start_infeasible and slot.value(sol.uav_xy_m, sol.bandwidth_share) > start_value:
        sol = replace(
            sol,
            uav_xy_m=start[0],
            uav_velocity_mps=slot.velocities(start[1]),
            bandwidth_share=start[2],
        )
        duals = None
        note += ", its start kept (lower)"
    return HorizonAnswer(sol, duals, note)


def first_slot_refusal(
    slot: HorizonSlot, data: HorizonSlotData, sol: HorizonSolution
) -> Refusal | None:
    """Why the plan's first slot may not fly (the exact check of 14a-14j, SlotConstraints, as
    every method's plan passes it, 14j against every target of the slot along its own path;
    the vehicle model's leg limits, `legs_ok`), None if it may."""
    s = slot.s
    xy1, eta1 = sol.uav_xy_m[0], sol.bandwidth_share[0]
    lead = np.asarray(slot.inp.lead.state_pred, dtype=float)
    cons = SlotConstraints(
        data.prev_xy,
        data.serving_xy,
        s.bs_xy,
        lead[:2],
        s,
        keep_out_xy=slot.inp.keep_out_xy_m,
        target_clearance_m=float(predicted_clearances(s, slot.target_cov_pred, 1)[0]),
        target_velocity_mps=lead[2:4],
        target_motion=slot.inp.lead.motion,
        other_targets=moving_targets(slot.inp.targets[1:], s),
    )
    if not bool(cons.feasible(xy1[None], eta1[None])[0]):
        bad = ", ".join(cons.describe_violations(xy1, eta1))
        return Refusal(f"IPOPT's answer violates {bad}", "answer infeasible")
    if sol.uav_velocity_mps is not None:
        velocity1 = sol.uav_velocity_mps[0]
        if not legs_ok(s, data.prev_xy, slot.start_velocity_mps, xy1, velocity1):
            return Refusal("IPOPT's first leg breaks the vehicle limits", "leg limits")
    return None


def horizon_slot_plan(
    slot: HorizonSlot,
    ranked: RankedStarts,
    kept: HorizonAnswer,
    base: SlotPlan | None,
    started_s: float,
) -> SlotPlan:
    """The slot's plan: the horizon's first slot flown, the whole horizon carried for the next
    slot's warm start; its report the per-slot plan's (base, None if it was not computed) with
    the horizon's summary and solve_s since started_s (perf_counter, s)."""
    sol = kept.sol
    start_value = ranked.scores[0][1]
    traces = slot.value.traces(sol.uav_xy_m, sol.bandwidth_share)
    summary = (
        f"horizon: {kept.note}, objective {start_value:.6g} -> "
        f"{float(slot.value.weights @ traces):.6g}"
    )
    base_report = base.report if base is not None else SolveReport(status="ok")
    report = replace(
        base_report,
        status="ok",  # also where the per-slot plan was its best effort
        fallback="",
        reason="",
        solve_s=time.perf_counter() - started_s,
        polish=summary if base is not None else f"{summary}, from the shifted horizon alone",
        objective_history=(*base_report.objective_history, float(traces[0])),
    )
    velocity = sol.uav_velocity_mps
    return SlotPlan(
        uav_xy_m=sol.uav_xy_m[0],
        bs_of_uav=ranked.bs_of_uav,
        bandwidth_share=sol.bandwidth_share[0],
        pcrb_trace=float(traces[0]),
        report=report,
        uav_velocity_mps=None if velocity is None else velocity[0],
        horizon=HorizonPlan(
            uav_xy_m=sol.uav_xy_m,
            uav_velocity_mps=sol.uav_velocity_mps,
            bandwidth_share=sol.bandwidth_share,
            pcrb_trace=traces,
            duals=kept.duals,
        ),
    )


def plan_horizon(
    inp: SlotInput, per_slot: Callable[[], SlotPlan], kit: SolverKit, started_s: float
) -> SlotPlan:
    """The horizon plan of this slot, or the polished per-slot plan (already feasible or already
    the best effort) with the reason when the horizon's answer is not kept (planning/fallback.py,
    `per_slot_instead`).

    per_slot: computes the `proposed` plan of inp, called only when it is needed: as a start
    when last slot's horizon shifted is none or does not meet the horizon's rows, and as the
    fallback (docs/model.md, "Receding horizon", "Start points"); started_s: the perf_counter
    time the slot's planning started (for solve_s)."""
    s = kit.scenario
    base = PerSlotPlan(per_slot, started_s)
    lead, prev_plan = inp.lead, inp.prev_plan
    J_pred, cov = lead.prior_information, lead.cov_pred
    target_cov_pred = scaled_inverse(J_pred) if cov is None else cov
    v = inp.prev_velocity_mps
    prev_v = np.zeros((s.M, 2)) if v is None else np.asarray(v)
    prev_v = planned_start_velocity(s, inp.prev_xy_m, prev_v, prev_plan)
    targets = nlp_targets(inp)
    # The NLP and the fleet's order depend on the UAVs' start only (not on the association).
    nlp, order, width = ordered_nlp(
        kit, prev_xy_m=inp.prev_xy_m, prev_velocity_mps=prev_v, n_targets=len(targets)
    )
    if nlp is None:
        why = f"its pairs within reach need a band of {width} (pair_band {kit_pair_bands(kit)})"
        return base.instead(why, "pairs beyond the band")
    if len(targets) == 1:
        offsets = lead.path_offsets(s.planner.horizon.length)
        value = HorizonValue.of(s, lead.state_pred, J_pred, kit.sensing, offsets)
        slot = HorizonSlot(s, inp, nlp, order, prev_v, target_cov_pred, value)
    else:
        value = HorizonValue.of_targets(s, targets, kit.sensing)
        slot = HorizonSlot(s, inp, nlp, order, prev_v, target_cov_pred, value, targets)
    shifted = None
    if prev_plan is not None and prev_plan.horizon is not None:
        shifted = _shifted(prev_plan.horizon, nlp.length, s.M, s.dt, s)
    ranked = None if shifted is None else shifted_alone(slot, kit, shifted)
    if ranked is None:
        ranked = with_per_slot(slot, base.get(), shifted)
    kept = answer(slot, ranked, solve_best(slot, ranked))
    if isinstance(kept, Refusal):
        return base.instead(kept.why, kept.kind)
    refusal = first_slot_refusal(slot, ranked.data, kept.sol)
    if refusal is not None:
        return base.instead(refusal.why, refusal.kind)
    return horizon_slot_plan(slot, ranked, kept, base.computed, started_s)


def proposed_plan(inp: SlotInput, kit: SolverKit) -> SlotPlan:
    """The `proposed` plan of inp with its end velocity (the horizon's per-slot plan)."""
    return with_end_velocity(Proposed().plan(inp, kit), inp, kit.scenario)
