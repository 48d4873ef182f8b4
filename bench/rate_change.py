"""What an operator's new R_th costs a live mission (docs/model.md, "R_th changed mid-mission").

Starts `isac-mission run paper --speed 2` for 150 slots (free-running, the console on a free
port) from the tree given (default: this one) and posts `set` R_th on the console's
`/api/control` every --every wall seconds from 25 s to 120 s, alternating 11, 12 and 10 Mbit/s. Prints
the service's RSS at each `set` and at the end, the plan time (the trace's solve_ms: median, p95,
max), the slots slower than --slow-ms or not `ok` or fallen back, and the summary's counters of
late and timed-out plans. Run one tree after the other on a quiet machine, with the compiled
problems of the first R_th in the cache (`isac-mission compile config/paper.yaml`).

Run: python bench/rate_change.py [--tree DIR] [--every 8] [--slow-ms 400]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", type=Path, default=ROOT, help="run this tree's service")
    parser.add_argument("--every", type=float, default=8.0, help="wall seconds between sets")
    parser.add_argument("--slow-ms", type=float, default=400.0, help="list slower plans")
    args = parser.parse_args()
    sys.path.insert(0, str(args.tree.resolve()))
    from isac_mission.records import read_trace
    from tests.support.browser import post, rss_kib, short_config, start_run, stop, wait_http

    with tempfile.TemporaryDirectory(prefix="rate-change-") as tmp_dir:
        tmp = Path(tmp_dir)
        proc, url, _ = start_run(short_config(tmp, 150), tmp / "run", 2.0)
        wait_http(url, proc)
        started = time.monotonic()
        sets, next_s = 0, 25.0
        while proc.poll() is None and time.monotonic() - started < 120:
            if time.monotonic() - started >= next_s:
                sets += 1
                body = {"command": "set", "params": {"rate_min_mbps": 10 + sets % 3}}
                status, _ = post(url, "api/control", body)
                rss = rss_kib(proc.pid) // 1024
                print(
                    f"{time.monotonic() - started:6.1f} s: set #{sets} -> {status}, RSS {rss} MiB"
                )
                next_s += args.every
            time.sleep(0.1)
        if proc.poll() is None:
            print(f"RSS at the end {rss_kib(proc.pid) // 1024} MiB")
        out = stop(proc)
        trace = read_trace(next((tmp / "run").glob("trace_*.jsonl")))
    solve_ms = np.array([r.solve_ms or 0.0 for r in trace.slots])
    print(
        f"{len(trace.slots)} slots; plan median / p95 / max "
        f"{np.median(solve_ms):.0f} / {np.percentile(solve_ms, 95):.0f} / {solve_ms.max():.0f} ms"
    )
    for r in trace.slots:
        if r.fallback or r.status != "ok" or (r.solve_ms or 0.0) > args.slow_ms:
            why = (r.reason or "")[:90]
            ms = r.solve_ms or 0.0
            print(f"  slot {r.slot}: {r.status}, fallback {r.fallback}, {ms:.0f} ms {why}")
    for line in out.splitlines():
        if any(k in line for k in ("plans late", "timed out", "operator commands", "fallback")):
            print(line)


if __name__ == "__main__":
    main()
