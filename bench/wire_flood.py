"""Slot periods of a live mission under a garbage flood, beside a clean run measured in the same run.

Runs `run_embedded` (world, MAVLink bridges, ground loop over loopback) at --speed 5 for a short
mission, first clean, then while `tests.support.wire_garbage` publishes the bad-payload catalogue
at 300 messages per wall second on the detections, telemetry and clock keys (a 2-3 MB payload every
0.5 s among them), and prints the wall-clock slot periods (median, p5, p95, min, max) of each and
the flooded/clean ratio. The target: every flooded period within 0.5x-2x dt / speed, its median
within 20 % of the clean one.
Run: python bench/wire_flood.py [--slots 16] [--rate 300] [--repeats 1]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from isac_mission.config import load_scenario  # noqa: E402
from isac_mission.quiet import quiet_highs_banner  # noqa: E402
from tests.support.flood import live_run  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--slots", type=int, default=16)
    ap.add_argument("--rate", type=float, default=300.0, help="garbage messages per wall second")
    ap.add_argument("--repeats", type=int, default=1, help="clean/flooded pairs")
    args = ap.parse_args()
    quiet_highs_banner()
    s = load_scenario(ROOT / "config" / "paper.yaml").with_changes(N=args.slots, H=20.0)
    speed = 5.0
    nominal_ms = s.dt / speed * 1e3
    periods: dict[str, list[float]] = {"clean": [], "flood": []}
    sent = rejected = 0
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeats):
            for name, flood in (("clean", None), ("flood", (args.rate, 0.5))):
                run = asyncio.run(live_run(s, Path(tmp) / f"{name}{k}", speed, flood))
                periods[name] += [p * 1e3 for p in run.periods_s]
                if flood is not None:
                    sent += run.counters["flood sent"]
                    rejected += sum(v for n, v in run.counters.items() if n.startswith("rejected "))
    print(
        f"slot periods (ms), N = {s.N} at speed {speed:g} (nominal {nominal_ms:.0f} ms), "
        f"{args.repeats} pair(s); flood: {sent} sent, {rejected} rejected"
    )
    print(f"{'run':<8} {'median':>8} {'p5':>8} {'p95':>8} {'min':>8} {'max':>8} {'in 0.5-2x':>10}")
    for name, p in periods.items():
        a = np.array(p)
        inside = np.mean((a >= 0.5 * nominal_ms) & (a <= 2.0 * nominal_ms))
        print(
            f"{name:<8} {np.median(a):>8.1f} {np.percentile(a, 5):>8.1f} {np.percentile(a, 95):>8.1f}"
            f" {a.min():>8.1f} {a.max():>8.1f} {inside:>10.0%}"
        )
    ratio = np.median(periods["flood"]) / np.median(periods["clean"])
    print(f"median ratio flood / clean: {ratio:.3f}")


if __name__ == "__main__":
    main()
