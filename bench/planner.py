"""Per-slot planning time and memory of every strategy and SOCP solver for M = 3 .. 24 UAVs.

Each scenario is the paper's with M UAVs on a ring around the area centre and K BSs placed at
random (M, K) = (3, 5), (6, 8), (12, 12), (24, 20), N_a = ceil(M / K) + 1. Every cell flies the
closed loop for its number of slots, so the timed slots are the states the strategy itself
produces (one run, seed 100).

Cells per M: the five strategies with the default kit (position subproblem by CLARABEL called
directly), then the proposed method with the position subproblem through cvxpy (CLARABEL, SCS),
and `reference`: the proposed method with SolverKit(fast=False), every subproblem through cvxpy
as before the fast paths (docs/decisions/0004-planner-fast-paths.md). OSQP, HIGHS and SCIPY cannot solve the
SOCP and ECOS is not installed.

Time: plan_slot's own clock (report.solve_s), median and p95 over slots. Memory: tracemalloc peak
of one plan_slot call on the first slots' inputs (replayed after timing, median over them): Python
and numpy allocations; the solvers' native (Rust / C) heaps are not seen by tracemalloc.
Ratios are against the proposed method at M = 3 of the same run; `vs ref` is reference median /
cell median at the same M (the speed-up of the performance work).

The second table replays the proposed method's own slot inputs through the reference kit: the
largest waypoint difference and the relative difference of the plan's tr(PCRB).

The third table replays the proposed method's slot inputs through `proposed-sca` (Algorithm 2
alone) and `proposed` (Algorithm 2 + the polish, planning/polish.py), interleaved slot by slot:
median plan time of each, their ratio, IPOPT's iterations and the polish's gain in tr(PCRB).

The last table, "plan time per method and M", gives for each method of --methods (default: every
one of proposed, sd, aba, crb, horizon that planning.slot.METHODS has) and each M its median and
p95 plan time and the ratio of its median to the proposed method's at the same M, all from this
one run. --methods-only times just those cells (no solver, reference or polish cells).

With --fleet: the receding horizon beside `proposed` on the fleets of bench/horizon_fleet.py,
M = 3, 6, 12, 24, 48 (with --compiled also with the IPOPT problems compiled: the first seed's
build cold in an empty cache, the next ones warm): median and p95 plan time, build time, IPOPT's
iterations, the slots converged, kept at the cap and fallen back, the mission's tr(PCRB)
against `proposed`'s.

Run: python bench/planner.py [--slots 20] [--slots-24 6] [--quick] [--methods proposed,horizon]
     python bench/planner.py --fleet [--slots 60] [--seeds 1,2,3] [--sizes ...] [--compare-tree DIR]
     python bench/planner.py --methods-only [--methods ...]   (the per-method table alone)
     python bench/planner.py --compare-tree DIR [--rounds 3] [--methods ...]   (before/after)
     python bench/planner.py --profile M                       (cProfile of the proposed method)
"""

from __future__ import annotations

import argparse
import cProfile
import json
import math
import os
import pstats
import subprocess
import sys
import time
import tracemalloc
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np

from isac_mission.config import Scenario, parse_scenario
from isac_mission.experiment.closed_loop import draw_run_noise, record_slot_inputs, run_closed_loop
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.positions import PositionSubproblem
from isac_mission.planning.slot import METHODS, Method, SlotInput, plan_slot, warm_up

SIZES = ((3, 5), (6, 8), (12, 12), (24, 20))
DEFAULT_METHODS = tuple(m for m in ("proposed", "sd", "aba", "crb", "horizon") if m in METHODS)
MEMORY_SLOTS = 3


def scenario(m: int, k: int, n_a: int, slots: int, solver: str = "CLARABEL") -> Scenario:
    """The paper's scenario with m UAVs on a 700 m ring, k random BSs of capacity n_a."""
    angles = np.linspace(0, 2 * np.pi, m, endpoint=False) + 0.3
    start = 1500 + 700 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return parse_scenario(
        {
            "timing": {"duration_s": slots, "slot_s": 1.0},
            "radio": {"bs_capacity": n_a},
            "base_stations": {"count": k},
            "uavs": {"start_xy_m": start.round(1).tolist()},
            "planner": {"solver": solver, "polish": True},
        },
        f"bench M={m}",
    )


@dataclass
class Cell:
    """One row of the table."""

    m: int
    k: int
    method: str
    solver: str
    times_s: np.ndarray
    ok_fraction: float
    peak_kib: float
    inputs: list[SlotInput]


def make_kit(s: Scenario, solver: str) -> SolverKit:
    """The kit of a cell: solver "CLARABEL" = direct call (default), "CLARABEL/cvxpy" and "SCS"
    through cvxpy, "reference" = SolverKit(fast=False)."""
    if solver == "reference":
        return SolverKit(s, fast=False)
    if solver == "CLARABEL/cvxpy":
        kit = SolverKit(s)
        kit.positions = PositionSubproblem(s, "CLARABEL", direct=False)
        return kit
    return SolverKit(s.with_changes(planner=s.planner.model_copy(update={"solver": solver})))


def recorded_run(
    s: Scenario, method: Method, kit: SolverKit
) -> tuple[np.ndarray, float, list[SlotInput]]:
    """Closed loop of one run: per-slot planning times [N], the fraction of slots with status
    ok, and the slot inputs seen."""
    result, inputs = record_slot_inputs(s, method, draw_run_noise(s, 100), kit)
    return result.solve_s, float(np.mean([v == "ok" for v in result.status])), inputs


def peak_memory_kib(inputs: list[SlotInput], kit: SolverKit, method: Method) -> float:
    """Median over the first slots of the tracemalloc peak of one plan_slot call, KiB."""
    peaks = []
    for inp in inputs[:MEMORY_SLOTS]:
        tracemalloc.start()
        plan_slot(inp, kit, method)
        peaks.append(tracemalloc.get_traced_memory()[1] / 1024)
        tracemalloc.stop()
    return float(np.median(peaks))


def run_cell(m: int, k: int, slots: int, method: Method, solver: str) -> Cell:
    s = scenario(m, k, math.ceil(m / k) + 1, slots)
    kit = make_kit(s, solver)
    warm_up(kit, method)  # the method's own problems built before timing
    s = kit.scenario
    times, ok, inputs = recorded_run(s, method, kit)
    return Cell(m, k, method, solver, times, ok, peak_memory_kib(inputs, kit, method), inputs)


def agreement(cell: Cell, slots: int) -> tuple[float, float, float, float, int]:
    """Replay the cell's inputs through the reference kit: (median and max |dQ| m, median and
    max of the signed relative difference of tr(PCRB), default / reference - 1; slots)."""
    s = scenario(cell.m, cell.k, math.ceil(cell.m / cell.k) + 1, slots)
    fast, ref = SolverKit(s), SolverKit(s, fast=False)
    dq, dtr = [], []
    for inp in cell.inputs:
        a, b = plan_slot(inp, fast, "proposed"), plan_slot(inp, ref, "proposed")
        dq.append(float(np.abs(a.uav_xy_m - b.uav_xy_m).max()))
        dtr.append(a.pcrb_trace / b.pcrb_trace - 1)
    worst = float(max(dtr, key=abs))
    return float(np.median(dq)), max(dq), float(np.median(dtr)), worst, len(cell.inputs)


TIMING_CODE = """
import json, sys
import numpy as np
from isac_mission.config import parse_scenario
from isac_mission.experiment.closed_loop import draw_run_noise, run_closed_loop
from isac_mission.planning.registry import planner
from isac_mission.planning.slot import SolverKit
m, k, n_a, slots = map(int, sys.argv[1:5])
method = sys.argv[5]
angles = np.linspace(0, 2 * np.pi, m, endpoint=False) + 0.3
start = 1500 + 700 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
s = parse_scenario({"timing": {"duration_s": slots, "slot_s": 1.0},
                    "radio": {"bs_capacity": n_a}, "base_stations": {"count": k},
                    "uavs": {"start_xy_m": start.round(1).tolist()}}, "bench")
kit = SolverKit(s)
planner(method).prepare(kit)
print(json.dumps(run_closed_loop(s, method, draw_run_noise(s, 100), kit).solve_s.tolist()))
"""


def compare_trees(
    old_tree: str, rounds: int, slots: int, slots_24: int, methods: tuple[str, ...] = ("proposed",)
) -> None:
    """Each method at M = 3, and `proposed` also at M = 24: the package in old_tree against this
    tree, interleaved in subprocesses (old, new, old, new, ...) so that both see the same load."""
    new_tree = str(Path(__file__).resolve().parent.parent)
    print(f"before = {old_tree}, after = {new_tree}; {rounds} interleaved rounds")
    print(
        f"{'method':>9} {'M':>3} {'slots':>5} {'before ms':>9} {'p95':>7} {'after ms':>9} "
        f"{'p95':>7} {'speed-up':>8}"
    )
    cells = [(method, SIZES[0]) for method in methods]
    if "proposed" in methods:
        cells.append(("proposed", SIZES[-1]))
    for method, (m, k) in cells:
        n = slots_24 if m >= 24 else slots
        times: dict[str, list[float]] = {old_tree: [], new_tree: []}
        for _ in range(rounds):
            for tree in times:
                out = subprocess.run(
                    [
                        sys.executable,
                        "-c",
                        TIMING_CODE,
                        str(m),
                        str(k),
                        str(math.ceil(m / k) + 1),
                        str(n),
                        method,
                    ],
                    cwd=tree,
                    env={**os.environ, "PYTHONPATH": tree},
                    capture_output=True,
                    text=True,
                    check=True,
                )
                times[tree] += json.loads(out.stdout.strip().splitlines()[-1])
        before, after = (np.array(times[old_tree]) * 1e3, np.array(times[new_tree]) * 1e3)
        print(
            f"{method:>9} {m:>3} {len(after):>5} {np.median(before):>9.1f} "
            f"{np.percentile(before, 95):>7.1f} "
            f"{np.median(after):>9.1f} {np.percentile(after, 95):>7.1f} "
            f"{np.median(before) / np.median(after):>8.2f}"
        )


def profile(m: int, slots: int) -> None:
    """cProfile of one closed-loop run of the proposed method (after warm-up), top 30 by
    cumulative time."""
    k = dict(SIZES).get(m, max(5, m))
    s = scenario(m, k, math.ceil(m / k) + 1, slots)
    kit = SolverKit(s)
    warm_up(kit)
    prof = cProfile.Profile()
    prof.enable()
    result = run_closed_loop(s, "proposed", draw_run_noise(s, 100), kit)
    prof.disable()
    print(f"M = {m}, K = {k}, {slots} slots: median {np.median(result.solve_s) * 1e3:.1f} ms")
    pstats.Stats(prof).sort_stats("cumulative").print_stats(30)


def method_table(cells: list[Cell], methods: list[str]) -> None:
    """Median / p95 plan time per method and M, and the median's ratio to proposed's (same M)."""
    print("\nplan time per method and M (ms; ratio = median / proposed's median at the same M)")
    head = f"{'M':>3} {'slots':>5} " + " ".join(
        f"{m + ' med':>14} {'p95':>7} {'ratio':>6}" for m in methods
    )
    print(head)
    for m_uavs in sorted({c.m for c in cells}):
        row = {c.method: c.times_s * 1e3 for c in cells if c.m == m_uavs and c.solver == "CLARABEL"}
        base = float(np.median(row["proposed"])) if "proposed" in row else math.nan
        n = len(next(iter(row.values())))
        cols = []
        for method in methods:
            ms = row[method]
            med = float(np.median(ms))
            cols.append(f"{med:>14.1f} {np.percentile(ms, 95):>7.1f} {med / base:>6.2f}")
        print(f"{m_uavs:>3} {n:>5} " + " ".join(cols))


def parse_methods(text: str) -> list[Method]:
    """--methods: comma-separated names of planning.slot.METHODS (exit with a message if not)."""
    chosen = [m.strip() for m in text.split(",") if m.strip()]
    unknown = sorted(set(chosen) - set(METHODS))
    if unknown or not chosen:
        raise SystemExit(f"--methods: unknown {unknown}; choose from {', '.join(METHODS)}")
    return [cast("Method", m) for m in chosen]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--slots", type=int, default=20, help="slots per cell for M <= 12")
    ap.add_argument("--slots-24", type=int, default=6, help="slots per cell at M = 24")
    ap.add_argument("--quick", action="store_true", help="smoke run: M = 3, 6; 4 slots")
    ap.add_argument(
        "--methods",
        default=",".join(DEFAULT_METHODS),
        help=f"methods timed per M (default {','.join(DEFAULT_METHODS)})",
    )
    ap.add_argument(
        "--methods-only",
        action="store_true",
        help="only the per-method timing table (no solver, reference or polish cells)",
    )
    ap.add_argument(
        "--compare-tree",
        metavar="DIR",
        help="instead: before/after medians of the proposed method at M = 3, 24 against the "
        "isac_mission package in DIR (e.g. git archive HEAD isac_mission | tar -x -C DIR)",
    )
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds for --compare-tree")
    ap.add_argument(
        "--profile",
        type=int,
        metavar="M",
        help="instead: cProfile one closed-loop run of the proposed method at M UAVs",
    )
    ap.add_argument(
        "--fleet",
        nargs=argparse.REMAINDER,
        metavar="ARGS",
        help="instead: the horizon beside `proposed` on fleets of M = 3 .. 48 "
        "(bench/horizon_fleet.py --sizes 3,6,12,24,48 ARGS; e.g. --fleet --slots 60 --seeds "
        "1,2,3 --compare-tree DIR, or --compiled for cold and warm builds of compiled problems)",
    )
    args = ap.parse_args()
    if args.fleet is not None:
        fleet = Path(__file__).with_name("horizon_fleet.py")
        command = [sys.executable, str(fleet), "--sizes", "3,6,12,24,48"]
        sys.exit(subprocess.run([*command, *args.fleet], check=False).returncode)
    if args.profile:
        profile(args.profile, args.slots_24 if args.profile >= 24 else args.slots)
        return
    if args.compare_tree:
        compare_trees(
            str(Path(args.compare_tree).resolve()),
            args.rounds,
            args.slots,
            args.slots_24,
            tuple(parse_methods(args.methods)) if args.methods else ("proposed",),
        )
        return
    methods = parse_methods(args.methods)
    sizes = SIZES[:2] if args.quick else SIZES
    solvers = (
        ("CLARABEL/cvxpy", "reference") if args.quick else ("CLARABEL/cvxpy", "SCS", "reference")
    )
    t_start = time.perf_counter()
    cells: list[Cell] = []
    for m, k in sizes:
        slots = 4 if args.quick else (args.slots_24 if m >= 24 else args.slots)
        for method in methods:
            cells.append(run_cell(m, k, slots, method, "CLARABEL"))
        if args.methods_only:
            continue
        for solver in solvers:
            cells.append(run_cell(m, k, slots, "proposed", solver))
    if args.methods_only or "proposed" not in methods:
        method_table(cells, list(methods))
        print(f"\ntotal {time.perf_counter() - t_start:.0f} s")
        return
    base = next(float(np.median(c.times_s)) for c in cells if c.m == 3 and c.method == "proposed")
    ref = {c.m: float(np.median(c.times_s)) for c in cells if c.solver == "reference"}
    print("per-slot planning time and memory (one closed-loop run per cell, seed 100)")
    head = (
        f"{'M':>3} {'K':>3} {'N_a':>3} {'slots':>5} {'method':<12} {'solver':<15} {'median ms':>9} "
        f"{'p95 ms':>8} {'ratio':>6} {'vs ref':>6} {'ok %':>5} {'peak KiB':>9} {'mem ratio':>9}"
    )
    print(head)
    mem_base = next(c.peak_kib for c in cells if c.m == 3 and c.method == "proposed")
    for c in cells:
        med = float(np.median(c.times_s))
        p95 = float(np.percentile(c.times_s, 95))
        n_a = math.ceil(c.m / c.k) + 1
        print(
            f"{c.m:>3} {c.k:>3} {n_a:>3} {len(c.times_s):>5} {c.method:<12} {c.solver:<15} "
            f"{med * 1e3:>9.1f} {p95 * 1e3:>8.1f} {med / base:>6.2f} {ref[c.m] / med:>6.2f} "
            f"{c.ok_fraction:>5.0%} {c.peak_kib:>9.0f} {c.peak_kib / mem_base:>9.2f}"
        )
    print(
        "ratio = median / median of proposed (CLARABEL) at M = 3; vs ref = reference median / "
        "median (same M); peak = tracemalloc peak per plan_slot (Python + numpy heap), median of "
        f"{MEMORY_SLOTS} slots; mem ratio against proposed at M = 3"
    )
    print("\nsame inputs, default kit vs reference kit (proposed method)")
    print(
        f"{'M':>3} {'slots':>5} {'median |dQ| m':>13} {'max |dQ| m':>10} "
        f"{'median d tr':>11} {'largest d tr':>12}"
    )
    for c in cells:
        if c.method == "proposed" and c.solver == "CLARABEL":
            dq50, dq, dtr50, dtr, n = agreement(c, len(c.times_s))
            print(f"{c.m:>3} {n:>5} {dq50:>13.2e} {dq:>10.2e} {dtr50:>+11.1e} {dtr:>+12.1e}")
    print("d tr = tr(PCRB) of the default plan / reference plan - 1 (negative: default better)")
    polish_table(cells)
    method_table(cells, list(methods))
    print(f"\ntotal {time.perf_counter() - t_start:.0f} s")


def polish_table(cells: list[Cell], repeats: int = 3) -> None:
    """Polish on/off on the proposed cells' own inputs, interleaved (SCA, then SCA + polish, per
    slot, `repeats` times; the median of each slot's repeats)."""
    print("\npolish on/off, same inputs, interleaved (proposed-sca vs proposed)")
    print(
        f"{'M':>3} {'slots':>5} {'SCA ms':>8} {'SCA+polish ms':>13} {'ratio':>6} "
        f"{'IPOPT it':>8} {'median gain':>11} {'largest gain':>12} {'kept':>5}"
    )
    for c in cells:
        if c.method != "proposed" or c.solver != "CLARABEL":
            continue
        s = scenario(c.m, c.k, math.ceil(c.m / c.k) + 1, len(c.times_s))
        kit = SolverKit(s)
        warm_up(kit)
        t_sca, t_pol, iters, gain, kept = [], [], [], [], []
        for inp in c.inputs:
            a_s, b_s = [], []
            for _ in range(repeats):
                a = plan_slot(inp, kit, "proposed-sca")
                b = plan_slot(inp, kit, "proposed")
                a_s.append(a.report.solve_s)
                b_s.append(b.report.solve_s)
            t_sca.append(np.median(a_s))
            t_pol.append(np.median(b_s))
            iters.append(b.report.polish_iterations)
            gain.append(1 - b.pcrb_trace / a.pcrb_trace)
            kept.append(b.report.polish.startswith("polished"))
        med_a, med_b = float(np.median(t_sca)), float(np.median(t_pol))
        print(
            f"{c.m:>3} {len(c.inputs):>5} {med_a * 1e3:>8.1f} {med_b * 1e3:>13.1f} "
            f"{med_b / med_a:>6.2f} {np.median(iters):>8.0f} {np.median(gain):>11.2%} "
            f"{np.max(gain):>12.2%} {np.mean(kept):>5.0%}"
        )
    print("gain = 1 - tr(PCRB) polished / SCA; kept = share of slots where the polish was kept")


if __name__ == "__main__":
    main()
