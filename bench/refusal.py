"""How fast an oversized payload is refused: the wall-clock figures of
tests/reliability/test_wire_fuzz_zenoh.py (the tests check that it is refused, and before it is
parsed; this bench times it).

1. The size guard against parsing: `decode(DetectionMsg, ...)` of 4 MB of valid JSON (refused as
   too large by wire.MAX_PAYLOAD_BYTES) against `json.loads` of the same bytes, medians over
   --repeats and their ratio (target: the refusal under a tenth of the parse).
2. Publish to counted over real Zenoh: each oversized payload of the bad-payload catalogue
   (tests/support/wire_garbage.py) published to a GroundLoop on its own thread until the loop
   has counted it, --repeats times: median and max per payload (target: max < 2 s).
Run: python bench/refusal.py [--repeats 20]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from isac_mission import wire  # noqa: E402
from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback  # noqa: E402
from isac_mission.config import load_scenario  # noqa: E402
from isac_mission.errors import MessageError  # noqa: E402
from isac_mission.wire import DetectionMsg, decode  # noqa: E402
from tests.support.ports import free_tcp_port  # noqa: E402
from tests.support.sim_harness import wait_until  # noqa: E402
from tests.support.wire_garbage import GroundThread, bad_payloads, valid_detection  # noqa: E402

LAG_TARGET_S = 2.0


def size_guard(repeats: int) -> tuple[float, float]:
    """(median json.loads s, median refusal s) of a 4 MB detection payload."""
    body = json.dumps(valid_detection() | {"pad": [1.5] * 800_000}).encode()
    parse, refuse = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        json.loads(body)
        parse.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        with contextlib.suppress(MessageError):
            decode(DetectionMsg, body)
        refuse.append(time.perf_counter() - t0)
    return float(np.median(parse)), float(np.median(refuse))


def publish_to_counted(repeats: int) -> dict[str, list[float]]:
    """Per oversized payload of the catalogue: its publish-to-counted lags, wall seconds."""
    s = load_scenario(ROOT / "config" / "paper.yaml").with_changes(N=3)
    endpoint = tcp_loopback(free_tcp_port())
    ground = GroundThread(s, endpoint).start()
    world = ZenohBus.open(BusSettings(connect=(endpoint,)))
    lags: dict[str, list[float]] = {}
    try:
        asyncio.run(world.wait_for_subscribers(ground.keys.clock, 60.0))
        big = [b for b in bad_payloads(s.M) if len(b.payload) > wire.MAX_PAYLOAD_BYTES]
        name = "rejected payload too large"
        for _ in range(repeats):
            for bad in big:
                before = ground.counters.get(name, 0)
                key = {
                    "detections": ground.keys.detections(0),
                    "telemetry": ground.keys.telemetry(0),
                    "clock": ground.keys.clock,
                }[bad.kind]
                t0 = time.monotonic()
                world.publish(key, bad.payload)
                wait_until(lambda b=before: ground.counters.get(name, 0) > b, 60.0, bad.name)
                lags.setdefault(bad.name, []).append(time.monotonic() - t0)
    finally:
        world.close()
        ground.stop()
    return lags


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args()
    parse_s, refuse_s = size_guard(args.repeats)
    print(f"4 MB payload, medians of {args.repeats}:")
    print(f"  json.loads {parse_s * 1e3:9.2f} ms")
    print(f"  refused    {refuse_s * 1e3:9.4f} ms   ratio parse/refusal {parse_s / refuse_s:,.0f}")
    print(f"  target refusal < parse / 10: {'met' if refuse_s < parse_s / 10 else 'missed'}")
    lags = publish_to_counted(args.repeats)
    print(f"publish to counted over Zenoh, {args.repeats} times each:")
    print(f"  {'payload':<40} {'median ms':>10} {'max ms':>10}")
    worst = 0.0
    for name, values in lags.items():
        worst = max(worst, max(values))
        print(f"  {name:<40} {np.median(values) * 1e3:>10.1f} {max(values) * 1e3:>10.1f}")
    print(f"  target max < {LAG_TARGET_S:g} s: {'met' if worst < LAG_TARGET_S else 'missed'}")


if __name__ == "__main__":
    main()
