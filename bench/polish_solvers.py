"""Which solver polishes the slot: CasADi/IPOPT (exact Hessian) against scipy SLSQP and
trust-constr with the project's analytic gradients, on the same slots, from the same SCA point.

Slots: the `proposed-sca` closed loop of `paper.yaml` (M = 3, seeds 1..N) and of
bench/planner.py's ring scenario at M = 6 (K = 8, N_a = 2); every slot whose SCA plan is ok.
Each solver gets the same exact problem (planning/polish.py's constraints, the same scaling
q = q_prev + L z and f / f_SCA) and the same start, and its answer is kept only if the planner's
own exact check (SlotConstraints.feasible) passes and f drops, exactly as plan_slot does.
scipy gets the analytic objective gradient of PlanningObjective.value_and_gradients and
analytic constraint Jacobians; trust-constr approximates the Hessian (BFGS), SLSQP is
quasi-Newton by construction: scipy has no exact Hessian of tr(J^-1) to use.

Printed per solver: median and p95 time per slot (the solve alone), the median and worst
f / f_best over the solvers, the share of slots within 1e-6 of the best, kept (feasible and
better) slots, failures.

Run: python bench/polish_solvers.py [--seeds 2] [--slots 20]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy import optimize

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.planner import scenario as ring_scenario  # noqa: E402
from isac_mission.config import Scenario, load_scenario  # noqa: E402
from isac_mission.experiment.closed_loop import draw_run_noise, record_slot_inputs  # noqa: E402
from isac_mission.planning.feasibility import SlotConstraints, operating_area  # noqa: E402
from isac_mission.planning.kit import SolverKit  # noqa: E402
from isac_mission.planning.margins import MIN_SHARE, RATE_MARGIN, SOLVER_MARGIN_M  # noqa: E402
from isac_mission.planning.per_slot import polish_nlp  # noqa: E402
from isac_mission.planning.slot import SlotInput, plan_slot  # noqa: E402
from isac_mission.tracking.pcrb import PlanningObjective  # noqa: E402

Solve = Callable[[np.ndarray, np.ndarray, PlanningObjective, SlotConstraints], np.ndarray]


def constraints_of(
    s: Scenario, cons: SlotConstraints, xy0: np.ndarray
) -> tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray]]:
    """(g(x) >= 0, its Jacobian) of polish.py's constraints, x = (Q [M, 2] row-major, eta [M])."""
    M = s.M
    L = s.v_max * s.dt
    control = cons.bs_xy[np.argmin(np.linalg.norm(xy0[:, None] - cons.bs_xy[None], axis=-1), 1)]
    d_th = max(s.d_th - SOLVER_MARGIN_M, 0.0)
    step = L - SOLVER_MARGIN_M
    ds = s.d_safe + SOLVER_MARGIN_M
    pi, pj = np.triu_indices(M, 1)
    keep = np.zeros((0, 2)) if cons.keep_out_xy is None else cons.keep_out_xy
    accel = cons.ballistic_xy is not None and np.isfinite(cons.accel_radius_m)
    ra = max(cons.accel_radius_m - SOLVER_MARGIN_M, 0.0) if accel else 0.0
    k = np.log(2.0) * s.r_th

    def g(x: np.ndarray) -> np.ndarray:
        q, eta = x[: 2 * M].reshape(M, 2), x[2 * M :]
        dbs = np.sum((q - cons.serving_bs_xy) ** 2, axis=1)
        out = [
            eta * s.B * np.log1p(s.rho0 / (dbs + s.dH**2)) / k - 1.0 - RATE_MARGIN,
            (d_th**2 - np.sum((q - control) ** 2, axis=1)) / L**2,
            (step**2 - np.sum((q - cons.prev_xy) ** 2, axis=1)) / L**2,
            (np.sum((q - cons.target_xy) ** 2, axis=1) - ds**2) / L**2,
            (np.sum((q[pi] - q[pj]) ** 2, axis=1) - ds**2) / L**2,
            (np.sum((q[:, None] - keep[None]) ** 2, axis=2).ravel() - ds**2) / L**2,
        ]
        if accel:
            assert cons.ballistic_xy is not None
            out.append((ra**2 - np.sum((q - cons.ballistic_xy) ** 2, axis=1)) / L**2)
        return np.concatenate(out)

    def jac(x: np.ndarray) -> np.ndarray:
        q, eta = x[: 2 * M].reshape(M, 2), x[2 * M :]
        rows = []
        eye = np.eye(M)

        def per_uav(dq: np.ndarray) -> np.ndarray:  # [M, 2] gradient of UAV m's own row
            J = np.zeros((M, 3 * M))
            J[np.arange(M), 2 * np.arange(M)] = dq[:, 0]
            J[np.arange(M), 2 * np.arange(M) + 1] = dq[:, 1]
            return J

        dbs = np.sum((q - cons.serving_bs_xy) ** 2, axis=1)
        snr = s.rho0 / (dbs + s.dH**2)
        Jr = per_uav(
            (eta * s.B / k * (-snr / (1 + snr)) / (dbs + s.dH**2))[:, None]
            * 2
            * (q - cons.serving_bs_xy)
        )
        Jr[:, 2 * M :] = eye * (s.B * np.log1p(snr) / k)[:, None]
        rows += [Jr, per_uav(-2 * (q - control) / L**2), per_uav(-2 * (q - cons.prev_xy) / L**2)]
        rows.append(per_uav(2 * (q - cons.target_xy) / L**2))
        Jp = np.zeros((len(pi), 3 * M))
        d = 2 * (q[pi] - q[pj]) / L**2
        for c in range(2):
            Jp[np.arange(len(pi)), 2 * pi + c] = d[:, c]
            Jp[np.arange(len(pi)), 2 * pj + c] = -d[:, c]
        rows.append(Jp)
        Jk = np.zeros((M * len(keep), 3 * M))
        for m in range(M):
            for j in range(len(keep)):
                Jk[m * len(keep) + j, 2 * m : 2 * m + 2] = 2 * (q[m] - keep[j]) / L**2
        rows.append(Jk)
        if accel:
            assert cons.ballistic_xy is not None
            rows.append(per_uav(-2 * (q - cons.ballistic_xy) / L**2))
        return np.vstack(rows)

    return g, jac


def scipy_solver(method: str, max_iter: int) -> Solve:
    """A polish by scipy.optimize.minimize(method) from (xy0, eta0) with analytic gradients."""

    def solve(
        xy0: np.ndarray, eta0: np.ndarray, obj: PlanningObjective, cons: SlotConstraints
    ) -> np.ndarray:
        s = cons.scenario
        M = s.M
        f0 = obj.value(xy0, eta0)

        def fun(x: np.ndarray) -> tuple[float, np.ndarray]:
            q, eta = x[: 2 * M].reshape(M, 2), x[2 * M :]
            f, dq, de = obj.value_and_gradients(q, eta)
            return f / f0, np.concatenate([dq.ravel(), de]) / f0

        g, jac = constraints_of(s, cons, xy0)
        lo, hi = operating_area(s)
        bounds = [(lo[c], hi[c]) for _ in range(M) for c in range(2)] + [(MIN_SHARE, 1.0)] * M
        x0 = np.concatenate([xy0.ravel(), eta0])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if method == "SLSQP":
                cons_ = [
                    {"type": "ineq", "fun": g, "jac": jac},
                    {
                        "type": "eq",
                        "fun": lambda x: np.array([x[2 * M :].sum() - 1.0]),
                        "jac": lambda x: np.r_[np.zeros(2 * M), np.ones(M)][None],
                    },
                ]
                res = optimize.minimize(
                    fun,
                    x0,
                    jac=True,
                    method="SLSQP",
                    bounds=bounds,
                    constraints=cons_,
                    options={"maxiter": max_iter, "ftol": 1e-12},
                )
            else:
                A = np.r_[np.zeros(2 * M), np.ones(M)][None]
                cons_t = [
                    optimize.NonlinearConstraint(g, 0.0, np.inf, jac=jac),
                    optimize.LinearConstraint(A, 1.0, 1.0),
                ]
                res = optimize.minimize(
                    fun,
                    x0,
                    jac=True,
                    method="trust-constr",
                    bounds=optimize.Bounds([b[0] for b in bounds], [b[1] for b in bounds]),
                    constraints=cons_t,
                    options={"maxiter": max_iter, "gtol": 1e-9, "xtol": 1e-12},
                )
        return np.asarray(res.x)

    return solve


def slots(s: Scenario, seeds: int, per_seed: int) -> list[tuple[SlotInput, SolverKit]]:
    kit = SolverKit(s)
    out = []
    for seed in range(1, seeds + 1):
        _, inputs = record_slot_inputs(s, "proposed-sca", draw_run_noise(s, seed), kit)
        out += [(inp, kit) for inp in inputs[1 : per_seed + 1]]
    return out


def polish_with(solve: Solve, inp: SlotInput, kit: SolverKit) -> tuple[float, float, bool]:
    """(f of the kept plan, solve time s, kept): plan_slot's SCA plan, then `solve`."""
    s = kit.scenario
    sca = plan_slot(inp, kit, "proposed-sca")
    cons = SlotConstraints(
        inp.prev_xy_m, s.bs_xy[sca.bs_of_uav], s.bs_xy, inp.lead.state_pred[:2], s
    )
    obj = PlanningObjective(inp.lead.prior_information, inp.lead.state_pred, kit.sensing)
    t0 = time.perf_counter()
    x = solve(sca.uav_xy_m, sca.bandwidth_share, obj, cons)
    dt = time.perf_counter() - t0
    M = s.M
    xy, eta = x[: 2 * M].reshape(M, 2), np.maximum(x[2 * M :], 0.0)
    eta = eta / eta.sum()
    f = obj.value(xy, eta)
    if bool(cons.feasible(xy[None], eta[None])[0]) and f < sca.pcrb_trace:
        return f, dt, True
    return sca.pcrb_trace, dt, False


def ipopt(kit_of: dict[int, SolverKit]) -> Solve:
    def solve(
        xy0: np.ndarray, eta0: np.ndarray, obj: PlanningObjective, cons: SlotConstraints
    ) -> np.ndarray:
        nlp = polish_nlp(kit_of[cons.scenario.M])
        r = nlp.polish(xy0, eta0, obj, cons)
        return np.concatenate([r.uav_xy_m.ravel(), r.bandwidth_share])

    return solve


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--slots", type=int, default=20, help="slots per seed")
    args = ap.parse_args()
    cases = {
        "M=3 paper": load_scenario("paper"),
        "M=6 ring": ring_scenario(6, 8, 2, 60),
    }
    for name, s in cases.items():
        s = s.with_changes(planner=s.planner.model_copy(update={"polish": True}))
        data = slots(s, args.seeds, args.slots)
        kit_of = {s.M: data[0][1]}
        solvers: dict[str, Solve] = {
            "IPOPT (CasADi, exact Hessian)": ipopt(kit_of),
            "SLSQP (analytic gradients)": scipy_solver("SLSQP", 200),
            "trust-constr (analytic gradients, BFGS)": scipy_solver("trust-constr", 500),
        }
        f = np.empty((len(solvers), len(data)))
        t = np.empty_like(f)
        kept = np.empty_like(f, dtype=bool)
        for j, (inp, kit) in enumerate(data):
            for i, solve in enumerate(solvers.values()):
                f[i, j], t[i, j], kept[i, j] = polish_with(solve, inp, kit)
        sca = np.array([plan_slot(inp, kit, "proposed-sca").pcrb_trace for inp, kit in data])
        best = np.minimum(f.min(axis=0), sca)
        print(f"\n{name}: {len(data)} slots (M = {s.M})")
        print(
            f"{'solver':<40} {'median ms':>9} {'p95 ms':>7} {'median f/best-1':>15} "
            f"{'worst f/best-1':>14} {'at best':>7} {'kept':>5}"
        )
        print(
            f"{'SCA alone':<40} {'':>9} {'':>7} {np.median(sca / best - 1):>15.2e} "
            f"{np.max(sca / best - 1):>14.2e} {np.mean(sca <= best * (1 + 1e-6)):>7.0%} {'':>5}"
        )
        for i, label in enumerate(solvers):
            r = f[i] / best - 1
            print(
                f"{label:<40} {np.median(t[i]) * 1e3:>9.1f} {np.percentile(t[i], 95) * 1e3:>7.1f} "
                f"{np.median(r):>15.2e} {np.max(r):>14.2e} {np.mean(r <= 1e-6):>7.0%} "
                f"{np.mean(kept[i]):>5.0%}"
            )


if __name__ == "__main__":
    main()
