"""Lossy, late radio links (issue 16, item 3): every vehicle's MAVLink loses 20 % of its packets
each way with 100 +- 50 ms of latency, and the mission flies on.

Real parts: the simulated world's PX4-like vehicles over loopback UDP MAVLink through the
impairment (sim/impairment.py, sim/impaired_io.py), the bridges, the ground loop, real Zenoh
(tests/support/lossy_mission.py). Each lossy run is compared with the clean run of the same
seed (same target and sensing noise; the impairment has its own streams).

- CI: one seed, a 16-slot mission: it completes, every vehicle lands, no vehicle is excluded for
  longer than its radio silence warrants, the channel lost what it was set to lose (5 sigma),
  and the location RMSE is within the bound below of the clean run's.
- `--full`: the paper's 60 slots over 5 seeds, the pooled location RMSE within 25 % of the clean
  runs' (the issue's figure), each run as above.

The CI bound on one short run: one run's RMSE moves with the geometry the radio changes (which
noise each slot draws), and the seed-to-seed spread is large (0.7-4.5 m over 5 clean 60-slot
runs, bench/lossy_link.py); the largest lossy / clean ratio of one seed measured was 1.14 (60
slots) and 1.13 (16 slots), so one run is held to 1.5x; the 25 % figure is over 5 full missions.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from isac_mission.config import ImpairmentConfig, Scenario, apply_impairment_flags
from isac_mission.records import read_trace
from tests.support.lossy_mission import LINK_LOST_AFTER_S, LossyRun, fly_lossy

LOSSY = "loss=0.2,latency_ms=100,jitter_ms=50"
CI_SLOTS, CI_RATIO = 16, 1.5
FULL_SEEDS, FULL_RATIO = (1, 2, 3, 4, 5), 1.25

pytestmark = pytest.mark.timeout(1800)


def lossy_impairment() -> ImpairmentConfig:
    return apply_impairment_flags(ImpairmentConfig(), [LOSSY])


def check_run(run: LossyRun, s: Scenario) -> None:
    """A lossy run that flew: complete, landed, not falsely excluded, losses as configured."""
    assert run.completed, run.counters
    assert run.counters.get("plans applied", 0) >= s.N
    # 20 % loss at 20 Hz never silences a vehicle for the 3 s of a link loss (that needs 60
    # packets lost in a row), so no exclusion is warranted, and none happened.
    assert max(run.any_silence_s) < LINK_LOST_AFTER_S, run.any_silence_s
    assert run.falsely_excluded == [], (run.excluded_s, run.any_silence_s)
    # The radio lost what it was set to lose: the heartbeats, at 20 % (binomial, 5 sigma).
    n, lost = run.hb_sent, run.hb_sent * run.hb_loss_rate
    assert n >= 50 and abs(lost - 0.2 * n) <= 5 * math.sqrt(n * 0.2 * 0.8), (n, lost)


def pooled_rmse(runs: list[LossyRun]) -> float:
    """sqrt of the mean squared location error over every slot of every run."""
    return math.sqrt(float(np.mean([r.loc_rmse_m**2 for r in runs])))


async def test_lossy_links_mission_completes_and_tracks_as_well(
    paper: Scenario, tmp_path: Path, full_size: bool
) -> None:
    s = paper if full_size else paper.with_changes(N=CI_SLOTS)
    seeds = FULL_SEEDS if full_size else FULL_SEEDS[:1]
    bound = FULL_RATIO if full_size else CI_RATIO
    clean: list[LossyRun] = []
    lossy: list[LossyRun] = []
    for seed in seeds:
        clean.append(await fly_lossy(s, tmp_path / f"clean-{seed}", impairment=None, seed=seed))
        run = await fly_lossy(
            s, tmp_path / f"lossy-{seed}", impairment=lossy_impairment(), seed=seed
        )
        check_run(run, s)
        lossy.append(run)
        assert clean[-1].completed
    ratio = pooled_rmse(lossy) / pooled_rmse(clean)
    print(  # the figure, for the log of a --full run
        f"location RMSE lossy / clean over seeds {seeds}: {pooled_rmse(lossy):.3f} / "
        f"{pooled_rmse(clean):.3f} m = {ratio:.3f}"
    )
    assert ratio <= bound, (ratio, [r.loc_rmse_m for r in lossy], [r.loc_rmse_m for r in clean])


async def test_lost_and_late_detections_are_exactly_the_missing_measurements(
    paper: Scenario, tmp_path: Path
) -> None:
    # Each UAV's detections on Zenoh: 20 % lost, 300 +- 200 ms late (simulation time). In lockstep
    # the ground waits for a slot's detections until they are all in or 2 wall s have passed
    # (the held clock never reaches the 0.5 s deadline), so the late ones are used and only the
    # lost ones are missing: the trace's missing measurements are exactly the channel's losses.
    # The world does not hold after the last slot (no plan follows it), so slot N's late
    # detections race its 0.5 s deadline on the running clock: there, only lost => missing.
    s = paper.with_changes(N=12)
    imp = apply_impairment_flags(
        ImpairmentConfig(), ["detections:loss=0.2,latency_ms=300,jitter_ms=200"]
    )
    run = await fly_lossy(s, tmp_path, impairment=imp, seed=2)
    assert run.completed, run.counters
    trace = read_trace(run.live.trace_path)
    missing = {(r.slot, m) for r in trace.slots for m in range(s.M) if np.isnan(r.r_diag[m])}
    lost = {(n, m) for n, m in run.detections_lost if 1 <= n <= s.N}
    missing_held = {k for k in missing if k[0] < s.N}
    lost_held = {k for k in lost if k[0] < s.N}
    assert missing_held == lost_held and lost_held, (sorted(missing), sorted(lost))
    assert {k for k in lost if k[0] == s.N} <= missing, (sorted(missing), sorted(lost))
    late = [d for (n, _), d in run.detections_late_s.items() if 1 <= n <= s.N]
    assert len(late) == s.N * s.M - len(lost) and min(late) >= 0.1 and max(late) <= 0.5
    assert run.counters.get("detections stale", 0) == 0
    assert run.counters["slots with missing detections"] == len({n for n, _ in missing})
    assert math.isfinite(run.loc_rmse_m)
