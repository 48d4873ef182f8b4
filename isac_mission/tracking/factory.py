"""The one place that picks, from the scenario, the tracker and the detection model.

A scenario's detections are labelled (the paper's one target, seen with a fixed detection
probability and no false alarms: `tracking/tracker.LabelledTracker`, `model/scene.LabelledScene`)
or unlabelled (several targets, a target that turns, flies waypoints or legs, comes late, leaves
or must be found, false alarms or an SNR detection model, or the IMM: `MultiTargetTracker`,
`UnlabelledScene`).
Everything else takes a `Tracker`, a `Scene` and their draws through here, whatever the number
of targets.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from isac_mission.model.run_noise import (
    MultiTargetNoise,
    RunNoise,
    draw_multi_target_noise,
    draw_run_noise,
)
from isac_mission.model.scene import LabelledScene, Scene, UnlabelledScene
from isac_mission.tracking.cycle import CycleModel, TrackState
from isac_mission.tracking.multi_target import MultiTargetTracker, TrackerSettings, TrackerState
from isac_mission.tracking.tracker import LabelledTracker, Tracker
from isac_mission.types import FloatArray

if TYPE_CHECKING:
    from isac_mission.config import Scenario

RunDraws = RunNoise | MultiTargetNoise
"""One run's random numbers, of the scenario's detection model."""

KEEP_OUT_TRACKS = 8
"""How many tracks besides the ones planned for a plan keeps every UAV D_s from, with a tracker
of several targets (the nearest to the fleet; the kit's problems are built for this many
keep-out points); the labelled tracker has no other track."""


def labelled(s: Scenario) -> bool:
    """True when the scenario's detections are labelled: one target, present all along, on the
    constant-velocity model, with the paper's detection model."""
    return not s.multi_target


def tracker_for(s: Scenario) -> Tracker:
    """A new tracker of the scenario, with no track yet (the scene's priors start them)."""
    if labelled(s):
        return LabelledTracker(CycleModel.from_scenario(s))
    return MultiTargetTracker(TrackerSettings.from_scenario(s))


def restored_tracker(s: Scenario, saved: object) -> Tracker:
    """The scenario's tracker as it was when its `saved()` gave `saved` (a TrackState of the
    labelled tracker, a TrackerState of the tracker of several targets). ValueError when
    `saved` is not the scenario's tracker's."""
    if labelled(s) and isinstance(saved, TrackState):
        return LabelledTracker(CycleModel.from_scenario(s), saved)
    if not labelled(s) and isinstance(saved, TrackerState):
        return MultiTargetTracker.restored(TrackerSettings.from_scenario(s), saved)
    raise ValueError(f"{type(saved).__name__} is not the state of {s.mission_id}'s tracker")


def keep_out_tracks(s: Scenario) -> int:
    """How many other tracks a plan keeps D_s from (the kits' keep-out points for tracks)."""
    return 0 if labelled(s) else KEEP_OUT_TRACKS


def draw_noise(s: Scenario, seed: int) -> RunDraws:
    """One run's random numbers for the scenario's detection model."""
    return draw_run_noise(s, seed) if labelled(s) else draw_multi_target_noise(s, seed)


def initial_errors(s: Scenario, seed: int) -> FloatArray:
    """[T, 4] (m, m/s): the run's draw of each known target's first estimate minus its state
    (x_hat - x, ~ N(0, P0)), as `simulate` starts its tracks for `seed`."""
    noise = draw_noise(s, seed)
    if isinstance(noise, RunNoise):
        return np.asarray(noise.initial_error, dtype=float)[None]
    return np.asarray(noise.initial_errors, dtype=float)


def scene_for(s: Scenario, noise: RunDraws, truth: FloatArray | None = None) -> Scene:
    """The run's offline world. truth [N + 1, 4]: a scripted path of the one labelled target
    (None: its motion model driven by the run's process noise)."""
    if isinstance(noise, RunNoise):
        return LabelledScene.of(s, noise, truth)
    if truth is not None:
        raise ValueError("a scripted truth is one labelled target's path")
    return UnlabelledScene.of(s, noise)


def tracker_description(s: Scenario) -> str:
    """Which tracker `s` uses and why (tracker.kind; docs/model.md, "Several targets"), as
    `check-config` prints it."""
    from isac_mission.config import multi_target_reasons

    if labelled(s):
        return f"labelled EKF (kind {s.tracker_kind})"
    reasons = multi_target_reasons(s)
    why = f": {', '.join(reasons)}" if s.tracker_kind == "auto" and reasons else ""
    imm = "" if s.imm is None else f", the IMM of {len(s.imm.modes)} modes on every track"
    return f"multi-target {s.multi_tracker.association.upper()}{imm} (kind {s.tracker_kind}{why})"


def detection_description(s: Scenario) -> str | None:
    """The detection model of a scenario of unlabelled detections, as `check-config` prints it
    (None: the paper's labelled detections)."""
    d = s.detection
    if labelled(s) or d is None:
        return None
    return f"{d.model}, {d.false_alarms_per_slot:g} false alarms/UAV/slot"
