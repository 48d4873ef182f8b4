"""The service's plan rate while console pages come and go: the wall-clock figure of
tests/e2e/test_console.py (the test checks that every connection is served, the service goes on
planning and its memory stays; this bench times the plan rate).

Starts `isac-mission run` (free-running at --speed 2, the console on a free port), watches the
plans with its own Zenoh session, and measures the plans per wall second over --window seconds
before, and while 20 WebSocket connections are opened and dropped three times over
(tests/support/browser.churn_websockets), --repeats times. Prints each pair, the medians and the
ratio during / before (target >= 0.8).
Run: python bench/console_churn.py [--repeats 3] [--window 8]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from isac_mission.bus import BusSettings, ZenohBus  # noqa: E402
from isac_mission.wire import Keys  # noqa: E402
from tests.support.browser import (  # noqa: E402
    churn_websockets,
    short_config,
    start_run,
    stop,
    wait_http,
)

RATIO_TARGET = 0.8


async def one_run(tmp: Path, window_s: float) -> tuple[float, float]:
    """(plans per wall second before the churn, during it)."""
    proc, url, endpoint = start_run(short_config(tmp, 200), tmp / "run", 2.0)
    arrivals: list[float] = []
    try:
        await asyncio.to_thread(wait_http, url, proc)
        bus = await ZenohBus.open_async(BusSettings(mode="client", connect=(endpoint,)))
        try:
            async with bus.subscribe(Keys("paper").plan) as sub:

                async def pump() -> None:
                    async for _key, _payload in sub:
                        arrivals.append(time.monotonic())

                task = asyncio.create_task(pump())
                while len(arrivals) < 3:  # the mission is flying
                    await asyncio.sleep(0.2)
                t0 = time.monotonic()
                await asyncio.sleep(window_s)
                t1 = time.monotonic()
                await churn_websockets(url, rounds=3, connections=20)
                await asyncio.sleep(2.0)
                t2 = time.monotonic()
                task.cancel()
        finally:
            bus.close()
    finally:
        stop(proc)

    def rate(a: float, b: float) -> float:
        return sum(1 for t in arrivals if a <= t <= b) / (b - a)

    return rate(t0, t1), rate(t1, t2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--window", type=float, default=8.0, help="wall seconds before the churn")
    args = ap.parse_args()
    rows = []
    for i in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            rows.append(asyncio.run(one_run(Path(tmp), args.window)))
        print(f"run {i}: plans/s before {rows[-1][0]:.2f}, during the churn {rows[-1][1]:.2f}")
    before, during = (float(np.median(col)) for col in np.array(rows).T)
    ratio = during / before
    verdict = "met" if ratio >= RATIO_TARGET else "missed"
    print(f"median plans/s before {before:.2f}, during {during:.2f}, ratio {ratio:.2f}")
    print(f"target ratio >= {RATIO_TARGET:g}: {verdict}")


if __name__ == "__main__":
    main()
