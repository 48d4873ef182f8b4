"""One run's random numbers, drawn from its seed: what `simulate` draws for run r (seed + r),
and what the simulated world of `run` / `sim` draws for the same seed, so that a live mission's
target flies the path of its offline twin (docs/performance.md, "Live against offline").

Pure: numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.kinematics import process_noise
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
    W = process_noise(s.dt, s.kappa)
    return RunNoise(
        seed=seed,
        process=rng.multivariate_normal(np.zeros(4), W, size=s.N),
        initial_error=rng.multivariate_normal(np.zeros(4), s.P0),
        measurement=rng.standard_normal((s.N, 2 * s.M)),
        miss_draw=rng.uniform(size=(s.N, s.M)),
    )
