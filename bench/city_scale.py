"""The fleet at city scale: `proposed`, the centralized horizon and the horizon decomposed by
targets (docs/model.md, "Decomposed by targets") on fleets of M = 12 .. 96 UAVs with 1, 3 or 10
targets.

Scene of (M, T): config/city-48.yaml (M <= 48) or config/city-96.yaml, its UAVs thinned evenly to
M (every UAV keeps its start point, the band scaled to keep each UAV's share B / M and the noise
density: sigma0^2 scaled with B), its first T targets (the known ones first), `--slots` slots,
the live settings (vehicle model). Each cell is one closed-loop mission per method and seed (the
same noise for every method), flown in this process one after another. `horizon-dec` is
`horizon` with `planner.horizon.decompose: targets`; with --planner-workers N its groups are
solved on a loopback Dask cluster of N workers (isac_mission/planner_cluster.py) instead of in
this process, the same plans.

Per cell: the build (the method's warm-up: its NLPs for the whole fleet; the decomposed horizon
builds a group's sub-kit when it first meets that group size, within the plan times), the plan
time (report.solve_s) median and p95 over every slot of every seed, the slots
fallen back (any fallback kind, and the kinds), the mission mean of the summed tr(PCRB_pos) of
the confirmed tracks (m^2) and GOSPA (m), and their ratios to the centralized horizon's (where
it ran) and to `proposed`'s in the same run.

Run: python bench/city_scale.py [--sizes 12,24] [--targets 1,3] [--slots 20] [--seeds 1]
     [--methods proposed,horizon,horizon-dec] [--planner-workers 0]
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import math
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from seeds import parse_seeds  # noqa: E402

from isac_mission.config import Scenario, parse_scenario  # noqa: E402
from isac_mission.config.live_settings import LiveSettings  # noqa: E402
from isac_mission.experiment.runs import fly_outcomes, mission_run  # noqa: E402
from isac_mission.planning.decomposed import use_group_executor  # noqa: E402
from isac_mission.planning.slot import warm_up  # noqa: E402
from isac_mission.planning.tracks import multi_target_kit  # noqa: E402
from isac_mission.quiet import quiet_highs_banner  # noqa: E402

METHODS = ("proposed", "horizon", "horizon-dec")


def city_config(m: int, t: int, slots: int, decompose: bool) -> dict[str, object]:
    """The scenario mapping of the (m, t) scene (module docstring)."""
    base = "city-48" if m <= 48 else "city-96"
    cfg = yaml.safe_load((ROOT / "config" / f"{base}.yaml").read_text())
    starts = cfg["uavs"]["start_xy_m"]
    keep = np.unique(np.linspace(0, len(starts) - 1, m).round().astype(int))
    if len(keep) != m:
        raise ValueError(f"cannot thin {len(starts)} UAVs to {m}")
    ratio = m / len(starts)
    cfg["uavs"]["start_xy_m"] = [starts[i] for i in keep]
    cfg["radio"]["bandwidth_hz"] = float(cfg["radio"]["bandwidth_hz"]) * ratio
    cfg["radio"]["noise_power_dbm"] = float(cfg["radio"]["noise_power_dbm"]) + 10 * math.log10(
        ratio
    )
    targets = sorted(cfg["targets"], key=lambda e: e.get("prior") != "known")
    cfg["targets"] = targets[:t]
    cfg["timing"]["duration_s"] = slots
    cfg["mission_id"] = f"city-{m}-{t}"
    if decompose:
        cfg["planner"].setdefault("horizon", {})["decompose"] = "targets"
    out: dict[str, object] = cfg
    return out


def cell_scenario(m: int, t: int, slots: int, method: str) -> Scenario:
    """The live-settings scenario a cell flies (`horizon-dec` decomposed)."""
    s = parse_scenario(city_config(m, t, slots, decompose=method == "horizon-dec"))
    return LiveSettings().apply(s)


def fly_cell(s: Scenario, method: str, seeds: list[int], executor: object | None) -> dict:  # type: ignore[type-arg]
    """Per-slot plan times (s), fallback kinds, and per-seed mission figures of one cell."""
    flown = "horizon" if method == "horizon-dec" else method
    kit = multi_target_kit(s)
    started = time.monotonic()
    warm_up(kit, flown)  # type: ignore[arg-type]
    build_s = time.monotonic() - started
    if executor is not None and method == "horizon-dec":
        use_group_executor(kit, executor)  # type: ignore[arg-type]
    solve_s: list[float] = []
    kinds: collections.Counter[str] = collections.Counter()
    bounds, gospas = [], []
    for seed in seeds:
        outcomes = fly_outcomes(s, flown, seed, kit)  # type: ignore[arg-type]
        for o in outcomes:
            solve_s.append(o.plan.report.solve_s)
            if o.plan.report.fallback:
                kinds[o.plan.report.fallback] += 1
        bounds.append(
            float(
                np.mean(
                    [
                        sum(t.bound.position_trace for t in o.tracking.tracks if t.confirmed)
                        for o in outcomes
                    ]
                )
            )
        )
        gospas.append(float(np.mean(mission_run(s, flown, seed, outcomes).tracking.gospa_m)))
    return {"solve_s": solve_s, "kinds": kinds, "bound": bounds, "gospa": gospas, "build": build_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--sizes", default="12,24")
    ap.add_argument("--targets", default="1,3")
    ap.add_argument("--slots", type=int, default=20)
    ap.add_argument("--seeds", default="1")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--planner-workers", type=int, default=0)
    args = ap.parse_args()
    quiet_highs_banner()
    seeds = parse_seeds(args.seeds)
    methods = [m for m in args.methods.split(",") if m]
    for m in methods:
        if m not in METHODS:
            ap.error(f"--methods: {m!r} is not one of {', '.join(METHODS)}")
    print(
        f"{args.slots} slots, seeds {args.seeds}, planner workers {args.planner_workers}; load "
        f"{Path('/proc/loadavg').read_text()[:14]}\n"
    )
    print(
        "| M | T | method | build (s) | plan median / p95 (ms) | fallbacks | mission sum "
        "tr(PCRB_pos) (m^2) | vs horizon | vs proposed | GOSPA (m) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    with contextlib.ExitStack() as stack:
        executor = None
        if args.planner_workers > 0:
            from isac_mission.planner_cluster import group_executor

            executor = stack.enter_context(group_executor(None, args.planner_workers))
        for m in [int(x) for x in args.sizes.split(",")]:
            for t in [int(x) for x in args.targets.split(",")]:
                cells = {}
                for method in methods:
                    s = cell_scenario(m, t, args.slots, method)
                    started = time.monotonic()
                    cells[method] = fly_cell(s, method, seeds, executor)
                    cells[method]["wall"] = time.monotonic() - started
                for method, c in cells.items():
                    p50, p95 = 1e3 * np.percentile(c["solve_s"], [50, 95])
                    n = len(c["solve_s"])
                    fell = sum(c["kinds"].values())
                    bound = float(np.mean(c["bound"]))
                    ratios = [
                        f"{bound / float(np.mean(cells[ref]['bound'])):.3f}" if ref in cells else ""
                        for ref in ("horizon", "proposed")
                    ]
                    print(
                        f"| {m} | {t} | {method} | {c['build']:.1f} | {p50:.0f} / {p95:.0f} "
                        f"| {fell} of {n} "
                        f"({100 * fell / n:.1f} %) | {bound:.4g} | {ratios[0]} | {ratios[1]} "
                        f"| {np.mean(c['gospa']):.3f} |"
                    )
                for method, c in cells.items():
                    if c["kinds"]:
                        print(f"  {m}/{t} {method} fallbacks: {dict(c['kinds'])}")


if __name__ == "__main__":
    main()
