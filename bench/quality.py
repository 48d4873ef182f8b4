"""How close the proposed plan comes to the best plan an independent optimiser finds, per slot.

For a sample of slots of paper-scenario closed-loop runs of the proposed method (runs `--runs`,
every `--every`-th slot), the slot's own inputs (previous positions q_{n-1}, association,
predicted state, prior information) are replayed: plan_slot gives the proposed plan and its
objective f = tr(C) (plan.pcrb_trace). The same exact non-convex problem

    min_{Q, eta} f(Q, eta)  s.t.  14a  eta_m R~_m(q_m) >= R_th      (the slot's serving BS)
                                  14b  ||q_m - w|| <= d_th          (w: the BS nearest q_{m,n-1})
                                  14c  sum eta = 1,  14d  0 <= eta <= 1
                                  14h  ||q_m - q_{m,n-1}|| <= V_max dt
                                  14i  ||q_i - q_j|| >= D_s,  14j  ||q_m - u_pred|| >= D_s
                                  (and the dynamics disk when planner.accel_limit_mps2 is set)

is then solved by scipy's SLSQP (smooth constraints in squared form, tightened by the planner's
1 mm margin, analytic gradients of f from PlanningObjective)
from `--starts` random feasible points drawn independently of the planner (uniform in the 14h
disks, rejection on 14i/14j; shares = floors of 14a plus a Dirichlet share of the rest). The
proposed plan is not a starting point. An SLSQP answer counts only if `SlotConstraints.feasible`
(the planner's exact 14a-14j check) and this script's own check both accept it.

Printed: the distribution of proposed / best over the sampled slots (median, p95, worst), the
fraction within 1 % (ratio <= 1.01) and the fraction where the proposed plan is at least as
good as every SLSQP answer. ratio < 1 means the proposed plan beat the multistart.

Run: python bench/quality.py [--config config/paper.yaml] [--runs 2] [--every 5] [--starts 30]
"""

from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from isac_mission.config import Scenario, load_scenario
from isac_mission.experiment.closed_loop import draw_run_noise, record_slot_inputs
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.slot import SlotInput, SolverKit, plan_slot
from isac_mission.tracking.pcrb import PlanningObjective
from isac_mission.types import FloatArray, SlotPlan

# SLSQP's constraints are tightened by 1 mm (the planner's SOLVER_MARGIN_M), so that an answer
# within SLSQP's tolerance passes the exact checks; the planner's SOCP has the same handicap.
MARGIN_M = 1e-3


@dataclass(frozen=True)
class SlotProblem:
    """The exact problem of one slot: its inputs, association and the planner's answer."""

    inp: SlotInput
    plan: SlotPlan
    constraints: SlotConstraints
    objective: PlanningObjective


def recorded_inputs(s: Scenario, kit: SolverKit, seed: int) -> list[SlotInput]:
    """The proposed method's slot inputs over one closed-loop run (noise seed `seed`)."""
    return record_slot_inputs(s, "proposed", draw_run_noise(s, seed), kit)[1]


def slot_problem(s: Scenario, kit: SolverKit, inp: SlotInput) -> SlotProblem:
    """Replay one slot: the proposed plan and the constraints with the plan's association."""
    plan = plan_slot(inp, kit, "proposed")
    ballistic = None
    radius = np.inf
    if s.planner.accel_limit_mps2 is not None and inp.prev_velocity is not None:
        coast = inp.prev_velocity * s.dt
        norm = np.linalg.norm(coast, axis=1, keepdims=True)
        coast = coast * np.minimum(1.0, s.v_max * s.dt * (1 - 1e-9) / np.maximum(norm, 1e-12))
        ballistic = inp.prev_xy + coast
        radius = s.planner.accel_limit_mps2 * s.dt**2 / 4
    cons = SlotConstraints(
        inp.prev_xy,
        s.bs_xy[plan.bs_of_uav],
        s.bs_xy,
        inp.x_pred[:2],
        s,
        ballistic_xy=ballistic,
        accel_radius_m=radius,
    )
    return SlotProblem(inp, plan, cons, PlanningObjective(inp.J_pred, inp.x_pred, kit.sensing))


def own_check(s: Scenario, p: SlotProblem, Q: FloatArray, eta: FloatArray) -> bool:
    """This script's own check of 14a-14j (loops, no shared code with feasibility.py)."""
    c = p.constraints
    for m in range(s.M):
        d_bs = float(np.hypot(*(Q[m] - c.serving_bs_xy[m])))
        rate = eta[m] * s.B * np.log2(1 + s.rho0 / (d_bs**2 + s.dH**2))
        if rate < s.r_th * (1 - 1e-12):
            return False
        if min(float(np.hypot(*(Q[m] - w))) for w in s.bs_xy) > s.d_th:
            return False
        if float(np.hypot(*(Q[m] - c.prev_xy[m]))) > s.v_max * s.dt:
            return False
        if float(np.hypot(*(Q[m] - c.target_xy))) < s.d_safe:
            return False
        if c.ballistic_xy is not None and np.hypot(*(Q[m] - c.ballistic_xy[m])) > c.accel_radius_m:
            return False
        for j in range(m + 1, s.M):
            if float(np.hypot(*(Q[m] - Q[j]))) < s.d_safe:
                return False
    return bool(abs(eta.sum() - 1) <= 1e-9 and np.all(eta >= 0) and np.all(eta <= 1))


def random_start(
    s: Scenario, p: SlotProblem, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray] | None:
    """A random feasible (Q, eta), drawn without the planner; None after 200 rejections."""
    c = p.constraints
    step = s.v_max * s.dt
    for _ in range(200):
        r = step * np.sqrt(rng.uniform(size=s.M)) * 0.999
        phi = rng.uniform(0, 2 * np.pi, s.M)
        Q = c.prev_xy + np.column_stack([r * np.cos(phi), r * np.sin(phi)])
        floor = s.r_th / c.full_rates(Q) * (1 + 1e-6)
        if floor.sum() >= 1:
            continue
        eta = floor + (1 - floor.sum()) * rng.dirichlet(np.ones(s.M))
        if own_check(s, p, Q, eta):
            return Q, eta
    return None


def slsqp(
    s: Scenario, p: SlotProblem, Q0: FloatArray, eta0: FloatArray
) -> tuple[FloatArray, FloatArray] | None:
    """SLSQP on the exact problem from (Q0, eta0); variables z = ((Q - q_prev) / step, eta)."""
    c = p.constraints
    M = s.M
    step = s.v_max * s.dt
    prev = c.prev_xy
    near = s.bs_xy[np.argmin(np.linalg.norm(prev[:, None] - s.bs_xy[None], axis=-1), axis=1)]
    iu, ju = np.triu_indices(M, 1)

    def split(z: FloatArray) -> tuple[FloatArray, FloatArray]:
        return prev + step * z[: 2 * M].reshape(M, 2), z[2 * M :]

    def fun(z: FloatArray) -> tuple[float, FloatArray]:
        Q, eta = split(z)
        f, gq, ge = p.objective.value_and_gradients(Q, np.maximum(eta, 1e-12))
        return f, np.concatenate([gq.ravel() * step, ge])

    def ineq(z: FloatArray) -> FloatArray:  # every entry >= 0 (scaled to O(1))
        Q, eta = split(z)
        out = [
            eta * c.full_rates(Q) / (s.r_th * (1 + 1e-9)) - 1,  # 14a
            1 - np.sum((Q - near) ** 2, axis=1) / (s.d_th - MARGIN_M) ** 2,  # 14b
            1 - np.sum((Q - prev) ** 2, axis=1) / (step - MARGIN_M) ** 2,  # 14h
            np.sum((Q - c.target_xy) ** 2, axis=1) / (s.d_safe + MARGIN_M) ** 2 - 1,  # 14j
            np.sum((Q[iu] - Q[ju]) ** 2, axis=1) / (s.d_safe + MARGIN_M) ** 2 - 1,  # 14i
        ]
        if c.ballistic_xy is not None:
            r2 = max(c.accel_radius_m - MARGIN_M, 1e-9) ** 2
            out.append(1 - np.sum((Q - c.ballistic_xy) ** 2, axis=1) / r2)
        return np.concatenate(out)

    z0 = np.concatenate([((Q0 - prev) / step).ravel(), eta0])
    bounds = [(-1.0, 1.0)] * (2 * M) + [(0.0, 1.0)] * M
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        res = minimize(
            fun,
            z0,
            jac=True,
            method="SLSQP",
            bounds=bounds,
            constraints=[
                {"type": "ineq", "fun": ineq},
                {"type": "eq", "fun": lambda z: np.sum(z[2 * M :]) - 1},
            ],
            options={"maxiter": 300, "ftol": 1e-12},
        )
    Q, eta = split(np.asarray(res.x, dtype=float))
    eta = np.clip(eta, 0.0, 1.0)
    eta = eta / eta.sum()
    ok_planner = bool(c.feasible(Q[None], eta[None])[0])
    if not (ok_planner and own_check(s, p, Q, eta)):
        return None
    return Q, eta


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--config", default="config/paper.yaml")
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--every", type=int, default=5)
    ap.add_argument("--starts", type=int, default=30)
    args = ap.parse_args()
    t0 = time.perf_counter()
    s = load_scenario(args.config)
    kit = SolverKit(s)
    kit.warm_up()
    rng = np.random.default_rng(12345)
    rows = []
    for r in range(args.runs):
        inputs = recorded_inputs(s, kit, s.seed + r)
        for n in range(args.every - 1, len(inputs), args.every):
            p = slot_problem(s, kit, inputs[n])
            if p.plan.report.status != "ok":
                continue
            best, n_ok = np.inf, 0
            for _ in range(args.starts):
                start = random_start(s, p, rng)
                if start is None:
                    continue
                found = slsqp(s, p, *start)
                if found is None:
                    continue
                n_ok += 1
                best = min(best, p.objective.value(*found))
            rows.append((r, n + 1, p.plan.pcrb_trace, best, n_ok))
    ratio = np.array([prop / best for _, _, prop, best, _ in rows])
    print(f"{args.config}: {len(rows)} slots ({args.runs} runs, every {args.every}th slot), ")
    print(f"SLSQP multistart: {args.starts} random feasible starts per slot (not the plan)")
    print(f"{'run':>3} {'slot':>4} {'proposed f':>11} {'best SLSQP f':>13} {'ratio':>8} {'ok':>3}")
    for (r, n, prop, best, n_ok), q in zip(rows, ratio, strict=True):
        print(f"{r:>3} {n:>4} {prop:>11.5f} {best:>13.5f} {q:>8.4f} {n_ok:>3}")
    print(
        f"\nratio proposed / best: median {np.median(ratio):.4f}, p95 "
        f"{np.percentile(ratio, 95):.4f}, worst {ratio.max():.4f}, best {ratio.min():.4f}"
    )
    print(f"within 1 %: {np.mean(ratio <= 1.01):.0%}; proposed <= best: {np.mean(ratio <= 1):.0%}")
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
