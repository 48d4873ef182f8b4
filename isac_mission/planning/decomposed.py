"""The receding horizon decomposed by targets (`planner.horizon.decompose: targets`).

The centralized horizon (planning/horizon.py, `plan_horizon`) solves one IPOPT NLP for the whole
fleet of M UAVs and all T targets; its cost grows much faster than M. Here the slot's problem is
split into groups of UAVs that inform the same targets, each group is planned by the unchanged
horizon on a sub-scenario of its own UAVs, and the groups' plans are put back together:

1. **Grouping** (`group_by_targets`, pure). A UAV's Fisher information about a target falls with
   about the fourth power of range, so each UAV joins the group of its nearest target (of those
   with weight > 0; the predicted position `state_pred[:2]`); a target nearest to no UAV joins
   the group of the UAV nearest to it (so every target of the objective is planned for, and its
   clearance kept, by some group). Groups are then merged while they can couple within the
   horizon: a UAV of one within reach of a UAV of the other (the horizon's own rule,
   planning/pairs.py: start distance below the pair rows' distance + both reaches + 1 m), a UAV
   of one within its reach + the clearance of a target of the other (from the target's
   predicted path over the horizon), or two targets whose clearance regions along their paths
   overlap. Groups are ordered by their smallest UAV index; UAVs and targets in index order.
2. **Sub-problems**. Each group is planned by `plan_horizon` on `s.with_changes(M=|g|,
   uav_start_xy=..., B=B * budget_g, planner: association keep, decompose none)`, with the
   group's UAVs, targets, shares and last plan. The couplings through the shared resources:
   (a) *bandwidth*: the fleet's shares sum to 1 at every horizon slot (the NLP's
   `sum1(eta) == 1` row). Group g gets budget_g = |g| / M of the band (`fleet_share_budgets`;
   an explicit split may be given); its sub-problem has B' = B budget_g and its shares eta'
   sum to 1, and the fleet's shares are eta = budget_g eta'. Every number the planner uses
   depends on the share only through eta B: the rate eta B log2(1 + SNR) (14a) and the range
   information (eta B)^2 / alpha_d (eq. 8, with the scenario's alpha_d kept), so the
   sub-problem is exactly the fleet's problem restricted to the group with its shares summing
   to budget_g, and its rate rows hold for the scaled shares (checked again below). The
   split is fixed for the slot: it does not follow the targets' weights (an operator's
   priorities weigh targets within a group only; a group of one target plans it whatever its
   weight, as the one-target horizon does) nor the groups' marginal value of bandwidth, which
   the centralized NLP balances; last slot's group sums are no better (a decomposed plan's
   group sums are its budgets, a fixed point). A price-based update of the split is left.
   (b) *BS capacity N_a*: the slot's association (`slot_association`, P1-F.1 from q_n-1, or
   last slot's with `association: keep`) is computed ONCE for the whole fleet, and each group
   is given its UAVs' BSs as `prev_bs_of_uav` with `association: keep`, so no BS serves more
   than N_a UAVs across groups. (c) *UAV-UAV distances across groups*: by the merge rule no
   pair of two groups is within reach, so the centralized problem's rows between them are
   implied by the others (as `pairs_within_reach` argues for the pair band); the other groups'
   UAVs are NOT added as keep-out points (a keep-out point is a fixed point and would change
   the NLP's size per group, while by the rule they could never bind). The fleet's own
   keep-out points (other tracks, vehicles outside the plan) are passed to every group.
   The groups' objectives are independent up to the information a UAV gathers on another
   group's target (from beyond the merge distance, a (range ratio)^-4 fraction): that term is
   dropped, the decomposition's only approximation besides the fixed bandwidth split.
3. **Recombine and check** (`recombine`, `fleet_refusal`): the groups' first slots ([M, 2]
   waypoints, [M] shares scaled by the budgets, [M] BSs, [M, 2] end velocities) and horizons
   ([L, M, 2], [L, M]) are put back in fleet order; the horizon's predicted tr(PCRB) [L] is
   re-evaluated on the whole fleet's plan (every UAV's information on every target); the
   horizon's multipliers cannot be recombined (each is one sub-NLP's) and are dropped
   (`HorizonPlan.duals` None: every group's next solve starts cold in its multipliers, its
   primal start still last slot's horizon shifted, restricted to the group with its shares
   renormalised to the group). The whole plan then passes the slot's exact check
   (`SlotConstraints.feasible`: 14a-14j against every target along every leg, plus the shares'
   sum, the BS capacity and, under the vehicle model, the leg limits); a group whose horizon
   fell back, or a plan that fails the check, returns the centralized per-slot plan
   (`proposed`) with the reason (planning/fallback.py, `per_slot_instead`), as the horizon
   does. One group is the centralized horizon exactly (the existing code, unchanged).

Each group's sub-kit (SolverKit of its sub-scenario: the horizon's NLPs per target count, the
polish, the convex problems) is built on first use and cached in the `DecomposedHorizon` kept
in the fleet's kit (`plan_decomposed`), per (group size, bandwidth budget): B is built into the
NLPs; the target count is the sub-kit's own cache key (`horizon_nlp`).

**Where the groups are solved** (`DecomposedHorizon.executor`). By default (None) in this
process, one after the other, as above. A caller may set a `GroupExecutor` instead (the fleet
kit's planner: `use_group_executor(kit, executor)`; renewed kits share it): each group's
sub-problem is then a `GroupJob` (its sub-scenario, its SlotInput, the kit's settings and a
fingerprint of the sub-scenario, `sub_kit_fingerprint`: picklable data only), the jobs are
handed to `executor.map` together and their plans gathered in group order, then recombined and
checked as above. What runs a job, wherever the executor runs it, is `solve_group_job`: the
sub-kit from this process's own cache (`worker_sub_kit`, by fingerprint; a worker process
builds each sub-kit once and keeps it, nothing of it crosses the wire), then `plan_horizon` as
in the serial path, so a job's plan is the serial path's. If the executor raises (a job raised,
a worker died, the slot's deadline passed: the executor says which), the slot flies the
centralized per-slot plan with the reason and the fallback `horizon: decomposed worker lost`
(`WORKER_LOST`). The executor is made and owned outside planning/ (the Dask one:
isac_mission/planner_cluster.py).

Pure: no clock but perf_counter for solve_s, no RNG, no I/O (an executor is the caller's port;
the per-process sub-kit cache of `worker_sub_kit` is state, not I/O).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
import weakref
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Protocol

import numpy as np

from isac_mission.config import Scenario
from isac_mission.planning.fallback import per_slot_instead
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.horizon import (
    HorizonValue,
    belief_cov_pred,
    legs_ok,
    nlp_targets,
    plan_horizon,
    planned_start_velocity,
    predicted_clearances,
    proposed_plan,
    sample_clearances,
)
from isac_mission.planning.horizon_problem import LegSamples
from isac_mission.planning.kit import SolverKit, changed_fields
from isac_mission.planning.margins import SafetyMargins
from isac_mission.planning.nlp_model import IpoptFactory, plain_ipopt
from isac_mission.planning.pairs import REACH_SLACK_M, horizon_reach_m, pairs_within_reach
from isac_mission.planning.problem import (
    SlotInput,
    belief_clearance_m,
    moving_targets,
    slot_association,
)
from isac_mission.types import FloatArray, HorizonPlan, IntArray, SlotPlan, SolveReport

if TYPE_CHECKING:
    from isac_mission.tracking.beliefs import TargetBelief

DECOMPOSED_KEY = "horizon-decomposed"
"""The key of the `DecomposedHorizon` in the fleet kit's built problems (`SolverKit.built`)."""

SHARE_SUM_TOL = 1e-9
"""How far the recombined shares' sum may be from 1 (14c/14d; the exact check's own slack)."""

WORKER_LOST = "decomposed worker lost"
"""The fallback kind (after `horizon: `) of a slot whose groups' executor failed: a job raised,
a worker died or the slot's deadline passed (`DecomposedHorizon.plan` with an executor)."""

WORKER_KITS_MAX = 16
"""How many sub-kits one process keeps in `worker_sub_kit`'s cache (the oldest dropped)."""


@dataclass(frozen=True)
class Group:
    """One sub-problem: the UAVs (fleet indices, ascending) and the targets (indices into
    SlotInput.targets, ascending) it plans."""

    uavs: tuple[int, ...]
    targets: tuple[int, ...]


class _Sets:
    """Union-find over 0..n-1 (the targets); the smaller index is the root of a union."""

    def __init__(self, n: int) -> None:
        self.parent = list(range(n))

    def find(self, i: int) -> int:
        while self.parent[i] != i:
            self.parent[i] = self.parent[self.parent[i]]
            i = self.parent[i]
        return i

    def union(self, i: int, j: int) -> None:
        a, b = self.find(i), self.find(j)
        if a != b:
            self.parent[max(a, b)] = min(a, b)


def point_path_distance_m(points_xy_m: FloatArray, path_xy_m: FloatArray) -> FloatArray:
    """[N] the distance (m) of each of points_xy_m [N, 2] from the polyline path_xy_m [P, 2] (one
    point: the distance to it)."""
    pts = np.asarray(points_xy_m, dtype=float).reshape(-1, 2)
    path = np.asarray(path_xy_m, dtype=float).reshape(-1, 2)
    if len(path) == 1:
        return np.asarray(np.linalg.norm(pts - path[0], axis=1))
    a, b = path[:-1], path[1:]  # [S, 2] segments
    ab = b - a
    length2 = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    t = np.clip(np.einsum("nsk,sk->ns", pts[:, None] - a[None], ab) / length2, 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    return np.asarray(np.min(np.linalg.norm(pts[:, None] - nearest, axis=-1), axis=1))


def _segments_cross(p: FloatArray, q: FloatArray) -> bool:
    """Whether the polylines p [P, 2] and q [Q, 2] (each at least 2 points) cross."""

    def cross(o: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
        return np.asarray(
            (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1])
            - (a[..., 1] - o[..., 1]) * (b[..., 0] - o[..., 0])
        )

    a0, a1 = p[:-1, None], p[1:, None]
    b0, b1 = q[None, :-1], q[None, 1:]
    d1, d2 = cross(b0, b1, a0), cross(b0, b1, a1)
    d3, d4 = cross(a0, a1, b0), cross(a0, a1, b1)
    return bool(np.any((d1 * d2 < 0) & (d3 * d4 < 0)))


def path_path_distance_m(p_xy_m: FloatArray, q_xy_m: FloatArray) -> float:
    """The smallest distance (m) between the polylines p [P, 2] and q [Q, 2] (0 if they cross)."""
    p = np.asarray(p_xy_m, dtype=float).reshape(-1, 2)
    q = np.asarray(q_xy_m, dtype=float).reshape(-1, 2)
    if len(p) > 1 and len(q) > 1 and _segments_cross(p, q):
        return 0.0
    return float(min(point_path_distance_m(p, q).min(), point_path_distance_m(q, p).min()))


def group_by_targets(
    uav_xy_m: FloatArray,
    reach_m: FloatArray,
    pair_clearance_m: float,
    target_xy_m: FloatArray,
    target_clearance_m: FloatArray,
    target_paths_xy_m: FloatArray | None = None,
    target_weight: FloatArray | None = None,
) -> tuple[Group, ...]:
    """The UAVs at uav_xy_m [M, 2] (m) grouped by the targets they inform (module doc, step 1).

    reach_m [M]: how far each UAV can get from its start within the horizon
    (pairs.horizon_reach_m); pair_clearance_m: the distance the horizon's UAV-UAV rows keep (m);
    target_xy_m [T, 2]: the targets' predicted positions, by which UAVs are assigned;
    target_clearance_m [T]: the largest clearance (m) the horizon keeps from each;
    target_paths_xy_m [T, P, 2]: each target's predicted path over the horizon as a polyline
    (None: the point target_xy_m); target_weight [T]: the targets' weights (None: all 1): a UAV
    joins its nearest target of weight > 0 (any target if none has), a target nearest to no UAV
    the group of its nearest UAV. Groups coupled by a UAV pair within reach, a UAV within reach
    of another group's target's clearance, or two targets' overlapping clearance regions are
    merged. Deterministic: groups ordered by their smallest UAV index, indices ascending."""
    uav = np.asarray(uav_xy_m, dtype=float).reshape(-1, 2)
    reach = np.asarray(reach_m, dtype=float)
    txy = np.asarray(target_xy_m, dtype=float).reshape(-1, 2)
    clearance = np.asarray(target_clearance_m, dtype=float)
    T, M = len(txy), len(uav)
    paths = txy[:, None] if target_paths_xy_m is None else np.asarray(target_paths_xy_m)
    weight = np.ones(T) if target_weight is None else np.asarray(target_weight, dtype=float)
    candidates = np.flatnonzero(weight > 0) if np.any(weight > 0) else np.arange(T)
    distance = np.linalg.norm(uav[:, None] - txy[None], axis=-1)  # [M, T]
    owner = candidates[np.argmin(distance[:, candidates], axis=1)]  # [M]
    sets = _Sets(T)
    for j in range(T):
        if not np.any(owner == j):
            sets.union(j, int(owner[int(np.argmin(distance[:, j]))]))
    within = pairs_within_reach(uav, reach, pair_clearance_m)
    for a, b in zip(*np.nonzero(np.triu(within)), strict=True):
        sets.union(int(owner[a]), int(owner[b]))
    for j in range(T):
        near = point_path_distance_m(uav, paths[j]) < reach + clearance[j] + REACH_SLACK_M
        for m in np.flatnonzero(near):
            sets.union(int(owner[m]), j)
    for i in range(T):
        for j in range(i + 1, T):
            gap = path_path_distance_m(paths[i], paths[j])
            if gap < clearance[i] + clearance[j] + REACH_SLACK_M:
                sets.union(i, j)
    roots = sorted({sets.find(int(owner[m])) for m in range(M)})
    groups = [
        Group(
            tuple(m for m in range(M) if sets.find(int(owner[m])) == r),
            tuple(j for j in range(T) if sets.find(j) == r),
        )
        for r in roots
    ]
    return tuple(sorted(groups, key=lambda g: g.uavs[0]))


def target_paths_xy_m(s: Scenario, targets: tuple[TargetBelief, ...], length: int) -> FloatArray:
    """[T, L + 1, 2] each target's predicted path over the horizon's legs (m): its position at
    the start of slot n (dt before the prediction's instant) and at the ends of slots
    n..n+L-1 (its motion model, plus a manoeuvring belief's offsets)."""
    out = []
    for b in targets:
        offsets = b.path_offsets(length)
        points = [np.asarray(b.position_at(-s.dt), dtype=float)]
        for h in range(length):
            p = np.asarray(b.position_at(h * s.dt), dtype=float)
            points.append(p if offsets is None else p + offsets[h, :2])
        out.append(points)
    return np.asarray(out, dtype=float)


def target_horizon_clearances_m(
    s: Scenario, targets: tuple[TargetBelief, ...], length: int
) -> FloatArray:
    """[T] the largest distance (m) the horizon's leg samples, or the exact check, keep from
    each target over the horizon (horizon.sample_clearances of its grown covariance)."""
    out = []
    for b in targets:
        grown = predicted_clearances(s, belief_cov_pred(b), length)
        sampled = sample_clearances(s, grown, b.state_pred)
        out.append(max(float(np.max(sampled)), belief_clearance_m(b, s)))
    return np.asarray(out)


def slot_groups(s: Scenario, inp: SlotInput, start_velocity_mps: FloatArray) -> tuple[Group, ...]:
    """The slot's groups (`group_by_targets`) for the horizon of s: the UAVs at inp.prev_xy_m
    starting their first legs with start_velocity_mps [M, 2] (the paper's kinematics: at rest),
    the targets of inp.targets."""
    L = s.planner.horizon.length
    velocity = start_velocity_mps if s.planner.vehicle_model else np.zeros((s.M, 2))
    reach = horizon_reach_m(velocity, s.v_max, s.dt, L)
    pair_m = LegSamples.of(s, SafetyMargins.of(s)).pair_clearance_m
    targets = inp.targets
    return group_by_targets(
        inp.prev_xy_m,
        reach,
        pair_m,
        np.array([b.state_pred[:2] for b in targets], dtype=float),
        target_horizon_clearances_m(s, targets, L),
        target_paths_xy_m(s, targets, L),
        np.array([b.weight for b in targets], dtype=float),
    )


def fleet_share_budgets(groups: tuple[Group, ...], n_uavs: int) -> FloatArray:
    """[G] each group's budget of the band: its share of the fleet, |g| / M (sums to 1)."""
    return np.array([len(g.uavs) / n_uavs for g in groups], dtype=float)


def sub_scenario(s: Scenario, start_xy_m: FloatArray, budget: float) -> Scenario:
    """The scenario of a group of len(start_xy_m) UAVs with the band B * budget: the
    association kept from the input (`prev_bs_of_uav`, the fleet's), no further decomposition."""
    horizon = s.planner.horizon.model_copy(update={"decompose": "none"})
    planner = s.planner.model_copy(update={"association": "keep", "horizon": horizon})
    xy = np.asarray(start_xy_m, dtype=float).reshape(-1, 2)
    return s.with_changes(M=len(xy), uav_start_xy=xy, B=s.B * budget, planner=planner)


def _normalised(eta: FloatArray) -> FloatArray:
    """Shares [..., m] scaled to sum to 1 along the last axis (equal where they sum to 0)."""
    e = np.asarray(eta, dtype=float)
    total = e.sum(axis=-1, keepdims=True)
    equal = np.full_like(e, 1.0 / e.shape[-1])
    return np.asarray(np.where(total > 0, e / np.where(total > 0, total, 1.0), equal))


def group_prev_plan(prev: SlotPlan | None, uavs: IntArray, n_uavs: int) -> SlotPlan | None:
    """Last slot's fleet plan restricted to the UAVs `uavs` (fleet indices), its shares and its
    horizon's shares renormalised over them (each horizon slot to 1), without multipliers (they
    are a whole NLP's); None if there is none or it is not of this fleet of n_uavs."""
    if prev is None or len(prev.uav_xy_m) != n_uavs:
        return None
    horizon = None
    if prev.horizon is not None:
        h = prev.horizon
        horizon = HorizonPlan(
            uav_xy_m=h.uav_xy_m[:, uavs],
            uav_velocity_mps=None if h.uav_velocity_mps is None else h.uav_velocity_mps[:, uavs],
            bandwidth_share=_normalised(h.bandwidth_share[:, uavs]),
            pcrb_trace=h.pcrb_trace,
        )
    return dataclasses.replace(
        prev,
        uav_xy_m=prev.uav_xy_m[uavs],
        bs_of_uav=prev.bs_of_uav[uavs],
        bandwidth_share=_normalised(prev.bandwidth_share[uavs]),
        uav_velocity_mps=None if prev.uav_velocity_mps is None else prev.uav_velocity_mps[uavs],
        horizon=horizon,
    )


def group_input(inp: SlotInput, group: Group, bs_of_uav: IntArray) -> SlotInput:
    """The slot input of a group: its UAVs (positions, velocities, shares renormalised, BSs of
    the fleet's association bs_of_uav [M]), its targets (the one of weight > 0 nearest to its
    UAVs first, as the lead; then the others in the input's order), the fleet's keep-out points
    and last plan restricted to it (`group_prev_plan`)."""
    uavs = np.asarray(group.uavs, dtype=int)
    xy = np.asarray(inp.prev_xy_m, dtype=float)[uavs]
    beliefs = [inp.targets[j] for j in group.targets]

    def rank(b: TargetBelief) -> tuple[bool, float]:
        return (b.weight <= 0, float(np.min(np.linalg.norm(xy - b.state_pred[:2], axis=1))))

    lead = min(beliefs, key=rank)
    velocity = inp.prev_velocity_mps
    return SlotInput(
        prev_xy_m=xy,
        prev_bandwidth_share=_normalised(np.asarray(inp.prev_bandwidth_share)[uavs]),
        prev_bs_of_uav=np.asarray(bs_of_uav)[uavs],
        targets=(lead, *(b for b in beliefs if b is not lead)),
        prev_velocity_mps=None if velocity is None else np.asarray(velocity)[uavs],
        keep_out_xy_m=inp.keep_out_xy_m,
        prev_plan=group_prev_plan(inp.prev_plan, uavs, len(inp.prev_xy_m)),
    )


@dataclass(frozen=True)
class GroupPlan:
    """A group's plan: the group, its bandwidth budget (fraction of B), its input and its plan
    (shares summing to 1 over the group)."""

    group: Group
    budget: float
    inp: SlotInput
    plan: SlotPlan


def sub_kit_fingerprint(sub: Scenario, fast: bool, n_keep_out: int) -> str:
    """A stable key (hex SHA-256) of the sub-kit that plans the group scenario `sub` with the
    kit settings fast and n_keep_out: its trace config (JSON, keys sorted) without the UAVs'
    start points (no problem is built on them: one group's kit serves every slot) and R_th (a
    renewed kit takes another: `worker_sub_kit`), with M, B, fast and n_keep_out. Equal keys
    are checked field by field where a kit is reused (`worker_sub_kit`), so a collision costs a
    rebuild, never a wrong kit."""
    config = dict(sub.trace_config())
    config.pop("uav_start_xy", None)
    config.pop("r_th", None)
    text = json.dumps(
        {"config": config, "M": sub.M, "B": sub.B, "fast": fast, "n_keep_out": n_keep_out},
        sort_keys=True,
        default=str,
    )
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class GroupJob:
    """One group's sub-problem as an independent job: picklable data only (numbers and config,
    no solver), what `solve_group_job` plans wherever it runs.

    index: the group's place in the slot's groups (0-based); group: the group; budget: its
    share of the fleet's band (fraction of B); scenario: the group's sub-scenario
    (`sub_scenario`, band B * budget); inp: its SlotInput (`group_input`); fast, n_keep_out:
    the fleet kit's settings (SolverKit); kit_key: `sub_kit_fingerprint` of them (the worker's
    cache key)."""

    index: int
    group: Group
    budget: float
    scenario: Scenario
    inp: SlotInput
    fast: bool
    n_keep_out: int
    kit_key: str


class GroupExecutor(Protocol):
    """Where a slot's groups are solved (module doc, "Where the groups are solved")."""

    def map(self, jobs: Sequence[GroupJob]) -> Sequence[SlotPlan]:
        """Each job's plan (`solve_group_job` of it, wherever it runs), in the jobs' order;
        raises if any job could not be planned (it raised, its worker died, the slot's
        deadline passed), naming why."""
        ...


_WORKER_KITS: dict[str, SolverKit] = {}
"""This process's sub-kits by `sub_kit_fingerprint` (`worker_sub_kit`): in a worker process,
every sub-kit it has planned with; never pickled."""


def worker_sub_kit(job: GroupJob, ipopt: IpoptFactory = plain_ipopt) -> SolverKit:
    """The sub-kit for `job` from this process's cache: the one of its fingerprint where it
    differs from job.scenario in the UAVs' start points only and was built with `ipopt`,
    renewed (its IPOPT problems kept) where it differs in R_th too, else built (no solve
    lock: a worker process plans one job at a time) and kept, the oldest of WORKER_KITS_MAX
    dropped. As `DecomposedHorizon.sub_kit` does for the serial path."""
    cached = _WORKER_KITS.get(job.kit_key)
    if cached is not None and cached.ipopt is ipopt:
        changed = changed_fields(cached.scenario, job.scenario) - {"uav_start_xy"}
        if not changed:
            return cached
        if changed <= {"r_th"}:
            renewed = cached.renewed(cached.scenario.with_changes(r_th=job.scenario.r_th))
            _WORKER_KITS[job.kit_key] = renewed
            return renewed
    _WORKER_KITS.pop(job.kit_key, None)
    while len(_WORKER_KITS) >= WORKER_KITS_MAX:
        _WORKER_KITS.pop(next(iter(_WORKER_KITS)))
    built = SolverKit(job.scenario, fast=job.fast, n_keep_out=job.n_keep_out, ipopt=ipopt)
    _WORKER_KITS[job.kit_key] = built
    return built


def worker_kit_count() -> int:
    """How many sub-kits this process keeps (`worker_sub_kit`)."""
    return len(_WORKER_KITS)


def solve_group_job(job: GroupJob, ipopt: IpoptFactory = plain_ipopt) -> SlotPlan:
    """The plan of one group's job: `plan_horizon` on the job's input with this process's
    sub-kit (`worker_sub_kit`, IPOPT problems built by `ipopt`) and the per-slot plan of that
    kit as its start and fallback, as the serial path plans a group (its solve_s from here)."""
    kit = worker_sub_kit(job, ipopt)
    return plan_horizon(job.inp, partial(proposed_plan, job.inp, kit), kit, time.perf_counter())


def group_jobs(
    inp: SlotInput,
    kit: SolverKit,
    groups: tuple[Group, ...],
    budgets: FloatArray,
    bs_of_uav: IntArray,
) -> list[GroupJob]:
    """The slot's groups as jobs, in group order: each group's input (`group_input`, the
    fleet's association bs_of_uav [M]) and sub-scenario (`sub_scenario`, its budget of
    budgets [G]) with the fleet kit's settings and the sub-kit's fingerprint."""
    jobs = []
    for i, (group, budget) in enumerate(zip(groups, budgets, strict=True)):
        sub_inp = group_input(inp, group, bs_of_uav)
        sub_s = sub_scenario(kit.scenario, sub_inp.prev_xy_m, float(budget))
        key = sub_kit_fingerprint(sub_s, kit.fast, kit.n_keep_out)
        jobs.append(
            GroupJob(i, group, float(budget), sub_s, sub_inp, kit.fast, kit.n_keep_out, key)
        )
    return jobs


def recombine(
    s: Scenario, parts: list[GroupPlan], value: HorizonValue
) -> tuple[FloatArray, FloatArray, IntArray, FloatArray | None, HorizonPlan]:
    """The fleet's (waypoints [M, 2], shares [M] scaled by the budgets, BSs [M], end velocities
    [M, 2] or None, horizon) from the groups' plans, each with a horizon; the horizon's tr(PCRB)
    [L] re-evaluated on the whole fleet (value), its multipliers None."""
    M = s.M
    first = parts[0].plan.horizon
    assert first is not None
    L = len(first.uav_xy_m)
    xy, eta, bs = np.empty((M, 2)), np.empty(M), np.empty(M, dtype=int)
    h_xy, h_eta = np.empty((L, M, 2)), np.empty((L, M))
    vehicle = first.uav_velocity_mps is not None
    velocity = np.empty((M, 2)) if vehicle else None
    h_velocity = np.empty((L, M, 2)) if vehicle else None
    for part in parts:
        idx = np.asarray(part.group.uavs, dtype=int)
        plan, h = part.plan, part.plan.horizon
        assert h is not None
        xy[idx] = plan.uav_xy_m
        eta[idx] = part.budget * np.asarray(plan.bandwidth_share)
        bs[idx] = plan.bs_of_uav
        h_xy[:, idx] = h.uav_xy_m
        h_eta[:, idx] = part.budget * np.asarray(h.bandwidth_share)
        if velocity is not None and h_velocity is not None:
            assert plan.uav_velocity_mps is not None and h.uav_velocity_mps is not None
            velocity[idx] = plan.uav_velocity_mps
            h_velocity[:, idx] = h.uav_velocity_mps
    traces = value.traces(h_xy, h_eta)
    horizon = HorizonPlan(h_xy, h_velocity, h_eta, traces, duals=None)
    return xy, eta, bs, velocity, horizon


def fleet_refusal(
    s: Scenario,
    inp: SlotInput,
    xy: FloatArray,
    eta: FloatArray,
    bs_of_uav: IntArray,
    start_velocity_mps: FloatArray,
    end_velocity_mps: FloatArray | None,
) -> str | None:
    """Why the recombined first slot (xy [M, 2], eta [M], bs_of_uav [M], end velocities [M, 2]
    or None) may not fly, naming the failed constraints; None if it may. The horizon's exact
    check (SlotConstraints.feasible: 14a-14j, 14j against every target along its own path), and
    14c/14d (shares >= 0 summing to 1), the BS capacity N_a, and under the vehicle model the
    legs' limits from start_velocity_mps [M, 2] (`legs_ok`)."""
    lead = np.asarray(inp.lead.state_pred, dtype=float)
    cons = SlotConstraints(
        np.asarray(inp.prev_xy_m, dtype=float),
        s.bs_xy[bs_of_uav],
        s.bs_xy,
        lead[:2],
        s,
        keep_out_xy=inp.keep_out_xy_m,
        target_clearance_m=float(predicted_clearances(s, belief_cov_pred(inp.lead), 1)[0]),
        target_velocity_mps=lead[2:4],
        target_motion=inp.lead.motion,
        other_targets=moving_targets(inp.targets[1:], s),
    )
    bad = []
    if not bool(cons.feasible(xy[None], eta[None])[0]):
        bad += cons.describe_violations(xy, eta)
    if (abs(float(np.sum(eta)) - 1.0) > SHARE_SUM_TOL or np.any(eta < 0)) and (
        "14c/14d shares" not in bad
    ):
        bad.append("14c/14d shares")
    if np.max(np.bincount(bs_of_uav, minlength=s.K)) > s.n_a:
        bad.append(f"BS capacity N_a = {s.n_a}")
    if end_velocity_mps is not None and not legs_ok(
        s, np.asarray(inp.prev_xy_m, dtype=float), start_velocity_mps, xy, end_velocity_mps
    ):
        bad.append("the vehicle's leg limits")
    return None if not bad else ", ".join(bad)


class DecomposedHorizon:
    """The decomposed horizon of one fleet kit: its sub-kits, built on first use and kept per
    (group size, bandwidth budget); each sub-kit keeps its horizon NLPs per target count; and
    where its groups are solved (`executor`)."""

    def __init__(self) -> None:
        self._kits: dict[tuple[int, float], tuple[weakref.ref[SolverKit], SolverKit]] = {}
        self.executor: GroupExecutor | None = None
        """Where the groups are solved (module doc): None, in this process one after the
        other (the sub-kits above); else handed to it as `GroupJob`s (set by the caller:
        `use_group_executor`)."""

    @property
    def kit_count(self) -> int:
        """How many sub-kits are kept."""
        return len(self._kits)

    def sub_kit(self, kit: SolverKit, sub: Scenario) -> SolverKit:
        """The kit for the group scenario `sub` of the fleet kit `kit`: the cached one of the
        same size and band where it differs from `sub` in the UAVs' start points only (which no
        problem is built on) and was made for this fleet kit; renewed (fresh convex problems,
        the same IPOPT problems: `SolverKit.renewed`) for another fleet kit sharing this
        planner (a renewed fleet kit: a timed-out plan's thread may still use the old one's)
        or another R_th (an operator's change); built otherwise (its problems on first use)."""
        key = (sub.M, round(sub.B, 3))
        entry = self._kits.get(key)
        if entry is not None:
            owner, cached = entry
            changed = changed_fields(cached.scenario, sub) - {"uav_start_xy"}
            if not changed and owner() is kit:
                return cached
            if changed <= {"r_th"}:
                renewed = cached.renewed(cached.scenario.with_changes(r_th=sub.r_th))
                self._kits[key] = (weakref.ref(kit), renewed)
                return renewed
        built = SolverKit(
            sub,
            fast=kit.fast,
            n_keep_out=kit.n_keep_out,
            solve_lock=kit.solve_lock,
            ipopt=kit.ipopt,
        )
        self._kits[key] = (weakref.ref(kit), built)
        return built

    def plan(
        self,
        inp: SlotInput,
        kit: SolverKit,
        started_s: float,
        budgets: FloatArray | None = None,
    ) -> SlotPlan:
        """The slot's decomposed horizon plan (module doc), or the centralized per-slot plan
        with the reason where a group's horizon fell back or the recombined plan fails the
        exact check. budgets [G]: the groups' shares of the band (None: |g| / M,
        `fleet_share_budgets`); started_s: the perf_counter time planning began (solve_s).
        With an `executor`, the groups are solved by it (`_planned_on`), else here in turn."""
        s = kit.scenario
        v = inp.prev_velocity_mps
        measured = np.zeros((s.M, 2)) if v is None else np.asarray(v, dtype=float)
        start_velocity = planned_start_velocity(s, inp.prev_xy_m, measured, inp.prev_plan)
        groups = slot_groups(s, inp, start_velocity)
        if len(groups) == 1:
            return plan_horizon(inp, partial(proposed_plan, inp, kit), kit, started_s)
        shares = fleet_share_budgets(groups, s.M) if budgets is None else np.asarray(budgets)
        if len(shares) != len(groups) or abs(float(shares.sum()) - 1.0) > SHARE_SUM_TOL:
            raise ValueError(f"{len(groups)} groups need budgets summing to 1, got {shares}")
        assoc = slot_association(inp, kit)
        executor = self.executor
        if executor is not None:
            jobs = group_jobs(inp, kit, groups, shares, assoc)
            return self._planned_on(executor, jobs, inp, kit, started_s, assoc, start_velocity)
        parts = []
        for group, budget in zip(groups, shares, strict=True):
            sub_inp = group_input(inp, group, assoc)
            sub_s = sub_scenario(s, sub_inp.prev_xy_m, float(budget))
            sub_kit = self.sub_kit(kit, sub_s)
            plan = plan_horizon(
                sub_inp, partial(proposed_plan, sub_inp, sub_kit), sub_kit, time.perf_counter()
            )
            parts.append(GroupPlan(group, float(budget), sub_inp, plan))
        return self._recombined(inp, kit, started_s, parts, assoc, start_velocity)

    def _planned_on(
        self,
        executor: GroupExecutor,
        jobs: list[GroupJob],
        inp: SlotInput,
        kit: SolverKit,
        started_s: float,
        assoc: IntArray,
        start_velocity: FloatArray,
    ) -> SlotPlan:
        """The groups' jobs solved by `executor` and recombined (`_recombined`); if it raises
        or answers with another number of plans, the centralized per-slot plan with the
        fallback `horizon: decomposed worker lost` and the error as the reason."""
        try:
            plans = list(executor.map(jobs))
            if len(plans) != len(jobs):
                raise RuntimeError(f"{len(plans)} plans for {len(jobs)} groups")
        except Exception as err:  # whatever the executor met, the slot flies the per-slot plan
            why = f"decomposed: the groups' executor failed ({type(err).__name__}: {err})"
            base = proposed_plan(inp, kit)
            return per_slot_instead(
                base, "horizon", why, WORKER_LOST, time.perf_counter() - started_s
            )
        parts = [
            GroupPlan(job.group, job.budget, job.inp, plan)
            for job, plan in zip(jobs, plans, strict=True)
        ]
        return self._recombined(inp, kit, started_s, parts, assoc, start_velocity)

    def _recombined(
        self,
        inp: SlotInput,
        kit: SolverKit,
        started_s: float,
        parts: list[GroupPlan],
        assoc: IntArray,
        start_velocity: FloatArray,
    ) -> SlotPlan:
        """The groups' plans as one, or the centralized per-slot plan saying why not."""
        s = kit.scenario

        def instead(why: str, kind: str) -> SlotPlan:
            base = proposed_plan(inp, kit)
            return per_slot_instead(base, "horizon", why, kind, time.perf_counter() - started_s)

        for i, part in enumerate(parts):
            r = part.plan.report
            if r.fallback or r.status != "ok" or part.plan.horizon is None:
                why = r.reason or r.fallback or r.status
                return instead(
                    f"decomposed: group {i + 1} (UAVs {list(part.group.uavs)}): {why}",
                    "decomposed group fell back",
                )
        value = HorizonValue.of_targets(s, nlp_targets(inp), kit.sensing)
        xy, eta, bs, velocity, horizon = recombine(s, parts, value)
        if not np.array_equal(bs, assoc):
            return instead("decomposed: a group changed the fleet's association", "association")
        bad = fleet_refusal(s, inp, xy, eta, bs, start_velocity, velocity)
        if bad is not None:
            return instead(f"decomposed answer violates {bad}", "decomposed answer infeasible")
        summary = "; ".join(
            f"group {i + 1} (UAVs {list(p.group.uavs)}, targets {list(p.group.targets)}, "
            f"band {p.budget:.4g}): {p.plan.report.polish}"
            for i, p in enumerate(parts)
        )
        traces = horizon.pcrb_trace
        report = SolveReport(
            status="ok",
            solve_s=time.perf_counter() - started_s,
            polish=f"horizon decomposed into {len(parts)} groups, objective "
            f"{float(value.weights @ traces):.6g}: {summary}",
            polish_iterations=sum(p.plan.report.polish_iterations for p in parts),
            objective_history=(float(traces[0]),),
        )
        return SlotPlan(
            uav_xy_m=xy,
            bs_of_uav=bs,
            bandwidth_share=eta,
            pcrb_trace=float(traces[0]),
            report=report,
            uav_velocity_mps=velocity,
            horizon=horizon,
        )


def plan_decomposed(
    inp: SlotInput, kit: SolverKit, started_s: float, budgets: FloatArray | None = None
) -> SlotPlan:
    """The decomposed horizon plan of inp with the fleet kit `kit` (its `DecomposedHorizon`
    built on first use and kept in the kit), module doc; budgets [G] as
    `DecomposedHorizon.plan`."""
    planner = kit.built(DECOMPOSED_KEY, DecomposedHorizon)
    return planner.plan(inp, kit, started_s, budgets)


def use_group_executor(kit: SolverKit, executor: GroupExecutor | None) -> None:
    """Solve the groups of the fleet kit `kit`'s decomposed horizon on `executor` from its
    next plan on (None: in this process again, the default). The executor is kept in the
    kit's `DecomposedHorizon`, which renewed kits share (`SolverKit.renewed`); the kits of the
    smaller fleets (planning/fleet.KitCache's) take it from the full fleet's kit."""
    kit.built(DECOMPOSED_KEY, DecomposedHorizon).executor = executor
