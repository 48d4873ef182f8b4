"""Noisy detections from the truth, written once (eq. 6-8): the offline loop and `sim/` use it.

For UAV m at horizontal position q_m, the true range d_m and radial velocity v_m come from h(x)
(`measure`, eq. 6); Gaussian noise with the model's variances at the UAV's bandwidth share eta_m
(eq. 8) is added, from standard normals the caller drew:

    z = [d_1..d_M, v_1..v_M] + sqrt([sigma_d^2, sigma_v^2]) * normals.

UAV m's detection is missed (both entries NaN) when its uniform draw is below the miss
probability, when it has no sensing bandwidth (eta_m <= 0 or not finite), or when it is exactly
above the target (d_m = 0: radial velocity undefined). The function draws nothing: the caller owns
the random numbers and their order (common random numbers across methods offline; one stream per
world in `sim/sensing.py`). Pure: numpy only.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from isac_mission.model.radar import measure
from isac_mission.types import FloatArray


class VarianceModel(Protocol):
    """Eq. 8: r_diag [2M] (sigma_d^2 in m^2, then sigma_v^2 in m^2/s^2) at ranges [M], shares
    [M] (`isac_mission.tracking.pcrb.SensingParams` is one)."""

    def variances(self, range_m: FloatArray, eta: FloatArray) -> FloatArray: ...


def noisy_detections(
    target_x: FloatArray,
    uav_xy_m: FloatArray,
    eta: FloatArray,
    model: VarianceModel,
    normals: FloatArray,
    uniforms: FloatArray,
    missed_detection_prob: float,
) -> FloatArray:
    """z [2M]: ranges (m) then radial velocities (m/s) with noise; NaN where missed.

    target_x [4]: true state [x, y, vx, vy] (m, m/s); uav_xy_m [M, 2] (m); eta [M]; normals
    [2M]: standard normals (range noise of UAVs 1..M, then velocity noise); uniforms [M] in
    [0, 1): the miss draws; missed_detection_prob in [0, 1).
    """
    m = uav_xy_m.shape[0]
    with np.errstate(divide="ignore", invalid="ignore"):  # d = 0 or eta = 0: masked below
        z_clean = measure(target_x, uav_xy_m)
        variances = model.variances(z_clean[:m], eta)
        z: FloatArray = z_clean + np.sqrt(variances) * normals
    sensed = (
        (z_clean[:m] > 0.0) & (eta > 0.0) & np.isfinite(eta) & (uniforms >= missed_detection_prob)
    )
    z[~np.concatenate([sensed, sensed])] = np.nan
    return z
