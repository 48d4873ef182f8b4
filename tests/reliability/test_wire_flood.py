"""A live mission under a garbage flood (issue 7, item 3).

`run_embedded` flies a short mission with and without a flooder process publishing garbage (a
few MB-sized payloads among it) on the detections, telemetry and clock keys; every slot must
complete and the garbage must be counted by reason. The slot periods under the flood are a timing
figure, measured by bench/wire_flood.py (docs/performance.md), not asserted here.

Every socket is on 127.0.0.1; every Zenoh session has explicit loopback endpoints and no
multicast scouting (BusSettings).
"""

from __future__ import annotations

from pathlib import Path

from isac_mission.config import Scenario
from tests.support.flood import live_run


async def test_every_slot_completes_and_the_garbage_is_counted_under_a_flood(
    paper: Scenario, tmp_path: Path
) -> None:
    """A clean live run, then the same run while a flooder process publishes the bad-payload
    catalogue at 300 messages per wall second on the detections, telemetry and clock keys, a 2-3
    MB payload every 0.5 s among them. Every slot of both runs completes (`live_run` checks), the
    clean run rejects nothing, and the flooded run counts the garbage under each reason."""
    s = paper.with_changes(N=16, H=20.0)  # a low altitude: a short climb before slot 0
    clean = await live_run(s, tmp_path / "clean", 5.0, None)
    flooded = await live_run(s, tmp_path / "flood", 5.0, (300.0, 0.5))
    rejected = sum(v for k, v in flooded.counters.items() if k.startswith("rejected "))
    print(f"flood: {flooded.counters['flood sent']} sent, {rejected} counted as rejected")
    assert sum(v for k, v in clean.counters.items() if k.startswith("rejected ")) == 0
    reasons = {k for k in flooded.counters if k.startswith("rejected ")}
    assert {"rejected payload too large", "rejected payload not JSON", "rejected schema"} <= reasons
    # The mission lasts at least N x dt / speed wall seconds (the world's pace) at 300 per second,
    # two thirds of them on keys the ground loop reads (the clock key is the bridges').
    assert rejected >= 0.5 * 300.0 * (s.N - 1) * s.dt / 5.0
