"""Lossy, late radio links: the worst MAVLink packet loss the live mission survives.

Flies the paper's mission live in this process (world, MAVLink bridges, ground loop over
loopback UDP MAVLink and Zenoh; tests/support/lossy_mission.py), in lockstep at --speed, with
every vehicle's MAVLink losing a fraction p of its packets each way (and 100 +- 50 ms of
latency on every impaired level; p = 0 is the clean run, no impairment at all), for each level
of --levels and each seed of --seeds (more seeds at the clean and 20 % levels: --seeds-20).
Prints one row per level:

  loss      packet loss probability per packet and direction
  done      missions that flew all N slots and landed all vehicles / missions flown
  RMSE med  median location RMSE over the level's missions that completed (m)
  ratio     that median over the clean median; "pooled" below is sqrt(mean RMSE^2) over seeds
  excl s    simulation seconds vehicles were planned around during the missions (all seeds)
  silence   longest radio silence of any vehicle at its bridge (any packet), s; heartbeats
  hb run    longest run of consecutive lost heartbeats
  cmd fail  missions that failed on a command (no COMMAND_ACK after 8 attempts)

Run: python bench/lossy_link.py [--levels 0,0.1,0.2,0.3,0.4,0.5,0.6] [--seeds 1,2] [--slots 60]
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from isac_mission.config import ImpairmentConfig, apply_impairment_flags, load_scenario  # noqa: E402
from isac_mission.errors import IsacError  # noqa: E402
from isac_mission.quiet import quiet_highs_banner  # noqa: E402
from tests.support.lossy_mission import LossyRun, fly_lossy  # noqa: E402


def impairment(loss: float, latency_ms: float, jitter_ms: float) -> ImpairmentConfig | None:
    if loss == 0.0:
        return None
    return apply_impairment_flags(
        ImpairmentConfig(), [f"loss={loss},latency_ms={latency_ms},jitter_ms={jitter_ms}"]
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--levels", default="0,0.1,0.2,0.3,0.4,0.5,0.6")
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--seeds-20", default="1,2,3,4,5", help="Seeds of the 0 and 0.2 levels.")
    ap.add_argument("--slots", type=int, default=60)
    ap.add_argument("--speed", type=float, default=4.0)
    ap.add_argument("--latency-ms", type=float, default=100.0)
    ap.add_argument("--jitter-ms", type=float, default=50.0)
    ap.add_argument("--config", default=str(ROOT / "config" / "paper.yaml"))
    args = ap.parse_args()
    quiet_highs_banner()
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")
    s = load_scenario(args.config).with_changes(N=args.slots)
    levels = [float(x) for x in args.levels.split(",")]
    seeds = [int(x) for x in args.seeds.split(",")]
    seeds_20 = [int(x) for x in args.seeds_20.split(",")]
    out = Path(tempfile.mkdtemp(prefix="lossy-link-"))
    rows: dict[float, list[LossyRun | str]] = {}
    t_start = time.monotonic()
    for level in levels:
        runs: list[LossyRun | str] = []
        for seed in seeds_20 if level in (0.0, 0.2) else seeds:
            t0 = time.monotonic()
            try:
                run: LossyRun | str = asyncio.run(
                    fly_lossy(
                        s,
                        out / f"p{level}-seed{seed}",
                        impairment=impairment(level, args.latency_ms, args.jitter_ms),
                        seed=seed,
                        speed=args.speed,
                    )
                )
            except (IsacError, OSError) as err:
                run = f"{type(err).__name__}: {err}"
            runs.append(run)
            figure = f"{run.loc_rmse_m:.3f} m" if isinstance(run, LossyRun) else run[:120]
            print(f"  loss {level:.2f} seed {seed}: {figure} ({time.monotonic() - t0:.0f} s)")
            sys.stdout.flush()
        rows[level] = runs
    clean = [r for r in rows.get(0.0, []) if isinstance(r, LossyRun) and r.completed]
    clean_med = statistics.median(r.loc_rmse_m for r in clean) if clean else math.nan
    print(
        f"\nN = {s.N} slots, M = {s.M}, lockstep at speed {args.speed:g}; impaired levels with "
        f"{args.latency_ms:g} +- {args.jitter_ms:g} ms each way\n"
    )
    print(
        f"{'loss':>5} {'done':>5} {'RMSE med':>9} {'ratio':>6} {'excl s':>7} "
        f"{'silence s':>9} {'hb s':>6} {'hb run':>6} {'cmd fail':>8}"
    )
    for level, runs in rows.items():
        flown = [r for r in runs if isinstance(r, LossyRun)]
        done = [r for r in flown if r.completed]
        med = statistics.median(r.loc_rmse_m for r in done) if done else math.nan
        excl = sum(sum(r.excluded_s) for r in flown)
        silence = max((max(r.any_silence_s) for r in flown), default=math.nan)
        hb = max((max(r.hb_silence_s) for r in flown), default=math.nan)
        run_hb = max((max(r.hb_loss_run) for r in flown), default=0)
        fails = sum(1 for r in runs if isinstance(r, str) and "COMMAND_ACK" in r)
        print(
            f"{level:5.2f} {len(done):>2}/{len(runs):<2} {med:9.3f} {med / clean_med:6.3f} "
            f"{excl:7.1f} {silence:9.2f} {hb:6.2f} {run_hb:6d} {fails:8d}"
        )
    for level in (0.2,):
        done = [r for r in rows.get(level, []) if isinstance(r, LossyRun) and r.completed]
        if clean and done:
            pooled = math.sqrt(statistics.mean(r.loc_rmse_m**2 for r in done))
            pooled_clean = math.sqrt(statistics.mean(r.loc_rmse_m**2 for r in clean))
            print(
                f"\npooled location RMSE at loss {level:g}: {pooled:.3f} m over {len(done)} "
                f"seeds, clean {pooled_clean:.3f} m over {len(clean)}: ratio "
                f"{pooled / pooled_clean:.3f}"
            )
    print(f"\n{time.monotonic() - t_start:.0f} s of wall time; traces under {out}")


if __name__ == "__main__":
    main()
