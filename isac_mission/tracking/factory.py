"""The one place that picks, from the scenario, the tracker and the detection model.

A scenario's detections are labelled (the paper's one target, seen with a fixed detection
probability and no false alarms: `tracking/tracker.LabelledTracker`, `model/scene.LabelledScene`)
or unlabelled (several targets, a target that turns, flies waypoints, comes late, leaves or must
be found, false alarms or an SNR detection model: `MultiTargetTracker`, `UnlabelledScene`).
Everything else takes a `Tracker`, a `Scene` and their draws through here, whatever the number
of targets.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from isac_mission.model.run_noise import (
    MultiTargetNoise,
    RunNoise,
    draw_multi_target_noise,
    draw_run_noise,
)
from isac_mission.model.scene import LabelledScene, Scene, UnlabelledScene
from isac_mission.tracking.cycle import CycleModel
from isac_mission.tracking.multi_target import MultiTargetTracker, TrackerSettings
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


def keep_out_tracks(s: Scenario) -> int:
    """How many other tracks a plan keeps D_s from (the kits' keep-out points for tracks)."""
    return 0 if labelled(s) else KEEP_OUT_TRACKS


def draw_noise(s: Scenario, seed: int) -> RunDraws:
    """One run's random numbers for the scenario's detection model."""
    return draw_run_noise(s, seed) if labelled(s) else draw_multi_target_noise(s, seed)


def scene_for(s: Scenario, noise: RunDraws, truth: FloatArray | None = None) -> Scene:
    """The run's offline world. truth [N + 1, 4]: a scripted path of the one labelled target
    (None: its motion model driven by the run's process noise)."""
    if isinstance(noise, RunNoise):
        return LabelledScene.of(s, noise, truth)
    if truth is not None:
        raise ValueError("a scripted truth is one labelled target's path")
    return UnlabelledScene.of(s, noise)
