"""The simulated world's targets on a multi-target mission (no I/O; seeded): the unlabelled
implementation of `sim.scenes.WorldScene`.

Every target's true path and each slot's unlabelled reports are drawn exactly as `simulate`
draws run seed `seed` (`draw_multi_target_noise`, `target_paths`, `unlabelled_detections`: the
functions the offline loop calls), so that the live world and the offline loop see the same
targets and, from the same UAV positions and shares, the same measurements. The paths cover
slots 0..N; past slot N the world has nothing more to show. The world publishes slot n as
`truth_set` (every target's state, with the origin of each measurement of the slot) and one
`detection_set` per UAV (`show`).
"""

from __future__ import annotations

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.detections import UavReport, unlabelled_detections
from isac_mission.model.radar import SensingParams
from isac_mission.model.run_noise import draw_multi_target_noise
from isac_mission.model.targets import target_paths, target_radar_gains
from isac_mission.types import FloatArray
from isac_mission.wire import TruthSetMsg, detection_set_messages
from sim.scenes import SceneSlot


class MultiTargetScene:
    """The targets of scenario `s` for run seed `seed` (s.detection must be set)."""

    def __init__(self, s: Scenario, seed: int) -> None:
        if s.detection is None:
            raise ValueError(f"{s.mission_id}: a multi-target world needs a detection model")
        self.detection = s.detection
        self.noise = draw_multi_target_noise(s, seed)
        self.paths = target_paths(s.targets, s.dt, s.kappa, s.N, self.noise.target_normals)
        self.gains = target_radar_gains(s)
        self.sensing = SensingParams.from_scenario(s)
        self.n_slots = s.N

    def covers(self, n: int) -> bool:
        """Whether slot n is within the drawn mission (0..N)."""
        return 0 <= n <= self.n_slots

    def truth(self, n: int) -> FloatArray:
        """[T, 4] every target's state at slot n (m, m/s); NaN rows: not in the scene."""
        return np.array(self.paths.states[n], dtype=float)

    def reports(self, n: int, uav_xy_m: FloatArray, eta: FloatArray) -> list[UavReport]:
        """[M] each UAV's unlabelled report of slot n (1..N) from the UAVs at uav_xy_m [M, 2]
        (m) with shares eta [M]."""
        if not 1 <= n <= self.n_slots:
            raise ValueError(f"slot {n}: reports are drawn for slots 1..{self.n_slots}")
        return unlabelled_detections(
            self.paths.states[n],
            self.gains,
            uav_xy_m,
            eta,
            self.sensing,
            self.detection,
            self.noise.slots[n - 1],
        )

    def show(self, n: int, t_s: float, uav_xy_m: FloatArray, eta: FloatArray) -> SceneSlot:
        """Slot n (0..N) at simulation time t_s (s): `truth_set` with the origins of the slot's
        measurements, then each UAV's `detection_set` from the UAVs at uav_xy_m [M, 2] (m) with
        shares eta [M] (an empty one when it detected nothing; none at slot 0, which is before
        plan 1 and has no reports)."""
        reports = self.reports(n, uav_xy_m, eta) if n > 0 else []
        origins = tuple(tuple(int(o) for o in r.origin) for r in reports)
        truth = TruthSetMsg(slot=n, t_s=t_s, states=self.truth(n), origins=origins)
        measurements = [r.measurements for r in reports]
        return SceneSlot(truth, tuple(detection_set_messages(n, t_s, measurements, uav_xy_m, eta)))
