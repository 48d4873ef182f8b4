"""The receding horizon beside `proposed` on fleets of M = 3 .. 48 UAVs (docs/performance.md,
"The receding horizon at fleet scale").

Fleet of M: the UAVs on a jittered grid over the area (jitter +-60 m, seeded by M), K = max(5,
M // 2) random BSs, N_a = ceil(M / K) + 1, the paper's bandwidth per UAV (B = 20 MHz x M / 3),
planned with the live settings (vehicle model on). Each cell is one closed-loop mission per
method and seed (the same noise for both methods), run in a subprocess of its own.

Per M and method: build (the method's prepare, cold: there is no disk cache), median and p95 of the
plan time (report.solve_s), and for `horizon` IPOPT's iterations (median, max) and the slots
converged (its answer flown), stopped at the iteration cap on a feasible, lower iterate (flown),
at the cap otherwise (the per-slot plan flown instead) and fallen back for another reason; the
mission-mean tr(PCRB) of each method's own closed loop and their ratio. With --compare-tree the
package in DIR runs the same cells, interleaved with this tree's (old, new per seed), so both see
the same load. With --compiled this tree also runs them with its IPOPT problems compiled
(isac_mission/nlp_cache.py, in a cache of the bench's own that starts empty: the first seed's
build is cold, compile included, the next ones load it; `cold s` is the largest build).

Safety, per M and method: the slots flown on the best effort (infeasible) or by the evasion guard
(evasive), and the smallest UAV-UAV and UAV-to-true-target distances along the flown legs
(`flown_gaps_m`), with the slots where a UAV pair came within D_s.

Run: python bench/horizon_fleet.py [--sizes 3,6,12] [--slots 60] [--seeds 1,2,3] [--methods ...]
     python bench/horizon_fleet.py --compare-tree DIR [...]   (before/after in one run)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

METHODS = ("proposed", "horizon")
COMPILED_ENV = "BENCH_COMPILED"
"""Set in a cell's environment: plan with compiled IPOPT problems."""
AT_CAP_NOTE = "its last iterate kept"
"""planning/horizon.py's note of a capped iterate flown (a literal: the cells may import an
older package, which has none)."""


def fleet_config(m: int, slots: int) -> dict[str, object]:
    """The scenario mapping of a fleet of m UAVs (module docstring), before the live settings."""
    k = max(5, m // 2)
    rng = np.random.default_rng(1000 + m)
    n = math.ceil(math.sqrt(m))
    grid = (np.arange(n) + 0.5) / n
    cells = np.array([(x, y) for y in grid for x in grid])[:m]
    start = 300 + 2400 * cells + rng.uniform(-60, 60, size=(m, 2))
    return {
        "timing": {"duration_s": slots, "slot_s": 1.0},
        "radio": {"bs_capacity": math.ceil(m / k) + 1, "bandwidth_hz": 20e6 * m / 3},
        "base_stations": {"count": k},
        "uavs": {"start_xy_m": start.round(1).tolist()},
        "planner": {"polish": True},
    }


def fleet_scenario(m: int, slots: int):  # type: ignore[no-untyped-def]
    """The live planning scenario of a fleet of m UAVs (module docstring)."""
    from isac_mission.config import parse_scenario
    from isac_mission.config.live_settings import LiveSettings

    return LiveSettings().apply(parse_scenario(fleet_config(m, slots), f"fleet M={m}"))


def flown_gaps_m(s, outcomes) -> tuple[list[float], list[float]]:  # type: ignore[no-untyped-def]
    """Per slot, the smallest UAV-UAV distance and the smallest UAV-to-true-target distance (m)
    along the flown legs: the cubic Hermite legs from each slot's start (position, velocity) to
    its plan's (waypoint, end velocity), the target on the chord between its true states, at 41
    instants a slot."""
    from isac_mission.model.vehicle import hermite_position

    uav_gaps, target_gaps = [], []
    fractions = np.linspace(0, 1, 41)
    target_from = s.x0[:2]
    for o in outcomes:
        p0, v0 = o.slot_input.prev_xy_m, o.slot_input.prev_velocity_mps
        p1, v1 = o.plan.uav_xy_m, o.plan.uav_velocity_mps
        pts = np.stack([hermite_position(p0, v0, p1, v1, s.dt, f) for f in fractions])
        d = np.linalg.norm(pts[:, :, None] - pts[:, None], axis=-1) + 1e9 * np.eye(s.M)
        uav_gaps.append(float(d.min()))
        target = target_from + fractions[:, None] * (o.target_true[:2] - target_from)
        target_gaps.append(float(np.linalg.norm(pts - target[:, None], axis=-1).min()))
        target_from = o.target_true[:2]
    return uav_gaps, target_gaps


def run_cell(
    m: int, slots: int, seed: int, methods: tuple[str, ...]
) -> dict[str, dict[str, object]]:
    """The methods' closed loops at M = m, seed `seed`: what the table needs, as JSON values."""
    from isac_mission.experiment.closed_loop import SlotOutcome, draw_run_noise, run_closed_loop
    from isac_mission.planning.registry import planner
    from isac_mission.planning.slot import SolverKit

    s = fleet_scenario(m, slots)
    out: dict[str, dict[str, object]] = {}
    for method in methods:
        if os.environ.get(COMPILED_ENV):
            from isac_mission.nlp_cache import CompiledNlpCache

            kit = SolverKit(s, ipopt=CompiledNlpCache(compile="now"))
        else:
            kit = SolverKit(s)
        t0 = time.perf_counter()
        planner(method).prepare(kit)
        build_s = time.perf_counter() - t0
        outcomes: list[SlotOutcome] = []
        result = run_closed_loop(s, method, draw_run_noise(s, seed), kit, outcomes.append)
        reports = [o.plan.report for o in outcomes]
        notes = [f"fallback {r.fallback}: {r.reason}" if r.fallback else r.polish for r in reports]
        uav_gaps, target_gaps = flown_gaps_m(s, outcomes)
        run = MethodRun(
            build_s,
            [float(t) for t in result.solve_s],
            float(np.mean(result.pcrb)),
            notes,
            [r.fallback for r in reports],
            uav_gaps,
            target_gaps,
            float(s.d_safe),
        )
        out[method] = asdict(run)
    return out


def horizon_counts(notes: list[str]) -> tuple[list[int], int, int, int, int]:
    """(iterations, converged, accepted at the cap, fallen back at the cap, other fallbacks)
    from the horizon's slot notes."""
    iterations = [
        int(g) for note in notes for g in re.findall(r"IPOPT \w+ (?:in|after) (\d+) it", note)
    ]
    kept = sum(AT_CAP_NOTE in note for note in notes)
    capped = sum(note.startswith("fallback horizon: IPOPT Maximum_Iterations") for note in notes)
    converged = sum(not note.startswith("fallback ") for note in notes) - kept
    return iterations, converged, kept, capped, len(notes) - converged - kept - capped


@dataclass
class MethodRun:
    """One method's closed loop in one cell: build (s), plan times [N] (s), mean tr(PCRB), the
    slot notes (report.polish, or "fallback KIND: REASON"), the fallback kinds [N], the
    smallest UAV-UAV and UAV-target distances along each slot's flown legs [N] (m), D_s (m)."""

    build_s: float
    solve_s: list[float]
    pcrb: float
    notes: list[str]
    fallbacks: list[str]
    uav_gap_m: list[float]
    target_gap_m: list[float]
    d_safe_m: float


def collect(
    tree: str, m: int, slots: int, seed: int, methods: tuple[str, ...], compiled_cache: str = ""
) -> dict[str, MethodRun]:
    """run_cell in a subprocess with the package of `tree`; with compiled_cache (a directory),
    its IPOPT problems compiled and cached there."""
    env = {**os.environ, "PYTHONPATH": tree}
    if compiled_cache:
        env.update({COMPILED_ENV: "1", "ISAC_MISSION_NLP_CACHE": compiled_cache})
    out = subprocess.run(
        [sys.executable, __file__, "--cell", str(m), str(slots), str(seed), *methods],
        cwd=tree,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    cell = json.loads(out.stdout.strip().splitlines()[-1])
    return {method: MethodRun(**cell[method]) for method in methods}


def table(rows: list[tuple[str, int, dict[str, list[MethodRun]]]]) -> None:
    """Print one line per (tree, M, method)."""
    print(
        f"{'tree':<8} {'M':>3} {'method':<9} {'slots':>5} {'build s':>8} {'cold s':>7} "
        f"{'median ms':>9} "
        f"{'p95 ms':>8} {'it med':>6} {'it max':>6} {'conv':>5} {'kept':>4} {'cap':>4} {'other':>5} "
        f"{'inf':>4} {'evas':>4} {'gap m':>6} {'<D_s':>4} {'tgt m':>6} "
        f"{'tr(PCRB)':>10} {'/ prop.':>7} {'t / prop.':>9}"
    )
    for tree, m, cells in rows:
        proposed_pcrb = float(np.mean([c.pcrb for c in cells["proposed"]]))
        proposed_ms = 1e3 * float(np.median([t for c in cells["proposed"] for t in c.solve_s]))
        for method, runs in cells.items():
            times = 1e3 * np.array([t for c in runs for t in c.solve_s])
            pcrb = float(np.mean([c.pcrb for c in runs]))
            counts = f"{'':>6} {'':>6} {'':>5} {'':>4} {'':>4} {'':>5}"
            if method == "horizon":
                its, conv, kept, cap, other = horizon_counts([n for c in runs for n in c.notes])
                med, top = (f"{np.median(its):.0f}", str(max(its))) if its else ("-", "-")
                counts = f"{med:>6} {top:>6} {conv:>5d} {kept:>4d} {cap:>4d} {other:>5d}"
            kinds = [f for c in runs for f in c.fallbacks]
            gaps = [g for c in runs for g in c.uav_gap_m]
            below = sum(g < c.d_safe_m for c in runs for g in c.uav_gap_m)
            target = min(g for c in runs for g in c.target_gap_m)
            safety = (
                f"{kinds.count('infeasible'):>4d} {kinds.count('evasive'):>4d} "
                f"{min(gaps):>6.1f} {below:>4d} {target:>6.1f}"
            )
            builds = [c.build_s for c in runs]
            print(
                f"{tree:<8} {m:>3} {method:<9} {len(times):>5} "
                f"{np.median(builds):>8.1f} {max(builds):>7.1f} {np.median(times):>9.1f} "
                f"{np.percentile(times, 95):>8.1f} {counts} {safety} {pcrb:>10.4g} "
                f"{pcrb / proposed_pcrb:>7.3f} {np.median(times) / proposed_ms:>9.1f}"
            )
    print(
        "build: the method's prepare, median over seeds (cold s: the largest; compiled: the first "
        "seed compiles); it: IPOPT's iterations; conv: "
        "IPOPT converged, its answer flown; kept: IPOPT at max_iterations, its feasible, lower "
        "last iterate flown; cap: at max_iterations, the per-slot plan flown; other: "
        "fallen back for another reason; inf, evas: slots whose fallback is infeasible (the best "
        "effort) or evasive (the guard); gap m: the smallest UAV-UAV distance along the flown "
        "legs, <D_s: slots where it is below D_s; tgt m: the smallest UAV-to-true-target "
        "distance; tr(PCRB): mission mean of the method's own closed loop, "
        "mean over seeds; / prop.: against proposed's; t / prop.: median plan time against "
        "proposed's"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", default="3,6,12", help="fleet sizes M (comma-separated)")
    ap.add_argument("--slots", type=int, default=60, help="slots per mission")
    ap.add_argument("--seeds", default="1,2,3", help="noise seeds (comma-separated)")
    ap.add_argument("--methods", default=",".join(METHODS), help="proposed and/or horizon")
    ap.add_argument("--compare-tree", metavar="DIR", help="also the isac_mission package in DIR")
    ap.add_argument(
        "--compiled", action="store_true", help="also this tree with compiled IPOPT problems"
    )
    ap.add_argument("--cell", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.cell:
        m, slots, seed = (int(v) for v in args.cell[:3])
        print(json.dumps(run_cell(m, slots, seed, tuple(args.cell[3:]) or METHODS)))
        return
    methods = tuple(args.methods.split(","))
    if "proposed" not in methods or not set(methods) <= set(METHODS):
        ap.error(f"--methods: proposed and a subset of {', '.join(METHODS)}")
    here = str(Path(__file__).resolve().parent.parent)
    trees = {"after": (here, "")}
    if args.compare_tree:
        trees = {"before": (str(Path(args.compare_tree).resolve()), ""), "after": (here, "")}
    if args.compiled:
        trees["compiled"] = (here, tempfile.mkdtemp(prefix="bench-nlp-cache-"))
    t_start = time.perf_counter()
    rows = []
    for m in (int(v) for v in args.sizes.split(",")):
        cells: dict[str, dict[str, list[MethodRun]]] = {
            t: {method: [] for method in methods} for t in trees
        }
        for seed in (int(v) for v in args.seeds.split(",")):
            for name, (tree, cache) in trees.items():
                for method, cell in collect(tree, m, args.slots, seed, methods, cache).items():
                    cells[name][method].append(cell)
        rows += [(name, m, cells[name]) for name in trees]
    table(rows)
    print(f"\ntotal {time.perf_counter() - t_start:.0f} s; load {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
