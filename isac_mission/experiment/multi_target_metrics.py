"""The tracking figures of experiment/track_metrics.py on a `multi_target_loop.MultiTargetRun`
(the view `sweep` and the benches fly), and a run made of a live mission's slots.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from isac_mission.experiment.multi_target_loop import MultiTargetRun
from isac_mission.experiment.track_metrics import (
    IDENTITY_CUTOFF_M,
    IDENTITY_GATE_PROB,
    MIN_UAVS_SEEN,
    SETTLING_SLOTS,
    RunFigures,
    TargetFigures,
    TrackingSummary,
    follow,
    summarize_tracking,
    track_figures,
)
from isac_mission.model.targets import TargetPaths
from isac_mission.records.tracks import TracksSlot

__all__ = [
    "IDENTITY_CUTOFF_M",
    "IDENTITY_GATE_PROB",
    "MIN_UAVS_SEEN",
    "SETTLING_SLOTS",
    "RunFigures",
    "TargetFigures",
    "TrackingSummary",
    "follow",
    "run_figures",
    "run_of_slots",
    "summarize_tracking",
]


def run_figures(run: MultiTargetRun, gospa_cutoff_m: float) -> RunFigures:
    """The figures of one run (track_metrics.track_figures of its slots)."""
    return track_figures(run.slots, gospa_cutoff_m)


def run_of_slots(method: str, seed: int, slots: Sequence[TracksSlot]) -> MultiTargetRun:
    """A run made of slots 1.. of a mission flown elsewhere (the live ground loop's), for
    `run_figures`: its paths are the slots' truth (slot 0's unknown: NaN)."""
    if not slots:
        raise ValueError("a run needs at least one slot")
    truth = np.stack([o.truth for o in slots])
    states = np.concatenate([np.full((1, *truth.shape[1:]), np.nan), truth])
    paths = TargetPaths(states, np.all(np.isfinite(states), axis=2))
    return MultiTargetRun(method, seed, paths, tuple(slots))
