"""How close the proposed plan comes to the best plan an independent optimiser finds, per slot.

The exact problem of one slot is the one `plan_slot` enforces, with the slot's association:

    min_{Q, eta} f(Q, eta) = tr(C)  s.t.
        14a  eta_m R~_m(q_m) >= R_th                         (the plan's serving BS)
        14b  min_k ||q_m - w_k|| <= d_th                     (a union of disks)
        14c  sum eta = 1,  14d  0 <= eta <= 1
        14h  ||q_m - q_{m,n-1}|| <= V_max dt
        14i  ||q_i - q_j|| >= D_s  and  ||q_m - p_l|| >= D_s  (keep-out points p_l, if any)
        14j  ||q_m - u_pred|| >= D_s
        area 0 <= q_m <= area size                           (planner.keep_in_area)
        dyn  ||q_m - b_m|| <= a_max dt^2 / 4                 (planner.accel_limit_mps2 set: b_m is
             the coasting point q + v dt, clipped to the 14h disk and the area, as in slot.py)

Slots: `--slots` slots sampled evenly from `--seeds` closed-loop runs of the `proposed` method
(the scenario's default, noise seeds seed + r), at M = 3 (config/paper.yaml) and at M = 6
(bench/planner.py's ring scenario, K = 8, N_a = 2). Each slot's input (q_{n-1}, x_pred, prior,
velocities, keep-out points) is replayed through `plan_slot` as `proposed-sca` (the paper's SCA
alone) and as `proposed` with the polish on (SCA + polish), `--repeats` times each, interleaved
in alternating order; the time of a slot is the minimum of its repeats (report.solve_s).

Reference: scipy SLSQP (not the polish's IPOPT) from `--starts` random feasible starts drawn
without the planner (uniform in each UAV's 14h disk, or its dynamics disk, rejection on every
position constraint; shares = the 14a floors plus a Dirichlet share of the rest), seeded per
slot. 14b is smooth per start: each UAV keeps to the control disk of the BS nearest its start
point (the starts sample the union). Fixed settings: squared-distance constraints tightened by
1 mm (the planner's margin), 14a by 1e-9 relative, the area as variable bounds, analytic
gradients of f and of every constraint, f divided by its value at the start, ftol 1e-10, at most
300 iterations. An answer counts only if `SlotConstraints.feasible` (the planner's check) and
this script's own loop check both accept it. A slot where no start gives a feasible answer, or
where the plan is not `ok`, is a miss: its ratio is +inf.

Printed per M: the ratio plan / best (median, p95, p99, worst, share within 1 % and 5 %, misses)
for the default plan (the scenario's planner.polish; the ring takes paper.yaml's), the SCA alone
and SCA + polish; the worst slots; how many starts reach the best (within 0.1 %) and how many
hit the iteration cap; the polish's improvement (f_SCA - f_polish) / f_SCA and its outcomes; the
time per slot of both (medians, p95 and the ratio of medians). BLAS runs on one thread.

Run: python bench/quality.py [--slots 200] [--seeds 10] [--starts 30] [--workers 2] [--m 3 6]
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import multiprocessing
import sys
import time
import warnings
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import minimize
from threadpoolctl import threadpool_limits

from isac_mission.config import Scenario, load_scenario
from isac_mission.experiment.closed_loop import draw_run_noise, record_slot_inputs
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method, SlotInput, plan_slot, warm_up
from isac_mission.tracking.pcrb import PlanningObjective, SensingParams
from isac_mission.types import FloatArray, SlotPlan

MARGIN_M = 1e-3  # SLSQP's distance constraints are tightened by the planner's 1 mm margin
RATE_TIGHTEN = 1e-9  # ... and 14a by this relative amount
REACH_REL = 1e-3  # an answer "reaches the best" within 0.1 %
MAXITER = 300
FTOL = 1e-10  # on f / f(start), so relative
WORST = 8  # slots listed
MAX_REJECTIONS = 200  # draws per start before it counts as infeasible
BENCH = Path(__file__).resolve().parent


def ring_scenario(slots: int) -> Scenario:
    """bench/planner.py's ring scenario at M = 6, K = 8, N_a = 2, with `slots` slots."""
    spec = importlib.util.spec_from_file_location("bench_planner", BENCH / "planner.py")
    assert spec is not None and spec.loader is not None
    planner = sys.modules.setdefault("bench_planner", importlib.util.module_from_spec(spec))
    spec.loader.exec_module(planner)
    s: Scenario = planner.scenario(6, 8, 2, slots)
    return s


def with_polish(s: Scenario, on: bool) -> Scenario:
    """The scenario with planner.polish set to `on`."""
    return s.with_changes(planner=s.planner.model_copy(update={"polish": on}))


def paper_problem(s: Scenario) -> Scenario:
    """The scenario with planner.safety_margin "none": this benchmark's own check and multistart
    are the paper's per-slot problem (D_s at the slot instant, docs/model.md "Safety")."""
    return s.with_changes(planner=s.planner.model_copy(update={"safety_margin": "none"}))


# --- the exact problem ------------------------------------------------------------------------


@dataclass(frozen=True)
class ExactProblem:
    """The data of one slot's exact problem, computed here (not taken from the planner).

    prev_xy [M, 2]; serving_xy [M, 2] (the plan's association); target_xy [2]; keep_out_xy
    [L, 2]; ballistic_xy [M, 2] or None with accel_radius_m; area_lo / area_hi [2] (+-inf when
    the area is not enforced). Distances m, rates bit/s.
    """

    s: Scenario
    prev_xy: FloatArray
    serving_xy: FloatArray
    target_xy: FloatArray
    keep_out_xy: FloatArray
    ballistic_xy: FloatArray | None
    accel_radius_m: float
    area_lo: FloatArray
    area_hi: FloatArray


def exact_problem(s: Scenario, inp: SlotInput, plan: SlotPlan) -> ExactProblem:
    """This script's own statement of the slot's constraints (area, clipped coasting point)."""
    lo, hi = (
        (np.zeros(2), np.asarray(s.area, float))
        if s.planner.keep_in_area
        else (
            np.full(2, -np.inf),
            np.full(2, np.inf),
        )
    )
    ballistic, radius = None, np.inf
    if s.planner.accel_limit_mps2 is not None and inp.prev_velocity_mps is not None:
        ballistic = np.empty((s.M, 2))
        for m in range(s.M):
            coast = inp.prev_velocity_mps[m] * s.dt
            norm = math.hypot(*coast)
            limit = s.v_max * s.dt * (1 - 1e-9)
            if norm > limit:
                coast = coast * (limit / norm)
            ballistic[m] = np.minimum(np.maximum(inp.prev_xy_m[m] + coast, lo), hi)
        radius = s.planner.accel_limit_mps2 * s.dt**2 / 4
    keep_out = np.zeros((0, 2)) if inp.keep_out_xy_m is None else np.asarray(inp.keep_out_xy_m)
    return ExactProblem(
        s,
        np.asarray(inp.prev_xy_m, float),
        s.bs_xy[plan.bs_of_uav],
        np.asarray(inp.lead.state_pred[:2], float),
        keep_out,
        ballistic,
        radius,
        lo,
        hi,
    )


def planner_constraints(p: ExactProblem) -> SlotConstraints:
    """The same problem as the planner's SlotConstraints (to check answers with its code)."""
    return SlotConstraints(
        p.prev_xy,
        p.serving_xy,
        p.s.bs_xy,
        p.target_xy,
        p.s,
        ballistic_xy=p.ballistic_xy,
        accel_radius_m=p.accel_radius_m,
        keep_out_xy=p.keep_out_xy if len(p.keep_out_xy) else None,
    )


def own_check(p: ExactProblem, Q: FloatArray, eta: FloatArray) -> bool:
    """This script's own check of the exact problem (loops, no code shared with feasibility.py)."""
    s = p.s
    if abs(float(np.sum(eta)) - 1) > 1e-9 or np.any(eta < 0) or np.any(eta > 1):
        return False
    for m in range(s.M):
        x, y = float(Q[m, 0]), float(Q[m, 1])
        d2 = (x - p.serving_xy[m, 0]) ** 2 + (y - p.serving_xy[m, 1]) ** 2
        if eta[m] * s.B * math.log2(1 + s.rho0 / (d2 + s.dH**2)) < s.r_th * (1 - 1e-12):
            return False
        if min(math.hypot(x - w[0], y - w[1]) for w in s.bs_xy) > s.d_th:
            return False
        if math.hypot(x - p.prev_xy[m, 0], y - p.prev_xy[m, 1]) > s.v_max * s.dt:
            return False
        if math.hypot(x - p.target_xy[0], y - p.target_xy[1]) < s.d_safe:
            return False
        if any(math.hypot(x - k[0], y - k[1]) < s.d_safe for k in p.keep_out_xy):
            return False
        if not (p.area_lo[0] <= x <= p.area_hi[0] and p.area_lo[1] <= y <= p.area_hi[1]):
            return False
        if p.ballistic_xy is not None:
            bx, by = p.ballistic_xy[m]
            if math.hypot(x - bx, y - by) > p.accel_radius_m:
                return False
        for j in range(m + 1, s.M):
            if math.hypot(x - Q[j, 0], y - Q[j, 1]) < s.d_safe:
                return False
    return True


def full_rates(p: ExactProblem, Q: FloatArray) -> FloatArray:
    """R~ [M] on the serving BSs, bit/s."""
    s = p.s
    d2 = np.sum((Q - p.serving_xy) ** 2, axis=1)
    return np.asarray(s.B * np.log2(1 + s.rho0 / (d2 + s.dH**2)))


def random_start(p: ExactProblem, rng: np.random.Generator) -> tuple[FloatArray, FloatArray] | None:
    """A random feasible (Q, eta) drawn without the planner; None after MAX_REJECTIONS draws."""
    s = p.s
    centre, radius = p.prev_xy, s.v_max * s.dt
    if p.ballistic_xy is not None and p.accel_radius_m < radius:
        centre, radius = p.ballistic_xy, p.accel_radius_m
    for _ in range(MAX_REJECTIONS):
        r = radius * np.sqrt(rng.uniform(size=s.M)) * 0.999
        phi = rng.uniform(0, 2 * np.pi, s.M)
        Q = centre + np.column_stack([r * np.cos(phi), r * np.sin(phi)])
        floor = s.r_th / full_rates(p, Q) * (1 + 1e-6)
        if floor.sum() >= 1:
            continue
        eta = floor + (1 - floor.sum()) * rng.dirichlet(np.ones(s.M))
        if own_check(p, Q, eta):
            return Q, eta
    return None


def slsqp(
    p: ExactProblem, objective: PlanningObjective, Q0: FloatArray, eta0: FloatArray
) -> tuple[tuple[FloatArray, FloatArray] | None, bool]:
    """SLSQP on the exact problem from (Q0, eta0), z = ((Q - q_prev) / step, eta): (the answer
    if both checks accept it else None, whether SLSQP hit its iteration cap)."""
    s = p.s
    M, step = s.M, s.v_max * s.dt
    prev = p.prev_xy
    # 14b: the control disk of the BS nearest each start point (the start is inside it).
    near = s.bs_xy[np.argmin(np.linalg.norm(Q0[:, None] - s.bs_xy[None], axis=-1), axis=1)]
    iu, ju = np.triu_indices(M, 1)
    n_pairs = len(iu)
    rb2, rh2 = (s.d_th - MARGIN_M) ** 2, (step - MARGIN_M) ** 2
    rs2 = (s.d_safe + MARGIN_M) ** 2
    ra2 = max(p.accel_radius_m - MARGIN_M, 1e-9) ** 2
    rth = s.r_th * (1 + RATE_TIGHTEN)
    rows_m = np.arange(M)

    def split(z: FloatArray) -> tuple[FloatArray, FloatArray]:
        return prev + step * z[: 2 * M].reshape(M, 2), z[2 * M :]

    f0 = objective.value(Q0, eta0)  # f / f(start): ftol is relative

    def fun(z: FloatArray) -> tuple[float, FloatArray]:
        Q, eta = split(z)
        f, gq, ge = objective.value_and_gradients(Q, np.maximum(eta, 1e-12))
        return f / f0, np.concatenate([gq.ravel() * step, ge]) / f0

    def per_uav(jq: FloatArray) -> FloatArray:
        """[M, 3M] Jacobian of M per-UAV constraints from their d/dq [M, 2] (times step)."""
        out = np.zeros((M, 3 * M))
        out[rows_m, 2 * rows_m] = jq[:, 0] * step
        out[rows_m, 2 * rows_m + 1] = jq[:, 1] * step
        return out

    def constraints(z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(g [C], dg/dz [C, 3M]), every g >= 0 at a feasible point, scaled to O(1)."""
        Q, eta = split(z)
        vals, jacs = [], []
        dw = Q - p.serving_xy
        s2 = np.sum(dw**2, axis=1) + s.dH**2
        rate = s.B * np.log2(1 + s.rho0 / s2)
        drate = (s.B / np.log(2)) / (1 + s.rho0 / s2) * (-s.rho0 / s2**2)  # dR~/d(s2)
        vals.append(eta * rate / rth - 1)  # 14a
        j = per_uav((eta * drate / rth)[:, None] * 2 * dw)
        j[rows_m, 2 * M + rows_m] = rate / rth
        jacs.append(j)
        for centre, r2 in ((near, rb2), (prev, rh2)):  # 14b, 14h
            d = Q - centre
            vals.append(1 - np.sum(d**2, axis=1) / r2)
            jacs.append(per_uav(-2 * d / r2))
        if p.ballistic_xy is not None:  # dynamics disk
            d = Q - p.ballistic_xy
            vals.append(1 - np.sum(d**2, axis=1) / ra2)
            jacs.append(per_uav(-2 * d / ra2))
        d = Q - p.target_xy  # 14j
        vals.append(np.sum(d**2, axis=1) / rs2 - 1)
        jacs.append(per_uav(2 * d / rs2))
        for k in p.keep_out_xy:  # 14i against the keep-out points
            d = Q - k
            vals.append(np.sum(d**2, axis=1) / rs2 - 1)
            jacs.append(per_uav(2 * d / rs2))
        if n_pairs:  # 14i between the UAVs
            d = Q[iu] - Q[ju]
            vals.append(np.sum(d**2, axis=1) / rs2 - 1)
            j = np.zeros((n_pairs, 3 * M))
            rows = np.arange(n_pairs)
            for c in range(2):
                j[rows, 2 * iu + c] = 2 * d[:, c] / rs2 * step
                j[rows, 2 * ju + c] = -2 * d[:, c] / rs2 * step
            jacs.append(j)
        return np.concatenate(vals), np.vstack(jacs)

    lo = np.maximum((p.area_lo + MARGIN_M - prev) / step, -1.0)
    hi = np.minimum((p.area_hi - MARGIN_M - prev) / step, 1.0)
    bounds = [(float(lo[m, c]), float(hi[m, c])) for m in range(M) for c in range(2)]
    bounds += [(0.0, 1.0)] * M
    z0 = np.concatenate([((Q0 - prev) / step).ravel(), eta0])
    sum_jac = np.concatenate([np.zeros(2 * M), np.ones(M)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        res = minimize(
            fun,
            z0,
            jac=True,
            method="SLSQP",
            bounds=bounds,
            constraints=[
                {
                    "type": "ineq",
                    "fun": lambda z: constraints(z)[0],
                    "jac": lambda z: constraints(z)[1],
                },
                {"type": "eq", "fun": lambda z: np.sum(z[2 * M :]) - 1, "jac": lambda z: sum_jac},
            ],
            options={"maxiter": MAXITER, "ftol": FTOL},
        )
    Q, eta = split(np.asarray(res.x, dtype=float))
    eta = np.clip(eta, 0.0, 1.0)
    eta = eta / eta.sum()
    ok_planner = bool(planner_constraints(p).feasible(Q[None], eta[None])[0])
    capped = int(res.status) == 9
    if not (ok_planner and own_check(p, Q, eta)):
        return None, capped
    return (Q, eta), capped


# --- slots, plans and the multistart ----------------------------------------------------------


@dataclass(frozen=True)
class Slot:
    """One sampled slot: its input, the plans (the scenario's default, the SCA alone
    `proposed-sca`, SCA + polish) and the times of the last two, s."""

    seed: int
    n: int
    inp: SlotInput
    plan: SlotPlan
    sca: SlotPlan
    polished: SlotPlan
    sca_s: float
    polished_s: float


@dataclass(frozen=True)
class Reference:
    """The multistart of one slot: the best f found (+inf: none feasible), feasible answers,
    starts that reach the best within REACH_REL."""

    best: float
    n_feasible: int
    n_reach: int
    n_capped: int


def sample_slots(n_slots: int, per_seed: int) -> list[int]:
    """per_seed slot indices spread evenly over a run of n_slots slots (the last one included)."""
    idx = np.linspace(n_slots - 1, 0, per_seed, endpoint=False)[::-1]
    return sorted({round(float(i)) for i in idx})


def replay(s: Scenario, slots: int, seeds: int, repeats: int, log: bool = True) -> list[Slot]:
    """Record the proposed closed loop of each seed (the scenario's own polish setting) and
    replay its sampled slots: `proposed-sca` and `proposed` with the polish on, interleaved in
    alternating order, `repeats` times each (the time is the minimum)."""
    kit = SolverKit(s)
    warm_up(kit)
    kit_on = kit if s.planner.polish else SolverKit(with_polish(s, True))
    warm_up(kit_on)
    per_seed = math.ceil(slots / seeds)
    out: list[Slot] = []
    for r in range(seeds):
        seed = s.seed + r
        t0 = time.perf_counter()
        inputs = record_slot_inputs(s, "proposed", draw_run_noise(s, seed), kit)[1]
        for n in sample_slots(len(inputs), per_seed):
            inp = inputs[n]
            times: dict[Method, list[float]] = {"proposed-sca": [], "proposed": []}
            plans: dict[Method, SlotPlan] = {}
            for k in range(repeats):
                for method in list(times) if k % 2 == 0 else list(times)[::-1]:
                    plans[method] = plan_slot(inp, kit_on, method)
                    times[method].append(plans[method].report.solve_s)
            sca, pol = plans["proposed-sca"], plans["proposed"]
            plan = pol if s.planner.polish else sca
            t_sca, t_pol = min(times["proposed-sca"]), min(times["proposed"])
            out.append(Slot(seed, n + 1, inp, plan, sca, pol, t_sca, t_pol))
        if log:
            dt = time.perf_counter() - t0
            print(f"  seed {seed}: closed loop and replays {dt:.1f} s", flush=True)
    return out[: max(slots, 0)]


def multistart(
    s: Scenario, sensing: SensingParams, slot: Slot, starts: int, rng_seed: int
) -> Reference:
    """The SLSQP multistart of one slot (starts seeded by rng_seed, independent of the plan)."""
    p = exact_problem(s, slot.inp, slot.plan)
    objective = PlanningObjective(
        slot.inp.lead.prior_information, slot.inp.lead.state_pred, sensing
    )
    rng = np.random.default_rng(rng_seed)
    found: list[float] = []
    capped = 0
    for _ in range(starts):
        start = random_start(p, rng)
        if start is None:
            continue
        answer, cap = slsqp(p, objective, *start)
        capped += cap
        if answer is not None:
            found.append(objective.value(*answer))
    if not found:
        return Reference(math.inf, 0, 0, capped)
    best = min(found)
    return Reference(best, len(found), sum(f <= best * (1 + REACH_REL) for f in found), capped)


_JOBS: list[tuple[Scenario, SensingParams, Slot, int, int]] = []


def _run_job(i: int) -> Reference:
    with threadpool_limits(1):
        return multistart(*_JOBS[i])


def references(s: Scenario, slots: Sequence[Slot], starts: int, workers: int) -> list[Reference]:
    """The multistart of every slot, over a fork pool of `workers` processes (1: in process)."""
    sensing = SensingParams.from_scenario(s)
    _JOBS[:] = [(s, sensing, sl, starts, 1000 * sl.seed + sl.n) for sl in slots]
    try:
        if workers <= 1:
            return [_run_job(i) for i in range(len(_JOBS))]
        ctx = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(workers, mp_context=ctx) as pool:
            return list(pool.map(_run_job, range(len(_JOBS)), chunksize=1))
    finally:
        _JOBS.clear()


# --- tables -------------------------------------------------------------------------------------


def ratios(plans: Sequence[SlotPlan | None], refs: Sequence[Reference]) -> FloatArray:
    """plan f / best f per slot; +inf for a miss (plan not ok, or no feasible start)."""
    out = []
    for plan, ref in zip(plans, refs, strict=True):
        ok = plan is not None and plan.report.status == "ok" and math.isfinite(ref.best)
        out.append(plan.pcrb_trace / ref.best if ok and plan is not None else math.inf)
    return np.asarray(out, dtype=float)


def q(x: FloatArray, pct: float) -> float:
    """Percentile without interpolating into +inf (the sample at or above the rank)."""
    return float(np.percentile(x, pct, method="higher"))


def fmt(v: float, spec: str = ".4f") -> str:
    return "miss" if math.isinf(v) else ("n/a" if math.isnan(v) else format(v, spec))


def ratio_row(name: str, r: FloatArray) -> str:
    cells = [fmt(float(np.median(r))), fmt(q(r, 95)), fmt(q(r, 99)), fmt(float(r.max()))]
    within = [f"{np.mean(r <= 1.01):.1%}", f"{np.mean(r <= 1.05):.1%}"]
    misses = int(np.sum(np.isinf(r)))
    return f"{name:<22}" + "".join(f"{c:>9}" for c in cells + within) + f"{misses:>7}"


def print_tables(
    label: str, slots: Sequence[Slot], refs: Sequence[Reference], starts: int
) -> dict[str, Any]:
    """Print one M's tables; return the headline numbers."""
    default = ratios([sl.plan for sl in slots], refs)
    on = "on" if slots[0].plan is slots[0].polished else "off"
    print(
        f"\n== {label}: {len(slots)} slots from {len({sl.seed for sl in slots})} seeds, "
        f"{starts} SLSQP starts per slot; default: polish {on} =="
    )
    print(
        f"{'plan / best':<22}"
        + "".join(f"{h:>9}" for h in ("median", "p95", "p99", "worst", "<=1%", "<=5%"))
        + f"{'misses':>7}"
    )
    print(ratio_row("default proposed", default))
    r_sca = ratios([sl.sca for sl in slots], refs)
    r_pol = ratios([sl.polished for sl in slots], refs)
    print(ratio_row("SCA alone", r_sca))
    print(ratio_row("SCA + polish", r_pol))
    print(f"\nworst {WORST} slots of the default plan:")
    print(f"{'seed':>5}{'slot':>5}{'best f':>12}{'SCA':>9}{'polish':>9}{'reach':>6}  polish note")
    for i in np.argsort(-default, kind="stable")[:WORST]:
        sl, rf = slots[i], refs[i]
        print(
            f"{sl.seed:>5}{sl.n:>5}{rf.best:>12.5g}{fmt(r_sca[i]):>9}{fmt(r_pol[i]):>9}"
            f"{rf.n_reach:>6}  {sl.polished.report.polish or sl.polished.report.reason}"
        )
    n_cap = sum(rf.n_capped for rf in refs)
    n_ok = np.array([rf.n_feasible for rf in refs])
    n_reach = np.array([rf.n_reach for rf in refs])
    print(
        f"\nstarts with a feasible answer per slot: median {np.median(n_ok):.0f}, min {n_ok.min()}"
        f" of {starts}; slots with none: {int(np.sum(n_ok == 0))}"
    )
    print(
        f"starts reaching the best (within {REACH_REL:.1%}): median {np.median(n_reach):.0f}, "
        f"p5 {np.percentile(n_reach, 5, method='lower'):.0f}, min {n_reach.min()}; "
        f"slots where only 1 start did: {int(np.sum(n_reach == 1))}"
    )
    print(f"SLSQP runs that hit the {MAXITER}-iteration cap: {n_cap} of {starts * len(refs)}")
    both_ok = [sl for sl in slots if sl.sca.report.status == sl.polished.report.status == "ok"]
    g = 100 * np.array(
        [(sl.sca.pcrb_trace - sl.polished.pcrb_trace) / sl.sca.pcrb_trace for sl in both_ok]
    )
    if len(g):
        print(
            f"polish improvement (f_SCA - f_polish) / f_SCA, % ({len(g)} slots): median "
            f"{np.median(g):.3f}, p95 {np.percentile(g, 95):.3f}, p99 {np.percentile(g, 99):.3f}, "
            f"max {g.max():.3f}, min {g.min():.3f}; > 0.1 % on {np.mean(g > 0.1):.1%}, "
            f"> 1 % on {np.mean(g > 1):.1%}"
        )
    notes: dict[str, int] = {}
    for sl in slots:
        key = note_kind(sl.polished.report.polish or f"not run ({sl.polished.report.status})")
        notes[key] = notes.get(key, 0) + 1
    print("polish outcomes: " + "; ".join(f"{k}: {v}" for k, v in sorted(notes.items())))
    t_sca = np.array([sl.sca_s for sl in slots]) * 1e3
    t_pol = np.array([sl.polished_s for sl in slots]) * 1e3
    ratio_t = float(np.median(t_pol) / np.median(t_sca))
    print(
        f"time per slot, ms (min of repeats): SCA alone median {np.median(t_sca):.1f} "
        f"p95 {np.percentile(t_sca, 95):.1f}; SCA + polish median {np.median(t_pol):.1f} "
        f"p95 {np.percentile(t_pol, 95):.1f}; ratio of medians {ratio_t:.2f}"
    )
    return {
        "within1": float(np.mean(default <= 1.01)),
        "within5": float(np.mean(default <= 1.05)),
        "worst": float(default.max()),
        "time_ratio": ratio_t,
    }


def note_kind(note: str) -> str:
    """The kind of a polish note: its text without the numbers ("polished", "IPOPT <status>",
    "IPOPT answer violates ...", "no improvement")."""
    if note.startswith("polished"):
        return "polished"
    return note.removeprefix("polish kept the SCA plan: ").split(" after ")[0]


def scenarios(ms: Sequence[int], config: str, slots_per_run: int) -> list[tuple[str, Scenario]]:
    """The benchmark's scenarios by M: 3 = `config` (paper.yaml), 6 = the ring scenario with
    the polish setting of `config` (the ring is built from the code defaults)."""
    paper = paper_problem(load_scenario(config))
    out = []
    for m in ms:
        if m == 3:
            out.append((f"M = 3, {Path(config).name}", paper))
        elif m == 6:
            ring = paper_problem(with_polish(ring_scenario(slots_per_run), paper.planner.polish))
            out.append(("M = 6, bench/planner.py ring (K = 8, N_a = 2)", ring))
        else:
            raise SystemExit(f"--m {m}: only 3 and 6")
    return out


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--config", default=str(BENCH.parent / "config" / "paper.yaml"))
    ap.add_argument("--m", type=int, nargs="+", default=[3, 6], help="which M (3, 6)")
    ap.add_argument("--slots", type=int, default=200, help="sampled slots per M")
    ap.add_argument("--seeds", type=int, default=10, help="closed-loop runs per M")
    ap.add_argument("--starts", type=int, default=30, help="SLSQP starts per slot")
    ap.add_argument("--repeats", type=int, default=3, help="timed replays per slot and kit")
    ap.add_argument("--workers", type=int, default=2, help="processes for the multistart")
    ap.add_argument("--run-slots", type=int, default=60, help="slots of the M = 6 runs")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    summary: dict[str, Any] = {}
    with threadpool_limits(1):
        for label, s in scenarios(args.m, args.config, args.run_slots):
            t0 = time.perf_counter()
            print(f"{label}: replaying {args.slots} slots of {args.seeds} seeds", flush=True)
            slots = replay(s, args.slots, args.seeds, args.repeats)
            t1 = time.perf_counter()
            refs = references(s, slots, args.starts, args.workers)
            t2 = time.perf_counter()
            summary[label] = print_tables(label, slots, refs, args.starts)
            print(f"replays {t1 - t0:.0f} s, multistart {t2 - t1:.0f} s ({args.workers} workers)")
    print(f"\ntotal {time.perf_counter() - t_all:.0f} s")
    return summary


if __name__ == "__main__":
    main()
