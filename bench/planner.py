"""Per-slot planning time of every method for M = 3, 6, 12 UAVs (median, p95, ratio).

Each scenario is the paper's with M UAVs on a ring around the area centre and K BSs placed at
random (K = 5, 8, 12; N_a = 3, 3, 4). Every method flies the closed loop for `--slots` slots, so
the timed slots are the states the method itself produces. Ratios are against the proposed
method at M = 3, measured in the same run. Run: python bench/planner.py [--slots 20] [--runs 1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from isac_mission.config import Scenario, parse_scenario
from isac_mission.experiment.closed_loop import draw_run_noise, run_closed_loop
from isac_mission.planning.slot import METHODS, SolverKit

SIZES = ((3, 5, 3), (6, 8, 3), (12, 12, 4))


def scenario(m: int, k: int, n_a: int, slots: int) -> Scenario:
    angles = np.linspace(0, 2 * np.pi, m, endpoint=False) + 0.3
    start = 1500 + 700 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return parse_scenario(
        {
            "timing": {"duration_s": slots, "slot_s": 1.0},
            "radio": {"bs_capacity": n_a},
            "base_stations": {"count": k},
            "uavs": {"start_xy_m": start.round(1).tolist()},
        },
        f"bench M={m}",
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--slots", type=int, default=20)
    ap.add_argument("--runs", type=int, default=1)
    args = ap.parse_args()
    rows = []
    for m, k, n_a in SIZES:
        s = scenario(m, k, n_a, args.slots)
        kit = SolverKit(s)
        t0 = time.perf_counter()
        kit.warm_up()
        compile_ms = (time.perf_counter() - t0) * 1e3
        for method in METHODS:
            times = np.concatenate(
                [
                    run_closed_loop(s, method, draw_run_noise(s, 100 + r), kit).solve_s
                    for r in range(args.runs)
                ]
            )
            rows.append(
                (m, k, method, np.median(times) * 1e3, np.percentile(times, 95) * 1e3, compile_ms)
            )
    base = next(r[3] for r in rows if r[0] == 3 and r[2] == "proposed")
    print(f"per-slot planning time, {args.slots} slots x {args.runs} run(s) per cell")
    print(
        f"{'M':>3} {'K':>3} {'method':<9} {'median ms':>10} {'p95 ms':>9} {'ratio':>7} {'build+warm ms':>14}"
    )
    for m, k, method, med, p95, comp in rows:
        print(
            f"{m:>3} {k:>3} {method:<9} {med:>10.1f} {p95:>9.1f} {med / base:>7.2f} {comp:>14.0f}"
        )
    print("ratio = median / median of proposed at M = 3 (same run)")


if __name__ == "__main__":
    main()
