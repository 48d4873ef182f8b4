"""A view of the one offline loop (`closed_loop.fly_offline`; docs/model.md, "Several targets")
for a scenario of unlabelled detections: its slots as the tracks trace records them
(`runs.tracks_slot`), with the targets' paths (what `sweep` and the benches read; `simulate`
flies every scenario through experiment/runs.py)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from isac_mission.config import Scenario
from isac_mission.errors import ConfigError
from isac_mission.experiment.closed_loop import SlotOutcome, fly_offline
from isac_mission.experiment.runs import tracks_slot as multi_target_slot
from isac_mission.model.run_noise import MultiTargetNoise
from isac_mission.model.scene import UnlabelledScene
from isac_mission.model.targets import TargetPaths
from isac_mission.planning.multi_target import check_multi_target_method
from isac_mission.planning.slot import Method, SolverKit
from isac_mission.records.tracks import TracksSlot
from isac_mission.tracking.factory import scene_for, tracker_for

__all__ = ["MultiTargetRun", "TracksSlot", "run_multi_target"]


@dataclass(frozen=True)
class MultiTargetRun:
    """One run of one method: its slots 1..N and the targets' paths (states [N + 1, T, 4])."""

    method: str
    seed: int
    paths: TargetPaths
    slots: tuple[TracksSlot, ...]


def run_multi_target(
    s: Scenario,
    method: Method,
    noise: MultiTargetNoise,
    kit: SolverKit,
    on_slot: Callable[[TracksSlot], None] | None = None,
) -> MultiTargetRun:
    """Fly one mission of N slots of a multi-target scenario with the given method
    (`closed_loop.fly_offline`); `kit` from `multi_target_kit`."""
    check_multi_target_method(method)
    if s.detection is None:
        raise ConfigError(f"{s.mission_id}: the multi-target loop needs a detection model")
    scene = scene_for(s, noise)
    assert isinstance(scene, UnlabelledScene)

    def each(o: SlotOutcome) -> None:
        if on_slot is not None:
            on_slot(multi_target_slot(o))

    outcomes = fly_offline(s, method, scene, tracker_for(s), kit, each)
    slots = tuple(multi_target_slot(o) for o in outcomes)
    return MultiTargetRun(method, noise.seed, scene.paths, slots)
