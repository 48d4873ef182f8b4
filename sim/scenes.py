"""What the simulated world shows of each slot, for any number of targets (no I/O; seeded).

`WorldScene` is the one protocol the world (`sim.world`) runs a slot through: for slot n, the
truth to publish, then every UAV's report drawn from the vehicles' actual horizontal positions
and the shares of the plan in use, both as the bus messages of the scenario's detection model
(`SceneSlot`). Its two implementations, picked from the scenario in one place
(`sim.world_assembly.make_scene`):

- `LabelledTargetScene` (here): the paper's labelled target (`sim.target`, advanced once per
  slot) seen by the sensor (`sim.sensing`): `truth` and one `detection` per UAV (a miss with
  null range and radial velocity);
- `sim.multi_target_scene.MultiTargetScene`: several targets with `simulate`'s draws, unlabelled
  reports with misses and false alarms: `truth_set` (with each measurement's origin) and one
  `detection_set` per UAV (none at slot 0, which has no reports; nothing past slot N).

Each implementation takes its random draws in its own order (the labelled target's motion
before the slot's sensing; the reports before the truth that names their origins); the world
publishes the truth first, so that an evaluator has it when the slot's reports complete.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from isac_mission.types import FloatArray
from isac_mission.wire import (
    DetectionMsg,
    DetectionSetMsg,
    TruthMsg,
    TruthSetMsg,
    detection_messages,
)
from sim.sensing import Sensor
from sim.target import TargetModel


@dataclass(frozen=True)
class SceneSlot:
    """What the world publishes of one slot: `truth` on `isac/<mission>/truth`, then each of
    `reports` [M] on `isac/<mission>/detections/<m>` (m = the message's `uav`)."""

    truth: TruthMsg | TruthSetMsg
    reports: tuple[DetectionMsg | DetectionSetMsg, ...]


class WorldScene(Protocol):
    """The world's targets and their sensing, as the world runs a slot."""

    def covers(self, n: int) -> bool:
        """Whether the scene shows slot n (n >= 0, in order); the world shows nothing else of
        a slot it does not cover."""
        ...

    def show(self, n: int, t_s: float, uav_xy_m: FloatArray, eta: FloatArray) -> SceneSlot:
        """Slot n (a covered one, each once and in order) at simulation time t_s (s): its truth
        and every UAV's report from the UAVs at uav_xy_m [M, 2] (m) with shares eta [M]."""
        ...


class LabelledTargetScene:
    """The paper's labelled target and its detections: `target` advanced once per slot (slot 0
    is its start), then `sensor`'s detection of it from every UAV. The target flies on past the
    mission's last slot, so every slot is covered."""

    def __init__(self, target: TargetModel, sensor: Sensor) -> None:
        self.target = target
        self.sensor = sensor

    def covers(self, n: int) -> bool:
        """Every slot from 0 on."""
        return n >= 0

    def show(self, n: int, t_s: float, uav_xy_m: FloatArray, eta: FloatArray) -> SceneSlot:
        """`truth` of slot n and one `detection` per UAV; RuntimeError when slot n is not the
        target's next slot (the target is advanced exactly once per slot)."""
        x = self.target.state if n == 0 else self.target.advance()
        if self.target.slot != n:
            raise RuntimeError(f"target at slot {self.target.slot}, world at slot {n}")
        det = self.sensor.sense(n, x, uav_xy_m, eta)
        truth = TruthMsg(slot=n, t_s=t_s, target_x=x)
        return SceneSlot(truth, tuple(detection_messages(det, t_s, eta)))
