"""`nearest`: the pursuit benchmark. Each UAV closes on its nearest confirmed track as far as one
slot and its links allow; the shares are ABA's (docs/model.md, "Algorithm 1 and P1.2 details").

Per slot, on the slot problem every method shares (planning/problem.py):

1. **The goal.** UAV m's target is the track of `SlotInput.targets` whose predicted position at
   the slot's end (`state_pred[:2]`) is nearest to where the UAV is now (q_{n-1}); ties go to
   the earlier track. Several UAVs may pick the same track (no one-to-one assignment). The goal is
   that position, held inside the operating area.
2. **The reach.** The point of the slot's reach nearest to the goal: the 14h disk of radius
   V_max dt around q_{n-1} (the paper's kinematics: the full step straight at the goal, as
   `communication.fly_towards`); under a dynamics limit (planner.vehicle_model or
   planner.accel_limit_mps2) also the acceleration disk around the coasting point
   (`SlotProblem.ballistic_xy_m`), the projection onto the two disks' intersection.
3. **The pursuit line** runs from the start (q_{n-1}, or the coasting point under a dynamics
   limit: inside the reach, which is convex, so the whole line is) to that reach point. Shares
   are ABA's equal shares 1/M (14c sums them over the fleet). When the reach points of all
   UAVs pass the exact check (14a-14j, `SlotConstraints`) they are the plan. Otherwise each UAV in
   turn (UAV order, the others at their points so far) goes to the furthest point of its line
   that passes the exact check: the line is sampled (SCAN_POINTS), the furthest passing sample
   found, and the step between it and the next sample bisected (rounds of REFINE_POINTS) until
   the bracket is shorter than STOP_TOLERANCE_M. So a UAV stops short where moving on would
   break its rate at R_th (14a), its control range (14b), the clearance from a target or a
   keep-out point along the legs (14i/14j) or the operating area; the step just past the stop
   fails the check.
4. **Fallback.** When the link cannot reach R_th anywhere, or the start itself breaks the exact
   check (e.g. equal shares below R_th there), the slot is infeasible and flies
   `fallback.best_effort`, like every other method.

Pure: no clock but the plan's timer, no RNG, no I/O.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from isac_mission.planning.communication import fly_towards
from isac_mission.planning.fallback import best_effort
from isac_mission.planning.feasibility import SlotConstraints, capacity_ok, operating_area
from isac_mission.planning.problem import (
    PlansOnceToWarmUp,
    SlotInput,
    SlotProblem,
    build_slot_problem,
)
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.types import FloatArray, IntArray, SlotPlan, SolveReport

if TYPE_CHECKING:
    from isac_mission.planning.kit import SolverKit

SCAN_POINTS = 65
"""Samples of the pursuit line (its start and end included) the first pass checks."""
REFINE_POINTS = 33
"""Samples of the bracket per bisection round (ends included): each round shrinks it 32 times."""
STOP_TOLERANCE_M = 1e-6
"""The bisection stops when the bracket [passes, fails] along the line is shorter than this, m."""
_SHRINK = 1.0 - 1e-12
"""Disk radii a hair short, so that round-off never puts a reach point outside its disk."""


def nearest_track(prev_xy_m: FloatArray, targets: tuple[TargetBelief, ...]) -> IntArray:
    """[M] the index into `targets` of each UAV's nearest track: the smallest distance from
    prev_xy_m [M, 2] (m) to the track's predicted position at the slot's end, ties to the earlier
    track."""
    pred_xy_m = np.array([b.state_pred[:2] for b in targets], dtype=float)  # [T, 2]
    dist_m = np.linalg.norm(prev_xy_m[:, None, :] - pred_xy_m[None], axis=-1)  # [M, T]
    return np.asarray(np.argmin(dist_m, axis=1), dtype=np.int64)


def _into_disk(p_m: FloatArray, centre_m: FloatArray, radius_m: float) -> FloatArray:
    """The point [2] of the disk (centre_m [2], radius_m) nearest to p_m [2], m."""
    d = p_m - centre_m
    n = float(np.linalg.norm(d))
    return p_m if n <= radius_m else np.asarray(centre_m + d * (radius_m / n))


def nearest_reachable(
    goal_m: FloatArray,
    prev_m: FloatArray,
    step_m: float,
    coast_m: FloatArray | None = None,
    accel_radius_m: float = np.inf,
) -> FloatArray:
    """The point [2] nearest to goal_m [2] within step_m of prev_m [2] (14h) and, when coast_m
    [2] is given, within accel_radius_m of it (the acceleration disk around the coasting point,
    which lies inside the 14h disk); each radius a hair short (_SHRINK). All in m.

    The exact projection onto the two disks' intersection: the projection onto one disk if it
    lies in the other, else the nearer to the goal of the two circles' crossing points."""
    r1 = step_m * _SHRINK
    if coast_m is None or not np.isfinite(accel_radius_m):
        return np.asarray(fly_towards(prev_m[None], goal_m[None], step_m)[0], dtype=float)
    r2 = accel_radius_m * _SHRINK
    first = _into_disk(goal_m, prev_m, r1)
    if np.linalg.norm(first - coast_m) <= r2:
        return first
    second = _into_disk(goal_m, coast_m, r2)
    if np.linalg.norm(second - prev_m) <= r1:
        return second
    # Neither projection lies in the other disk: the nearest point is on both circles.
    d = coast_m - prev_m
    gap_m = float(np.linalg.norm(d))
    if gap_m < 1e-12:  # concentric: the smaller disk's projection lies in the larger one
        return second if r2 <= r1 else first
    along_m = (r1 * r1 - r2 * r2 + gap_m * gap_m) / (2.0 * gap_m)
    half_chord_m = float(np.sqrt(max(r1 * r1 - along_m * along_m, 0.0)))
    base = prev_m + d * (along_m / gap_m)
    perp = np.array([-d[1], d[0]]) / gap_m
    crossings = (base + half_chord_m * perp, base - half_chord_m * perp)
    return min(crossings, key=lambda c: float(np.linalg.norm(c - goal_m)))


def pursuit_lines(problem: SlotProblem) -> tuple[FloatArray, FloatArray, IntArray]:
    """(start [M, 2], reach [M, 2], chased [M]) of the slot: each UAV's pursuit line from its
    start (q_{n-1}, or the coasting point under a dynamics limit) to the point of its reach
    nearest to its nearest track's predicted position (held in the operating area), m; chased:
    that track's index into SlotInput.targets."""
    inp = problem.inp
    cons = problem.constraints
    chased = nearest_track(inp.prev_xy_m, inp.targets)
    lo, hi = operating_area(problem.scenario)
    goals = np.array([np.clip(inp.targets[i].state_pred[:2], lo, hi) for i in chased])
    coast = problem.ballistic_xy_m
    start = np.array(inp.prev_xy_m if coast is None else coast, dtype=float)
    reach = np.array(
        [
            nearest_reachable(
                goals[m],
                inp.prev_xy_m[m],
                problem.max_step_m,
                None if coast is None else coast[m],
                cons.accel_radius_m,
            )
            for m in range(len(goals))
        ]
    )
    return start, reach, chased


def furthest_passing(
    cons: SlotConstraints,
    current_xy_m: FloatArray,
    eta: FloatArray,
    m: int,
    start_m: FloatArray,
    end_m: FloatArray,
) -> float:
    """The fraction lambda in [0, 1] of the line start_m [2] -> end_m [2] (m) to which UAV m
    goes: the furthest sample of the line (SCAN_POINTS) whose point passes the exact check with
    the others at current_xy_m [M, 2] and shares eta [M], refined by bisection towards the next
    sample, which fails, until the bracket is shorter than STOP_TOLERANCE_M. current_xy_m must
    pass the check with UAV m at start_m (lambda = 0 passes)."""
    length_m = float(np.linalg.norm(end_m - start_m))
    if length_m == 0.0:
        return 0.0

    def passing(fractions: FloatArray) -> FloatArray:
        points = start_m[None] + fractions[:, None] * (end_m - start_m)[None]
        return np.asarray(cons.feasible_moving_one(current_xy_m, eta, m, points))

    fractions = np.linspace(0.0, 1.0, SCAN_POINTS)
    ok = passing(fractions)
    last = int(np.flatnonzero(ok)[-1]) if ok.any() else 0
    if last == len(fractions) - 1:
        return 1.0
    lo, hi = float(fractions[last]), float(fractions[last + 1])
    while (hi - lo) * length_m > STOP_TOLERANCE_M:
        inner = np.linspace(lo, hi, REFINE_POINTS)[1:-1]
        ok = passing(inner)
        if ok.any():
            k = int(np.flatnonzero(ok)[-1])
            lo = float(inner[k])
            hi = float(inner[k + 1]) if k + 1 < len(inner) else hi
        else:
            hi = float(inner[0])
    return lo


class Nearest(PlansOnceToWarmUp):
    """`nearest`: each UAV closes on its nearest confirmed track, as far as one slot allows,
    stopping where moving on would break the exact check; ABA's equal shares."""

    def plan(self, inp: SlotInput, kit: SolverKit) -> SlotPlan:
        problem = build_slot_problem(inp, kit)
        no_link = problem.link_infeasible_reason()
        if no_link is not None:
            return best_effort(problem, no_link)
        s = problem.scenario
        cons = problem.constraints
        eta = np.full(s.M, 1.0 / s.M)
        if not capacity_ok(problem.bs_of_uav, s.K, s.n_a):
            return best_effort(problem, "infeasible: no plan satisfies 14e capacity")
        start, reach, _ = pursuit_lines(problem)
        at_start = cons.describe_violations(start, eta)
        if at_start:
            why = "infeasible: the pursuit's start with equal shares breaks "
            return best_effort(problem, why + ", ".join(at_start))
        xy = reach
        if not bool(cons.feasible(reach[None], eta[None])[0]):
            xy = start.copy()
            for m in range(s.M):
                lam = furthest_passing(cons, xy, eta, m, start[m], reach[m])
                xy[m] = start[m] + lam * (reach[m] - start[m])
        violated = cons.describe_violations(xy, eta)
        if violated:
            return best_effort(
                problem, "infeasible: no pursuit plan satisfies " + ", ".join(violated)
            )
        return problem.plan(xy, eta, SolveReport("ok", solve_s=problem.elapsed_s()))
