"""Trace files as `run` and `serve` leave them (docs/trace.md), written directly for the tests
that read them: a single-target trace through `TraceWriter`, a multi-target one with its header
(`records/tracks.py`) and one line per slot; each with the `end` line a live run writes
when it stops (none when `killed`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from isac_mission.config import load_scenario
from isac_mission.records import MissionEnd, SlotRecord, TraceWriter
from isac_mission.records.header import header_line
from isac_mission.records.jsonlines import dumps_line
from isac_mission.records.tracks import end_line


def slot_record(n: int, m: int = 3) -> SlotRecord:
    """A plausible single-target slot record n for m UAVs (values change with n, so records
    differ)."""
    rng = np.random.default_rng(n)
    a = rng.normal(size=(4, 4))
    P = a @ a.T + 4 * np.eye(4)
    return SlotRecord(
        slot=n,
        method="proposed",
        status="ok",
        uav_xy_m=rng.uniform(0, 3000, size=(m, 2)),
        bandwidth_share=np.full(m, 1 / m),
        assoc=np.arange(m) % 2,
        target_true=rng.uniform(0, 3000, size=4),
        target_est=rng.uniform(0, 3000, size=4),
        target_pred=rng.uniform(0, 3000, size=4),
        r_diag=rng.uniform(0.1, 2.0, size=2 * m),
        pcrb_trace=float(n),
        solve_ms=12.5,
        P=P,
        J=np.linalg.inv(P),
        plan_xy=rng.uniform(0, 3000, size=(m, 2)),
        extra={"received": m, "latency_ms": 3.0},
    )


def run_end(scenario: str, slots: int) -> MissionEnd:
    """The `end` line of a live run of `scenario` that stopped after slot `slots`: complete at
    N, else interrupted."""
    n = load_scenario(scenario).N
    return MissionEnd("complete" if slots >= n else "interrupted", slots, n)


def write_single_target_trace(
    path: Path, scenario: str, slots: int, *, killed: bool = False
) -> None:
    """A `serve` trace of `scenario` (method proposed) with slots 1..slots, and its `end` line
    unless `killed`."""
    s = load_scenario(scenario)
    config = s.trace_config() | {"seed": s.seed, "method": "proposed"}
    with TraceWriter(path, config) as writer:
        for n in range(1, slots + 1):
            writer.write_slot(slot_record(n, s.M))
        if not killed:
            writer.write_end(run_end(scenario, slots))


def write_multi_target_trace(
    path: Path, scenario: str, slots: int, *, killed: bool = False
) -> None:
    """A multi-target `serve` trace of `scenario` (method proposed) with slots 1..slots: its
    header (records/tracks.py), one line per slot, and its `end` line unless `killed`."""
    s = load_scenario(scenario)
    lines = [header_line(s.trace_config() | {"seed": s.seed, "method": "proposed"})]
    for n in range(1, slots + 1):
        xy = [[100.0 * m, 50.0 * n] for m in range(s.M)]
        lines.append(
            dumps_line(
                {
                    "slot": n,
                    "method": "proposed",
                    "status": "ok",
                    "fallback": None,
                    "solve_ms": 10.0,
                    "uav_xy": xy,
                    "eta": [1 / s.M] * s.M,
                    "assoc": [0] * s.M,
                    "planned_for": 1,
                    "targets": [],
                    "tracks": [],
                    "measurements": [[] for _ in range(s.M)],
                    "origins": [[] for _ in range(s.M)],
                }
            )
        )
    if not killed:
        lines.append(end_line(run_end(scenario, slots)))
    path.write_text("".join(line + "\n" for line in lines))
