"""What a run's tracks measured, for any number of targets (docs/model.md, "Metrics"): GOSPA and
its parts per slot, which confirmed track follows which target, ID switches, each target's
confirmation delay, its location error against its track's bound, and the false tracks. The
paper's labelled target is the case of one target and one track.

Which track follows a target at a slot: the optimal assignment (least total distance) of the
confirmed tracks to the targets in the scene, a pair admissible when the track lies within
`IDENTITY_CUTOFF_M` of the target or the target within the track's own position gate
(chi-square, 2 degrees of freedom, `IDENTITY_GATE_PROB`: a new track far from its target but
honest about it follows it). A target's track changes ID when its assigned track
differs from the one it last had (a slot without one in between does not count as a switch: the
same ID coming back is no switch). A confirmed track assigned to no target is false at that slot.
Pure: numpy and scipy.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from isac_mission.model.detections import UavReport
from isac_mission.tracking.gospa import UNASSIGNED, gospa
from isac_mission.tracking.tracker import TrackEstimate
from isac_mission.types import FloatArray, IntArray

IDENTITY_CUTOFF_M = 100.0
"""A confirmed track within this of a target may follow it (m)..."""

IDENTITY_GATE_PROB = 0.999
"""... or one whose position gate of this probability holds the target."""

SETTLING_SLOTS = 10
"""The first slots a track follows its target are its approach (the EKF from a prior or an
initiation fit, at about twice its bound, as the labelled target's slots 1..10); the
settled ratio leaves them out."""

MIN_UAVS_SEEN = 3
"""A target counts as seen from the first slot at least this many UAVs detected it."""


@dataclass(frozen=True)
class TargetFigures:
    """One target over a run: seen_slot (first slot >= 3 UAVs detected it; 0: never), confirmed
    slot (first slot a confirmed track followed it; 0: never), id_switches, and over the slots a
    confirmed track followed it: slots_followed, squared_error_m2 [k] (position), bound_m2 [k]
    (tr of that track's position PCRB)."""

    seen_slot: int
    confirmed_slot: int
    id_switches: int
    squared_error_m2: FloatArray
    bound_m2: FloatArray

    @property
    def confirmation_delay(self) -> int | None:
        """Slots from seen to confirmed (None: never seen or never confirmed)."""
        if self.seen_slot == 0 or self.confirmed_slot == 0:
            return None
        return max(self.confirmed_slot - self.seen_slot, 0)


@dataclass(frozen=True)
class RunFigures:
    """One run: gospa, localisation, missed, false [N] per slot (GOSPA in m, its parts in m^2);
    targets [T]; false_track_runs: for every confirmed track that was false at some slot, the
    longest run of slots it stayed false."""

    gospa_m: FloatArray
    localisation_m2: FloatArray
    missed_m2: FloatArray
    false_m2: FloatArray
    targets: tuple[TargetFigures, ...]
    false_track_runs: tuple[int, ...]

    @property
    def id_switches(self) -> int:
        return sum(t.id_switches for t in self.targets)


class TrackedSlot(Protocol):
    """What the figures read of one slot: its number, truth [T, 4] (every target's true state,
    NaN rows: not in the scene), the UAVs' reports (with their true origins) and the tracks
    after the update."""

    @property
    def slot(self) -> int: ...
    @property
    def truth(self) -> FloatArray: ...
    @property
    def reports(self) -> tuple[UavReport, ...]: ...
    @property
    def tracks(self) -> tuple[TrackEstimate, ...]: ...


def track_figures(slots: Sequence[TrackedSlot], gospa_cutoff_m: float) -> RunFigures:
    """The figures of one run's slots 1.. (module docstring); GOSPA with p = 2, alpha = 2."""
    if not slots:
        raise ValueError("a run needs at least one slot")
    T = slots[0].truth.shape[0]
    parts = np.zeros((4, len(slots)))
    followed: list[IntArray] = []
    seen = np.zeros(T, dtype=np.int64)
    false_streak: dict[int, int] = {}
    longest_false: dict[int, int] = {}
    errors: list[list[float]] = [[] for _ in range(T)]
    bounds: list[list[float]] = [[] for _ in range(T)]
    for k, slot in enumerate(slots):
        present = np.flatnonzero(np.all(np.isfinite(slot.truth), axis=1))
        truth_xy = slot.truth[present, :2]
        confirmed = [t for t in slot.tracks if t.confirmed]
        track_xy = np.array([t.belief.x[:2] for t in confirmed]).reshape(-1, 2)
        g = gospa(truth_xy, track_xy, c=gospa_cutoff_m)
        parts[:, k] = g.distance, g.localisation, g.missed, g.false
        identity = follow(truth_xy, confirmed)
        ids = np.full(T, 0, dtype=np.int64)
        for i, t in enumerate(present):
            detections = sum(int(np.any(r.origin == t)) for r in slot.reports)
            if seen[t] == 0 and detections >= MIN_UAVS_SEEN:
                seen[t] = slot.slot
            j = identity[i]
            if j != UNASSIGNED:
                track = confirmed[j]
                ids[t] = track.track_id
                errors[t].append(float(np.sum((track.belief.x[:2] - slot.truth[t, :2]) ** 2)))
                bounds[t].append(float(np.trace(track.bound.C[:2, :2])))
        followed.append(ids)
        assigned = set(ids.tolist())
        for c in confirmed:
            if c.track_id in assigned:
                false_streak[c.track_id] = 0
                continue
            false_streak[c.track_id] = false_streak.get(c.track_id, 0) + 1
            longest_false[c.track_id] = max(
                longest_false.get(c.track_id, 0), false_streak[c.track_id]
            )
    by_slot = np.array(followed).reshape(len(slots), T)
    targets = tuple(
        TargetFigures(
            seen_slot=int(seen[t]),
            confirmed_slot=_first_slot(slots, by_slot[:, t]),
            id_switches=_switches(by_slot[:, t]),
            squared_error_m2=np.asarray(errors[t]),
            bound_m2=np.asarray(bounds[t]),
        )
        for t in range(T)
    )
    return RunFigures(
        parts[0], parts[1], parts[2], parts[3], targets, tuple(longest_false.values())
    )


def follow(truth_xy: FloatArray, tracks: Sequence[TrackEstimate]) -> IntArray:
    """[n] the index into tracks of the track following each target at truth_xy [n, 2] (m),
    or UNASSIGNED (module docstring)."""
    out = np.full(len(truth_xy), UNASSIGNED, dtype=np.int64)
    if not len(truth_xy) or not tracks:
        return out
    xy = np.array([t.belief.x[:2] for t in tracks])
    e = truth_xy[:, None, :] - xy[None]  # [n, m, 2]
    d = np.linalg.norm(e, axis=2)
    inv = np.linalg.inv(np.array([t.belief.P[:2, :2] for t in tracks]))
    d2 = np.einsum("nmi,mij,nmj->nm", e, inv, e)
    admissible = (d <= IDENTITY_CUTOFF_M) | (d2 <= chi2.ppf(IDENTITY_GATE_PROB, 2))
    big = 1e12
    rows, cols = linear_sum_assignment(np.where(admissible, d, big))
    ok = admissible[rows, cols]
    out[rows[ok]] = cols[ok]
    return out


def _first_slot(slots: Sequence[TrackedSlot], ids: IntArray) -> int:
    nonzero = np.flatnonzero(ids)
    return int(slots[nonzero[0]].slot) if len(nonzero) else 0


def _switches(ids: IntArray) -> int:
    """How often the followed track's ID changes (zeros, no track, skipped)."""
    had = [int(i) for i in ids if i != 0]
    return sum(a != b for a, b in itertools.pairwise(had))


@dataclass(frozen=True)
class TrackingSummary:
    """Figures over runs of one method: mission-mean GOSPA (m) and its parts (m^2), mean ID
    switches per run, the share of runs with a confirmed false track and the longest false run,
    the confirmation delays [.] (slots, targets that were seen and confirmed), the targets seen
    but never confirmed, and per target (by index) location RMSE (m), mean tr(PCRB_pos) (m^2)
    and MSE / tr(PCRB_pos), over every slot a track followed it and, settled, without each
    run's first SETTLING_SLOTS of them."""

    gospa_m: float
    localisation_m2: float
    missed_m2: float
    false_m2: float
    id_switches: float
    runs_with_false_tracks: float
    longest_false_run: int
    confirmation_delays: tuple[int, ...]
    never_confirmed: int
    rmse_m: tuple[float, ...]
    bound_m2: tuple[float, ...]
    efficiency: tuple[float, ...]
    settled_efficiency: tuple[float, ...]


def summarize_tracking(figures: Sequence[RunFigures]) -> TrackingSummary:
    """Pool the runs' figures (module docstring)."""
    T = len(figures[0].targets) if figures else 0
    delays = [d for f in figures for t in f.targets if (d := t.confirmation_delay) is not None]
    never = sum(1 for f in figures for t in f.targets if t.seen_slot and not t.confirmed_slot)
    rmse, bound, efficiency, settled = [], [], [], []
    for t in range(T):
        e = np.concatenate([f.targets[t].squared_error_m2 for f in figures])
        b = np.concatenate([f.targets[t].bound_m2 for f in figures])
        mse = float(np.mean(e)) if len(e) else float("nan")
        mb = float(np.mean(b)) if len(b) else float("nan")
        rmse.append(float(np.sqrt(mse)))
        bound.append(mb)
        efficiency.append(mse / mb if len(b) else float("nan"))
        e_s = np.concatenate([f.targets[t].squared_error_m2[SETTLING_SLOTS:] for f in figures])
        b_s = np.concatenate([f.targets[t].bound_m2[SETTLING_SLOTS:] for f in figures])
        settled.append(float(np.mean(e_s) / np.mean(b_s)) if len(b_s) else float("nan"))
    return TrackingSummary(
        gospa_m=float(np.mean([f.gospa_m.mean() for f in figures])),
        localisation_m2=float(np.mean([f.localisation_m2.mean() for f in figures])),
        missed_m2=float(np.mean([f.missed_m2.mean() for f in figures])),
        false_m2=float(np.mean([f.false_m2.mean() for f in figures])),
        id_switches=float(np.mean([f.id_switches for f in figures])),
        runs_with_false_tracks=float(np.mean([bool(f.false_track_runs) for f in figures])),
        longest_false_run=max((max(f.false_track_runs, default=0) for f in figures), default=0),
        confirmation_delays=tuple(delays),
        never_confirmed=never,
        rmse_m=tuple(rmse),
        bound_m2=tuple(bound),
        efficiency=tuple(efficiency),
        settled_efficiency=tuple(settled),
    )
