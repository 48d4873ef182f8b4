"""The receding horizon's plan time with several targets against one, at the same fleet size
(docs/performance.md, "The receding horizon for several targets").

Fleet of M: bench/horizon_fleet.py's (the UAVs on a jittered grid, K = max(5, M // 2) random BSs,
the live settings). Targets: T intruders known from the start (`prior: known`), spread on a
circle of radius 1000 m about the area's centre and flying along it at 20 m/s (constant velocity
between slots), detected every slot with no false alarm, tracked by the multi-target tracker for
every T (one target is the case T = 1 of the same tracker). Each cell (M, T) is one closed-loop
mission per seed, flown by `horizon` in this process, cells interleaved per seed so that the
load falls on every cell alike.

Per cell: the median and p95 of the plan time (report.solve_s) over the slots of every seed, the
slots that fell back (with their kinds), the mission-mean weighted tr(PCRB) of the confirmed
tracks, and the median's ratio to the one-target cell at the same M (same run).

Run: python bench/horizon_targets.py [--cells 6:3,24:10] [--slots 20] [--seeds 1,2]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

SPEED_MPS = 20.0
RADIUS_M = 1000.0


def scenario_of(m: int, n_targets: int, slots: int):  # type: ignore[no-untyped-def]
    """The fleet of m UAVs (bench/horizon_fleet.py) with n_targets known intruders (module
    docstring), tracked by the multi-target tracker."""
    from horizon_fleet import fleet_config

    from isac_mission.config import parse_scenario
    from isac_mission.config.live_settings import LiveSettings

    targets = []
    for i in range(n_targets):
        a = 2 * math.pi * (i + 0.37) / n_targets
        x, y = 1500 + RADIUS_M * math.cos(a), 1500 + RADIUS_M * math.sin(a)
        vx, vy = -SPEED_MPS * math.sin(a), SPEED_MPS * math.cos(a)
        targets.append(
            {
                "name": f"t{i + 1}",
                "initial_state": [round(x, 1), round(y, 1), round(vx, 3), round(vy, 3)],
                "rcs_dbsm": -10,
                "prior": "known",
            }
        )
    s = parse_scenario(
        fleet_config(m, slots)
        | {
            "targets": targets,
            "detection": {"model": "fixed", "false_alarms_per_slot": 0},
            "tracker": {"kind": "multi"},
        },
        f"fleet M={m}, {n_targets} targets",
    )
    return LiveSettings().apply(s)


@dataclass
class Cell:
    """What one (M, T) cell measured over its seeds."""

    solve_ms: list[float] = field(default_factory=list)
    fallbacks: Counter[str] = field(default_factory=Counter)
    pcrb: list[float] = field(default_factory=list)
    build_s: list[float] = field(default_factory=list)


def fly(m: int, n_targets: int, slots: int, seed: int, cell: Cell) -> None:
    """One closed-loop mission of `horizon` in cell (m, n_targets), added to `cell`."""
    from isac_mission.experiment.runs import fly_outcomes, kit_for
    from isac_mission.planning.slot import warm_up

    s = scenario_of(m, n_targets, slots)
    kit = kit_for(s)
    t0 = time.perf_counter()
    warm_up(kit, "horizon")
    cell.build_s.append(time.perf_counter() - t0)
    outcomes = fly_outcomes(s, "horizon", seed, kit)
    for o in outcomes:
        report = o.plan.report
        cell.solve_ms.append(1e3 * report.solve_s)
        if report.fallback:
            cell.fallbacks[report.fallback] += 1
        if np.isfinite(o.plan.pcrb_trace):
            cell.pcrb.append(float(o.plan.pcrb_trace))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", default="6:3,24:10", help="M:T pairs; each also runs M:1")
    ap.add_argument("--slots", type=int, default=20)
    ap.add_argument("--seeds", default="1,2")
    args = ap.parse_args()
    pairs = [tuple(int(v) for v in c.split(":")) for c in args.cells.split(",")]
    cells_mt = sorted({(m, t) for m, n in pairs for t in (1, n)})
    seeds = [int(v) for v in args.seeds.split(",")]
    results = {mt: Cell() for mt in cells_mt}
    for seed in seeds:
        for m, t in cells_mt:
            started = time.perf_counter()
            fly(m, t, args.slots, seed, results[(m, t)])
            took = time.perf_counter() - started
            print(f"M = {m}, T = {t}, seed {seed}: {took:.0f} s", file=sys.stderr, flush=True)
    print(f"horizon, {args.slots} slots x seeds {seeds}; plan ms median / p95; ratio to T = 1")
    print(
        f"{'M':>3} {'T':>3} {'median':>8} {'p95':>8} {'ratio':>6} {'build s':>8} "
        f"{'mean pcrb':>10}  fallbacks"
    )
    for m, t in cells_mt:
        c = results[(m, t)]
        med = float(np.median(c.solve_ms))
        one = float(np.median(results[(m, 1)].solve_ms))
        falls = ", ".join(f"{k} {v}" for k, v in sorted(c.fallbacks.items())) or "0"
        print(
            f"{m:>3} {t:>3} {med:>8.1f} {np.percentile(c.solve_ms, 95):>8.1f} {med / one:>6.2f} "
            f"{np.median(c.build_s):>8.2f} {np.mean(c.pcrb):>10.4f}  {falls}"
        )


if __name__ == "__main__":
    main()
