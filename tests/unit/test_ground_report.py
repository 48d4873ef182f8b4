"""The ground loop's report stays bounded on a long run, and its totals match the slots."""

from __future__ import annotations

import math

import numpy as np

from isac_mission.records import SlotRecord
from isac_mission.service.ground.report import SLOTS_KEPT, GroundReport
from isac_mission.service.mission_result import LiveResult, summarize_live


def _record(n: int, rng: np.random.Generator) -> SlotRecord:
    m = 3
    truth = rng.uniform(0, 3000, size=4)
    return SlotRecord(
        slot=n,
        method="proposed",
        status="ok" if n % 7 else "infeasible",
        uav_xy_m=rng.uniform(0, 3000, size=(m, 2)),
        bandwidth_share=np.full(m, 1 / m),
        assoc=np.arange(m),
        target_true=None if n % 5 == 0 else truth,
        target_est=truth + rng.normal(size=4),
        target_pred=truth,
        r_diag=np.ones(2 * m),
        pcrb_trace=float(rng.uniform(0.5, 2.0)),
        solve_ms=float(n % 50),
        P=np.eye(4),
        J=np.eye(4),
    )


def test_report_keeps_a_window_and_sums_the_whole_run() -> None:
    rng = np.random.default_rng(3)
    report = GroundReport()
    records = [_record(n, rng) for n in range(1, SLOTS_KEPT + 501)]
    for r in records:
        report.records.append(r)
        report.totals.add(r)
        report.latencies_s.append(0.01)
    assert len(report.records) == SLOTS_KEPT and report.records[0].slot == 501
    assert len(report.latencies_s) == SLOTS_KEPT
    summary = summarize_live(LiveResult(report, trace_path=None))  # type: ignore[arg-type]
    # The whole run, recomputed from every record.
    truth = [r for r in records if r.target_true is not None]
    err = np.array([np.asarray(r.target_est) - np.asarray(r.target_true) for r in truth])
    assert summary.slots == len(records)
    assert math.isclose(summary.loc_rmse, np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1))))
    assert math.isclose(summary.vel_rmse, np.sqrt(np.mean(np.sum(err[:, 2:] ** 2, axis=1))))
    assert math.isclose(summary.pcrb_mean, np.mean([r.pcrb_trace for r in records]))
    assert summary.infeasible == sum(r.status != "ok" for r in records)
