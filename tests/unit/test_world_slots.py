"""The simulated world runs a slot through one scene (sim/scenes.py) for any number of targets.

- What the world publishes for a seed (truth, reports and clock of every slot, the payload bytes,
  in order) equals a frozen copy for the paper's labelled target and for several targets:
  tests/unit/data/world_slots.json was written by `python -m tests.support.world_messages` on
  the tree before the world held one scene (when it ran the labelled target and the
  several-target scene on two branches), and both trees wrote the same bytes. A deliberate
  change of the world's draws or messages regenerates it and says why.
- `make_scene` picks the scene from the scenario's detection model (`tracking.factory.labelled`).
- Each scene shows its slots as its detection model's messages: the labelled target once per
  slot and in order, `truth` + `detection`; several targets `truth_set` (each measurement's
  origin) + `detection_set`, nothing at slot 0 but the truth, nothing past slot N.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from isac_mission.config import load_scenario
from isac_mission.tracking.factory import initial_errors, labelled
from isac_mission.wire import DetectionMsg, DetectionSetMsg, TruthMsg, TruthSetMsg
from sim.multi_target_scene import MultiTargetScene
from sim.scenes import LabelledTargetScene
from sim.world_assembly import make_scene
from sim.world_options import WorldOptions
from tests.support.world_messages import SCENARIOS, digest, positions_at, record_world

FROZEN: dict[str, dict[str, Any]] = json.loads(
    (Path(__file__).parent / "data" / "world_slots.json").read_text(encoding="utf-8")
)


@pytest.mark.parametrize("name", SCENARIOS)
def test_the_world_publishes_the_frozen_messages_in_the_frozen_order(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    frozen = FROZEN[name]
    sent = record_world(name, frozen["seed"], frozen["slots"], monkeypatch)
    shown = [[key, payload.decode()] for key, payload in sent[: len(frozen["first"])]]
    assert shown == frozen["first"]  # the first slots message by message, for a readable diff
    assert len(sent) == frozen["messages"]
    assert digest(sent) == frozen["sha256"]


def test_the_scene_is_picked_from_the_scenarios_detection_model() -> None:
    paper, multi = load_scenario("paper"), load_scenario("multi-target")
    assert labelled(paper) and not labelled(multi)
    assert isinstance(make_scene(paper, WorldOptions()), LabelledTargetScene)
    assert isinstance(make_scene(multi, WorldOptions()), MultiTargetScene)


def test_the_labelled_target_shows_truth_and_detections_once_per_slot_in_order() -> None:
    s = load_scenario("paper")
    scene = make_scene(s, WorldOptions(seed=3))
    eta = np.full(s.M, 1.0 / s.M)
    xy = positions_at(s, 0)
    first = scene.show(0, 0.0, xy, eta)
    assert isinstance(first.truth, TruthMsg) and first.truth.slot == 0
    # slot 0 is the truth simulate's estimate x0 + e is off by e (the tracker's cue is x0)
    np.testing.assert_array_equal(first.truth.target_x, s.x0 - initial_errors(s, 3)[0])
    assert [type(r) for r in first.reports] == [DetectionMsg] * s.M
    assert [r.uav for r in first.reports] == list(range(s.M))
    assert scene.covers(s.N + 5)  # the target flies on past the last slot
    with pytest.raises(RuntimeError, match="target at slot 1, world at slot 2"):
        scene.show(2, 2.0, xy, eta)


def test_several_targets_show_their_truth_with_the_origins_of_every_report() -> None:
    s = load_scenario("multi-target")
    scene = make_scene(s, WorldOptions(seed=3))
    eta = np.full(s.M, 1.0 / s.M)
    start = scene.show(0, 0.0, positions_at(s, 0), eta)
    assert isinstance(start.truth, TruthSetMsg)
    assert start.truth.origins == () and start.reports == ()
    slot = scene.show(1, 1.0, positions_at(s, 1), eta)
    assert isinstance(slot.truth, TruthSetMsg)
    assert [type(r) for r in slot.reports] == [DetectionSetMsg] * s.M
    assert [len(o) for o in slot.truth.origins] == [
        len(r.measurements) for r in slot.reports if isinstance(r, DetectionSetMsg)
    ]
    assert scene.covers(s.N) and not scene.covers(s.N + 1)
