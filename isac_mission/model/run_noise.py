"""One run's random numbers, drawn from its seed: what `simulate` draws for run r (seed + r),
and what the simulated world of `run` / `sim` draws for the same seed, so that a live mission's
target flies the path of its offline twin (docs/performance.md, "Live against offline").

Pure: numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.detections import SlotDraws
from isac_mission.types import FloatArray


@dataclass(frozen=True)
class RunNoise:
    """Common random numbers of one run.

    process [N, 4]: target process noise w_{n-1}; initial_error [4]: x_hat_0 - x_0;
    measurement [N, 2M]: standard normals; miss_draw [N, M]: uniforms for missed detections.
    """

    seed: int
    process: FloatArray
    initial_error: FloatArray
    measurement: FloatArray
    miss_draw: FloatArray


def draw_run_noise(s: Scenario, seed: int) -> RunNoise:
    """Draw one run's random numbers from a seeded generator."""
    rng = np.random.default_rng(seed)
    W = s.truth_motion.process_noise(s.dt)
    return RunNoise(
        seed=seed,
        process=rng.multivariate_normal(np.zeros(4), W, size=s.N),
        initial_error=rng.multivariate_normal(np.zeros(4), s.P0),
        measurement=rng.standard_normal((s.N, 2 * s.M)),
        miss_draw=rng.uniform(size=(s.N, s.M)),
    )


MULTI_TARGET_STREAM = 26
"""The second key of the multi-target draws' generator, [seed, 26]: a stream of its own, so a
single-target run's numbers (`draw_run_noise`) are the same whether or not these are drawn."""


@dataclass(frozen=True)
class MultiTargetNoise:
    """One run's random numbers of the multi-target path (docs/model.md, "Several targets").

    target_normals [T, N, 4]: standard normals of every target's process noise (model/targets.py);
    slots [N]: each slot's draws of the unlabelled detections (model/detections.SlotDraws);
    initial_errors [T, 4]: x_hat - x of each known target's first belief, ~ N(0, P0) (drawn
    after the rest, so the draws above are those of a generator that draws no more).
    """

    seed: int
    target_normals: FloatArray
    slots: tuple[SlotDraws, ...]
    initial_errors: FloatArray


def draw_multi_target_noise(s: Scenario, seed: int) -> MultiTargetNoise:
    """Draw a run's multi-target numbers from the generator [seed, MULTI_TARGET_STREAM]; the false
    alarms' counts are Poisson with the scenario's mean per UAV per slot."""
    rng = np.random.default_rng([seed, MULTI_TARGET_STREAM])
    T, M = max(len(s.targets), 1), s.M
    rate = 0.0 if s.detection is None else s.detection.false_alarms_per_slot
    target_normals = rng.standard_normal((T, s.N, 4))
    slots = []
    for _ in range(s.N):
        counts = rng.poisson(rate, size=M)
        slots.append(
            SlotDraws(
                normals=rng.standard_normal((M, T, 2)),
                detect=rng.uniform(size=(M, T)),
                target_keys=rng.uniform(size=(M, T)),
                clutter=tuple(rng.uniform(size=(int(c), 3)) for c in counts),
            )
        )
    initial_errors = rng.multivariate_normal(np.zeros(4), s.P0, size=T)
    return MultiTargetNoise(seed, target_normals, tuple(slots), initial_errors)
