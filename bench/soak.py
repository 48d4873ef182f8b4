"""Soak: a long live mission (M = 3) at high --speed in lockstep; does memory or slot time grow?

Flies the paper's mission live in this process (world, MAVLink bridges, ground loop over
loopback UDP MAVLink and Zenoh; tests/support/soak.py) for --slots slots and prints, per quarter
of the run, the medians of the wall time and the process CPU time per slot and of the planning
time, the resident memory at the quarter's end, and the last-over-first-quarter ratios (target: both
<= 1.1; the soak test asserts the RSS ratio, this bench owns the CPU one). --tracemalloc lists the Python allocations that grew
between the end of the first quarter and the end (slower).
It also counts, from the bus (tests/support/soak_safety.py), the telemetry samples closer than
D_s to the true target and to another UAV, and the infeasible slots (the issue's safety target:
none, and <= 1 %).
With --offline it flies the same scenario offline instead (`simulate`'s closed loop with the
live settings, the loop target as the truth; about 2 min for 3600 slots): the slots flown on the
best effort (infeasible), by the evasion guard (evasive) and fallen back otherwise, and the slots
where a UAV came closer than D_s to the true target or to another UAV along the flown legs
(bench/horizon_fleet.py's `flown_gaps_m`), with the nearest distances.
The racetrack target (`--target racetrack`, tests/support/soak.py) flies laps that turn at the
scenario's manoeuvre bound and change speed between 10 and 30 m/s: with --config
config/manoeuvring.yaml, a target manoeuvring at 4 m/s^2 tracked by the interacting multiple model.
Run: python bench/soak.py [--slots 3600] [--speed 20] [--method horizon] [--target loop|cv|racetrack]
     [--tracemalloc] [--offline] [--out DIR (keep the live trace)]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from isac_mission.config import Scenario, load_scenario  # noqa: E402
from isac_mission.config.live_settings import LiveSettings  # noqa: E402
from isac_mission.experiment.closed_loop import (  # noqa: E402
    SlotOutcome,
    draw_run_noise,
    run_closed_loop,
)
from isac_mission.planning.kit import SolverKit  # noqa: E402
from isac_mission.planning.registry import live_default_method  # noqa: E402
from isac_mission.planning.slot import METHODS  # noqa: E402
from isac_mission.quiet import quiet_highs_banner  # noqa: E402
from isac_mission.service.mission_result import summarize_live  # noqa: E402
from sim.target import ScriptedTarget  # noqa: E402
from tests.support.soak import (  # noqa: E402
    LOOP_SPEED_MPS,
    SoakSample,
    loop_waypoints,
    quarter_table,
    run_soak,
    soak_scenario,
)
from tests.support.soak_safety import ProximityEvent  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--slots", type=int, default=3600)
    ap.add_argument("--speed", type=float, default=20.0)
    ap.add_argument("--no-lockstep", action="store_true")
    ap.add_argument("--target", choices=("loop", "cv", "racetrack"), default="loop")
    ap.add_argument(
        "--method",
        choices=METHODS,
        default=None,
        help="Planning method (default: the live default for the scenario).",
    )
    ap.add_argument("--config", default=str(ROOT / "config" / "paper.yaml"))
    ap.add_argument("--tracemalloc", action="store_true")
    ap.add_argument("--samples", type=Path, help="Write the per-slot samples here (JSON Lines).")
    ap.add_argument("--out", type=Path, help="Keep the mission's trace in this directory.")
    ap.add_argument("--progress", type=int, default=100, help="Print a line every N slots.")
    ap.add_argument("--offline", action="store_true", help="The same scenario, offline.")
    args = ap.parse_args()
    quiet_highs_banner()
    s = soak_scenario(load_scenario(args.config), args.slots, args.target)
    args.method = args.method or live_default_method(multi_target=s.multi_target)
    if args.offline:
        if args.target == "racetrack":
            ap.error("--offline flies the loop or the cv target (the racetrack: live only)")
        offline_soak(s, args.method, args.target)
        return
    t0 = time.monotonic()
    samples: list[SoakSample] = []
    sink = args.samples.open("w") if args.samples is not None else None

    def progress(p: SoakSample) -> None:
        samples.append(p)
        if sink is not None:
            sink.write(json.dumps(p.__dict__) + "\n")
            sink.flush()
        if args.progress and p.slot % args.progress == 0:
            print(
                f"slot {p.slot:5d}/{s.N}  wall {time.monotonic() - t0:7.1f} s  "
                f"RSS {p.rss_bytes / 2**20:7.1f} MiB  solve {p.solve_ms:6.1f} ms",
                flush=True,
            )

    try:
        with tempfile.TemporaryDirectory() as tmp:
            out_dir = args.out or Path(tmp)
            out_dir.mkdir(parents=True, exist_ok=True)
            result = asyncio.run(
                run_soak(
                    s,
                    out_dir,
                    speed=args.speed,
                    lockstep=not args.no_lockstep,
                    target=args.target,
                    method=args.method,
                    trace_malloc=args.tracemalloc,
                    on_sample=progress,
                )
            )
    except BaseException:
        if len(samples) >= 8:
            print(f"\nFAILED after {len(samples)} slots; the table of those slots:")
            print(quarter_table(samples).render())
        raise
    finally:
        if sink is not None:
            sink.close()
    summary = summarize_live(result.live)
    lockstep = "lockstep" if not args.no_lockstep else "free-running"
    print(
        f"\n{len(result.samples)} slots, M = {s.M}, method {args.method}, speed {args.speed:g} "
        f"({lockstep}), target {args.target}; setup {result.setup_s:.1f} s, total {time.monotonic() - t0:.0f} s wall"
    )
    print(
        f"location RMSE {summary.loc_rmse:.2f} m, infeasible slots {summary.infeasible}, "
        f"counters {dict(result.live.report.counters)}"
    )
    n_slots = max(len(result.samples), 1)
    print(
        f"safety: {result.proximity.render(s.d_safe)}; infeasible slots "
        f"{result.infeasible_slots} ({100 * result.infeasible_slots / n_slots:.2f} %)"
    )
    print_events(result.proximity.events)
    print(quarter_table(result.samples).render())
    near = [p for p in result.samples if p.target_distance_m == p.target_distance_m]
    if near:
        closest = min(near, key=lambda p: p.target_distance_m)
        under = sum(p.target_distance_m < s.d_safe for p in near)
        big = sum(p.j_max > 1e9 for p in result.samples)
        print(
            f"nearest UAV-target distance {closest.target_distance_m:.1f} m (slot {closest.slot}); "
            f"{under} slots under D_s = {s.d_safe:g} m; {big} slots with max |J| > 1e9 "
            f"(largest {max(p.j_max for p in result.samples):.3g})"
        )
    if result.heap_growth:
        print("\nPython heap growth from the end of Q1 to the end (tracemalloc, by line):")
        for site, size, count in result.heap_growth:
            print(f"{size / 1024:10.1f} KiB {count:8d} blocks  {site}")


def print_events(events: list[ProximityEvent]) -> None:
    """The samples under D_s, one line per slot, UAV and party: count, nearest distance (m),
    and for a UAV pair the oldest age of the other's sample (s)."""
    if not events:
        return
    print("\nsamples under D_s (slot, UAV, party: count, nearest m, other sample's age s):")
    by_key: dict[tuple[int, int, int], list[ProximityEvent]] = {}
    for e in events:
        by_key.setdefault((e.slot, e.uav, e.other), []).append(e)
    for (slot, uav, other), group in sorted(by_key.items()):
        party = "target" if other < 0 else f"UAV {other}"
        print(
            f"  slot {slot:5d}  UAV {uav} - {party:7s}: {len(group):3d}  "
            f"{min(e.distance_m for e in group):5.1f} m  age {max(e.age_s for e in group):.2f} s"
        )


def offline_soak(s: Scenario, method: str, target: str) -> None:
    """Fly the soak's scenario `s` offline with `method` and the live settings, the loop target
    (or the constant-velocity one) as the truth, and print its safety counts (module docstring)."""
    sys.path.insert(0, str(ROOT / "bench"))
    from horizon_fleet import flown_gaps_m, horizon_counts

    planned = LiveSettings().apply(s)
    truth = None
    if target == "loop":
        path = ScriptedTarget(loop_waypoints(s.N, s.dt), LOOP_SPEED_MPS, s.dt)
        truth = np.array([path.state_at(n * s.dt) for n in range(s.N + 1)])
    outcomes: list[SlotOutcome] = []
    t0 = time.monotonic()
    result = run_closed_loop(
        planned,
        method,
        draw_run_noise(planned, 1),
        SolverKit(planned),
        outcomes.append,
        truth=truth,
    )
    uav_gaps, target_gaps = flown_gaps_m(planned, outcomes)
    kinds = [o.plan.report.fallback for o in outcomes]
    other = sum(1 for k in kinds if k and k not in ("infeasible", "evasive"))
    d_s = planned.d_safe
    print(
        f"{s.N} slots offline, M = {s.M}, method {method}, target {target}, the live settings; "
        f"{time.monotonic() - t0:.0f} s wall\n"
        f"infeasible {kinds.count('infeasible')} ({100 * kinds.count('infeasible') / s.N:.2f} %), "
        f"evasive {kinds.count('evasive')}, other fallbacks {other}\n"
        f"slots closer than D_s = {d_s:g} m to the true target "
        f"{sum(g < d_s for g in target_gaps)} (nearest {min(target_gaps):.1f} m), to another "
        f"UAV {sum(g < d_s for g in uav_gaps)} (nearest {min(uav_gaps):.1f} m)\n"
        f"mean tr(PCRB) {np.mean(np.trace(result.pcrb, axis1=1, axis2=2)):.6g}; plan time median / p95 / max "
        f"{' / '.join(f'{1e3 * q:.1f}' for q in np.percentile(result.solve_s, [50, 95, 100]))} ms"
    )
    if method == "horizon":
        reports = [o.plan.report for o in outcomes]
        notes = [f"fallback {r.fallback}: {r.reason}" if r.fallback else r.polish for r in reports]
        its, conv, kept, capped, other_hz = horizon_counts(notes)
        p50, p90, top = np.percentile(its, [50, 90, 100])
        print(
            f"horizon: converged {conv}, kept at the cap {kept}, fallen back at the cap {capped}, "
            f"other {other_hz}; IPOPT iterations median {p50:.0f}, p90 {p90:.0f}, max {top:.0f}"
        )


if __name__ == "__main__":
    main()
