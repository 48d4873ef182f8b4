"""Live-service timing at real time: detection-to-setpoint latency and setpoint period jitter.

Runs `isac-mission run` in-process (world, MAVLink bridges, ground loop over loopback UDP and
Zenoh) at --speed 1 for a short mission and prints, from wall-clock timestamps taken in the same
process: the time from slot n's last detection received to the first setpoint of plan n+1 sent
(median, p99), and per vehicle the setpoint stream's period (nominal 50 ms) and its jitter
|period - nominal| (median, p99). The flight altitude is lowered to 30 m so that take-off and
landing take seconds, not minutes (the planar problem does not change).
Run: python bench/live_latency.py [--slots 20] [--method proposed]
"""

from __future__ import annotations

import argparse
import asyncio
import socket
import tempfile
from pathlib import Path

import numpy as np

from isac_mission.bus import tcp_loopback
from isac_mission.cli.embedded import run_embedded
from isac_mission.config import load_scenario
from isac_mission.quiet import quiet_highs_banner
from isac_mission.service.assembly import LiveOptions


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--slots", type=int, default=20)
    ap.add_argument("--method", default="proposed")
    ap.add_argument("--config", default="config/paper.yaml")
    args = ap.parse_args()
    quiet_highs_banner()
    s = load_scenario(args.config).with_changes(N=args.slots, H=30.0, dH=30.0 - 15.0)
    with tempfile.TemporaryDirectory() as tmp:
        opts = LiveOptions(
            speed=1.0,
            method=args.method,
            out_dir=Path(tmp),
            zenoh_endpoint=tcp_loopback(_free_tcp_port()),
            mavlink_base_port=24540,
            mavlink_local_base_port=24580,
            gcs_port=24550,
            gcs_local_base_port=28570,
        )
        result = asyncio.run(run_embedded(s, opts, asyncio.Event()))
    lat = np.array(result.detection_to_setpoint_s) * 1e3
    plan = np.array(result.report.latencies_s) * 1e3
    print(f"{len(result.report.records)} slots at speed 1, M = {s.M}, method {args.method}")
    print(f"{'figure':<44} {'median ms':>10} {'p99 ms':>9}")
    print(
        f"{'last detection -> plan published':<44} {np.median(plan):>10.1f} {np.percentile(plan, 99):>9.1f}"
    )
    print(
        f"{'last detection -> first setpoint of new plan':<44} {np.median(lat):>10.1f} {np.percentile(lat, 99):>9.1f}"
    )
    nominal = 1e3 / 20.0
    for m, periods in sorted(result.setpoint_periods_s.items()):
        p = np.array(periods) * 1e3
        jitter = np.abs(p - nominal)
        print(
            f"vehicle {m}: setpoint period median {np.median(p):.1f} ms, "
            f"jitter |period - {nominal:.0f} ms| median {np.median(jitter):.2f} ms, "
            f"p99 {np.percentile(jitter, 99):.2f} ms ({len(p)} periods)"
        )


if __name__ == "__main__":
    main()
