"""The offline world of one Monte Carlo run: the targets' truth and each UAV's report per slot.

Two detection models, picked from the scenario by `tracking/factory.py`, the same interface:
- `LabelledScene`: the paper's one target and its labelled detections (model/detections.py's
  `noisy_detections`: one range and radial velocity per UAV, or a miss), the target on the
  constant-velocity model driven by the run's process noise (or a scripted path);
- `UnlabelledScene`: several intruders on their own paths (model/targets.py), each UAV's
  unlabelled report of the targets it detects and its false alarms (`unlabelled_detections`).

A scene holds a run's random numbers and nothing that changes: every method of a run flies the
same scene (common random numbers). Pure: numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from isac_mission.model.detections import UavReport, noisy_detections, unlabelled_detections
from isac_mission.model.radar import SensingParams
from isac_mission.model.run_noise import MultiTargetNoise, RunNoise
from isac_mission.model.targets import TargetPaths, target_paths, target_radar_gains
from isac_mission.types import FloatArray, Gaussian

if TYPE_CHECKING:
    from isac_mission.config import Scenario

TARGET = 0
"""The labelled scene's target index (a report's origin)."""


class Scene(Protocol):
    """A run's world: `seed`; `truth(n)` [T, 4] every target's true state at slot n (NaN rows:
    not in the scene); `priors(n)` the beliefs of the targets whose prior is known that enter at
    slot n (the tracker starts a confirmed track on each before slot n + 1); `reports(n, ...)`
    each UAV's report of slot n."""

    @property
    def seed(self) -> int: ...

    def truth(self, n: int) -> FloatArray: ...

    def priors(self, n: int) -> tuple[Gaussian, ...]: ...

    def reports(
        self, n: int, uav_xy_m: FloatArray, eta: FloatArray, sensing: SensingParams
    ) -> tuple[UavReport, ...]: ...


def true_trajectory(s: Scenario, noise: RunNoise) -> FloatArray:
    """[N + 1, 4] target states x_0..x_N of the scenario's motion model (eq. 3) driven by the
    run's process noise."""
    F = s.truth_motion.transition(s.dt)
    xs = np.empty((s.N + 1, 4))
    xs[0] = s.x0
    for n in range(1, s.N + 1):
        xs[n] = F @ xs[n - 1] + noise.process[n - 1]
    return xs


@dataclass(frozen=True)
class LabelledScene:
    """The paper's target and its labelled detections. path [N + 1, 4]: the true states
    x_0..x_N; noise: the run's draws (its initial error starts the belief at x_0)."""

    scenario: Scenario
    noise: RunNoise
    path: FloatArray

    @classmethod
    def of(cls, s: Scenario, noise: RunNoise, truth: FloatArray | None = None) -> LabelledScene:
        """The scene of a run; truth [N + 1, 4]: a scripted path (None: `true_trajectory`)."""
        path = true_trajectory(s, noise) if truth is None else np.asarray(truth, dtype=float)
        return cls(s, noise, path)

    @property
    def seed(self) -> int:
        return self.noise.seed

    def truth(self, n: int) -> FloatArray:
        return np.asarray(self.path[n][None])

    def priors(self, n: int) -> tuple[Gaussian, ...]:
        s = self.scenario
        if n != 0:
            return ()
        return (Gaussian(x=s.x0 + self.noise.initial_error, P=s.P0.copy()),)

    def reports(
        self, n: int, uav_xy_m: FloatArray, eta: FloatArray, sensing: SensingParams
    ) -> tuple[UavReport, ...]:
        # Noise from the true geometry; the tracker uses the variances at its prediction.
        z = noisy_detections(
            self.path[n],
            uav_xy_m,
            eta,
            sensing,
            self.noise.measurement[n - 1],
            self.noise.miss_draw[n - 1],
            self.scenario.missed_detection_prob,
        )
        M = len(uav_xy_m)
        out = []
        for m in range(M):
            row = np.array([[z[m], z[M + m]]])
            seen = bool(np.isfinite(row).any())
            out.append(
                UavReport(
                    row if seen else np.zeros((0, 2)),
                    np.full(int(seen), TARGET, dtype=np.int64),
                )
            )
        return tuple(out)


@dataclass(frozen=True)
class UnlabelledScene:
    """Several targets and the UAVs' unlabelled reports (docs/model.md, "Several targets")."""

    scenario: Scenario
    noise: MultiTargetNoise
    paths: TargetPaths
    """Every target's path (states [N + 1, T, 4], NaN where it is not in the scene)."""
    gains: FloatArray
    """[T] each target's SNR d^4 (its RCS)."""

    @classmethod
    def of(cls, s: Scenario, noise: MultiTargetNoise) -> UnlabelledScene:
        paths = target_paths(s.targets, s.dt, s.kappa, s.N, noise.target_normals)
        return cls(s, noise, paths, target_radar_gains(s))

    @property
    def seed(self) -> int:
        return self.noise.seed

    def truth(self, n: int) -> FloatArray:
        return np.asarray(self.paths.states[n])

    def priors(self, n: int) -> tuple[Gaussian, ...]:
        s = self.scenario
        return tuple(
            Gaussian(x=self.paths.states[n, t] + self.noise.initial_errors[t], P=s.P0.copy())
            for t, spec in enumerate(s.targets)
            if spec.prior_known and spec.first_slot == n
        )

    def reports(
        self, n: int, uav_xy_m: FloatArray, eta: FloatArray, sensing: SensingParams
    ) -> tuple[UavReport, ...]:
        detection = self.scenario.detection
        assert detection is not None  # the factory builds this scene only with one
        draws = self.noise.slots[n - 1]
        return tuple(
            unlabelled_detections(
                self.paths.states[n], self.gains, uav_xy_m, eta, sensing, detection, draws
            )
        )
