"""Live against offline on a multi-target mission: does `simulate` predict the
service, phase by phase?

For each method and seed: the live mission in this process (`run_embedded`: the simulated world,
the MAVLink bridges and the multi-target ground loop over loopback Zenoh and UDP, lockstep at
--speed, the live settings, the 1 s plan budget; free ports, no console) and its offline twin
(experiment/runs.py `fly_outcomes` on the scenario with the live settings, the same seed: the
same targets, and the same reports wherever the UAVs are where their plans put them). From each
run's `track_figures`, over the approach (slots 1..10) and the tracking phase (11..N): mean GOSPA (m), its
localisation part and its missed + false part (m^2), the mean step per UAV per slot (m); over the
mission: confirmation delays, ID switches, false confirmed tracks, and MSE / tr(PCRB_pos) of the
followed targets (settled: from a target's 11th followed slot).

Prints live and offline side by side (means over seeds), live's % deviation from offline on each
phase's GOSPA and step with paired bootstrap 95 % intervals over seeds, and writes
--out/multi_target_live.json. One mission at a time; a 60-slot live mission takes 30-60 s.

With --free the world runs free at --speed (it does not wait for plans, as `run` without
--lockstep): each live mission then also reports its plans late and timed out, and whether every
target in the scene at the end was tracked (GOSPA's missed part 0 in the last slot).

Run: nice -n 10 python bench/multi_target_live.py [--seeds 1..10] [--methods proposed,sd]
     [--config config/multi-target.yaml] [--speed 10] [--free]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import socket
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from seeds import parse_seeds  # noqa: E402

from isac_mission.bus import tcp_loopback  # noqa: E402
from isac_mission.cli.embedded import run_embedded  # noqa: E402
from isac_mission.config import Scenario, load_scenario  # noqa: E402
from isac_mission.experiment.bootstrap import Interval, paired_bootstrap  # noqa: E402
from isac_mission.experiment.runs import fly_outcomes, tracks_slot  # noqa: E402
from isac_mission.experiment.track_metrics import RunFigures, track_figures  # noqa: E402
from isac_mission.planning.tracks import multi_target_kit  # noqa: E402
from isac_mission.quiet import quiet_highs_banner  # noqa: E402
from isac_mission.records.tracks import TracksSlot  # noqa: E402
from isac_mission.service.assembly import LiveOptions, planning_scenario  # noqa: E402
from tests.support.ports import free_port_block, sitl_ports  # noqa: E402

APPROACH_SLOTS = 10
"""Slots 1..10 are the approach; 11..N the tracking phase (as bench/live_compare.py)."""


def fly_live(
    s: Scenario, method: str, seed: int, speed: float, out: Path, free: bool
) -> tuple[list[TracksSlot], dict[str, int]]:
    """One live mission in this process; its slots (empty when it failed: printed) and the
    ground loop's counters."""
    opts = LiveOptions(
        speed=speed,
        lockstep=not free,
        method=method,  # type: ignore[arg-type]
        seed=seed,
        out_dir=out,
        zenoh_endpoint=tcp_loopback(free_port_block(1, socket.SOCK_STREAM)),
        **sitl_ports(s.M).world_kwargs(),
    )
    try:
        result = asyncio.run(run_embedded(s, opts, asyncio.Event()))
    except Exception as err:  # a failed mission is reported, the others go on
        print(f"  live {method} seed {seed}: FAILED: {type(err).__name__}: {err}")
        return [], {}
    if len(result.multi_target_slots) != s.N:
        print(f"  live {method} seed {seed}: {len(result.multi_target_slots)}/{s.N} slots")
    return result.multi_target_slots, dict(result.report.counters)


def fly_offline(s: Scenario, method: str, seed: int) -> list[TracksSlot]:
    """The offline twin: the live settings, the same seed."""
    planning = planning_scenario(s, LiveOptions())
    outcomes = fly_outcomes(planning, method, seed, multi_target_kit(planning))
    return [tracks_slot(o) for o in outcomes]


def phase_figures(s: Scenario, method: str, seed: int, slots: list[TracksSlot]) -> dict[str, Any]:
    """The figures of one run (module doc)."""
    f: RunFigures = track_figures(slots, s.multi_tracker.gospa_cutoff_m)
    xy = np.stack([s.uav_start_xy, *(o.uav_xy_m for o in slots)])
    step = np.linalg.norm(np.diff(xy, axis=0), axis=2).mean(axis=1)  # [N] per slot
    a, t = slice(0, APPROACH_SLOTS), slice(APPROACH_SLOTS, None)
    delays = [x.confirmation_delay for x in f.targets if x.confirmation_delay is not None]
    sq = [x.squared_error_m2[10:] for x in f.targets]
    bd = [x.bound_m2[10:] for x in f.targets]
    sq_all, bd_all = np.concatenate(sq), np.concatenate(bd)
    return {
        "gospa_approach": float(f.gospa_m[a].mean()),
        "gospa_tracking": float(f.gospa_m[t].mean()),
        "loc_approach": float(f.localisation_m2[a].mean()),
        "loc_tracking": float(f.localisation_m2[t].mean()),
        "card_approach": float((f.missed_m2[a] + f.false_m2[a]).mean()),
        "card_tracking": float((f.missed_m2[t] + f.false_m2[t]).mean()),
        "step_approach": float(step[a].mean()),
        "step_tracking": float(step[t].mean()),
        "confirm_delay_max": max(delays) if delays else float("nan"),
        "id_switches": f.id_switches,
        "false_runs": len(f.false_track_runs),
        "settled_mse_sum": float(sq_all.sum()),
        "settled_bound_sum": float(bd_all.sum()),
        "tracked_at_end": bool(f.missed_m2[-1] == 0.0),
    }


def deviation(offline: np.ndarray, live: np.ndarray) -> Interval:
    """Live's % deviation from offline in the mean, with its paired 95 % interval."""

    def stat(b: np.ndarray, o: np.ndarray) -> np.ndarray:
        return np.asarray(100.0 * (o.mean(axis=-1) / b.mean(axis=-1) - 1.0))

    return paired_bootstrap(offline, live, stat)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--config", default="config/multi-target.yaml")
    ap.add_argument("--seeds", default="1..10")
    ap.add_argument("--methods", default="proposed")
    ap.add_argument("--speed", type=float, default=10.0)
    ap.add_argument("--out", type=Path, default=Path("out/multi-target-live"))
    ap.add_argument("--free", action="store_true", help="free-running world (no lockstep)")
    args = ap.parse_args()
    quiet_highs_banner()
    s = load_scenario(ROOT / args.config)
    seeds = parse_seeds(args.seeds)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    table: dict[str, dict[str, list[dict[str, Any]]]] = {}
    t_start = time.monotonic()
    for method in methods:
        table[method] = {"live": [], "offline": []}
        for seed in seeds:
            out = args.out / f"{method}_seed{seed}"
            live, counters = fly_live(s, method, seed, args.speed, out, args.free)
            if len(live) != s.N:
                continue
            offline = fly_offline(s, method, seed)
            pace = {
                "plans_late": counters.get("plans late", 0),
                "plans_timed_out": counters.get("plans timed out", 0),
            }
            table[method]["live"].append(
                phase_figures(s, method, seed, live) | pace | {"seed": seed}
            )
            table[method]["offline"].append(
                phase_figures(s, method, seed, offline) | {"seed": seed}
            )
            g = table[method]
            print(
                f"  {method} seed {seed}: GOSPA approach live/offline "
                f"{g['live'][-1]['gospa_approach']:.2f}/{g['offline'][-1]['gospa_approach']:.2f}"
                f", tracking {g['live'][-1]['gospa_tracking']:.2f}/"
                f"{g['offline'][-1]['gospa_tracking']:.2f} m",
                flush=True,
            )
    mode = "free-running" if args.free else "lockstep"
    print(
        f"\nwall {time.monotonic() - t_start:.0f} s; seeds {seeds}; speed {args.speed:g} {mode}\n"
    )
    for method, sides in table.items():
        rows = sides["live"]
        print(
            f"{method} live: {len(rows)}/{len(seeds)} missions flew every slot; plans late "
            f"{sum(r['plans_late'] for r in rows)}, timed out "
            f"{sum(r['plans_timed_out'] for r in rows)} of {len(rows) * s.N}; every target "
            f"tracked at the end in {sum(r['tracked_at_end'] for r in rows)}/{len(rows)}"
        )
    print()
    keys = (
        "gospa_approach",
        "gospa_tracking",
        "loc_approach",
        "loc_tracking",
        "card_approach",
        "card_tracking",
        "step_approach",
        "step_tracking",
    )
    print(
        "| method | side | " + " | ".join(keys) + " | MSE/PCRB settled | false runs | max delay |"
    )
    print("|---" * (len(keys) + 5) + "|")
    for method, sides in table.items():
        for side in ("live", "offline"):
            rows = sides[side]
            if not rows:
                continue
            means = [np.mean([r[k] for r in rows]) for k in keys]
            ratio = sum(r["settled_mse_sum"] for r in rows) / sum(
                r["settled_bound_sum"] for r in rows
            )
            false = sum(r["false_runs"] > 0 for r in rows)
            delay = np.nanmax([r["confirm_delay_max"] for r in rows])
            print(
                f"| {method} | {side} | "
                + " | ".join(f"{m:.3f}" for m in means)
                + f" | {ratio:.2f} | {false}/{len(rows)} | {delay:g} |"
            )
    print("\nlive against offline (% deviation of the mean, paired 95 % interval over seeds):\n")
    print("| method | " + " | ".join(keys) + " |")
    print("|---" * (len(keys) + 1) + "|")
    for method, sides in table.items():
        if len(sides["live"]) < 2:
            continue
        cells = []
        for k in keys:
            off = np.array([r[k] for r in sides["offline"]])
            liv = np.array([r[k] for r in sides["live"]])
            if not off.any():  # a figure that is 0 offline (SD's parked UAVs' step)
                cells.append("(0 offline)" if off.sum() == 0 and not liv.any() else "-")
                continue
            iv = deviation(off, liv)
            cells.append(f"{iv.estimate:+.1f} % [{iv.low:+.1f}, {iv.high:+.1f}]")
        print(f"| {method} | " + " | ".join(cells) + " |")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "multi_target_live.json").write_text(json.dumps(table, indent=1))


if __name__ == "__main__":
    main()
