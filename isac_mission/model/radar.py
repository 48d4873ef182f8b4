"""Range/Doppler measurement model (eq. 5-8).

Measurement y = [d_1..d_M, v_1..v_M]: ranges (m) and radial velocities (m/s) of the target seen
from UAVs at uav_xy [M, 2]; UAVs and target fly at the same altitude, so distances are horizontal.
"""

from __future__ import annotations

import numpy as np

from isac_mission.types import FloatArray


def echo_snr(range_m: FloatArray, radar_gain: float) -> FloatArray:
    """SNR^s = lambda^2 Pu sigma_RCS / ((4 pi)^3 d^4 sigma0^2) = radar_gain / d^4 (Sec. II-B)."""
    return radar_gain / np.asarray(range_m) ** 4


def noise_variances(
    range_m: FloatArray,
    eta: FloatArray,
    *,
    radar_gain: float,
    alpha_d: float,
    alpha_v: float,
    B: float,
    Ts: float,
) -> tuple[FloatArray, FloatArray]:
    """(sigma_d^2 [M] in m^2, sigma_v^2 [M] in m^2/s^2) from eq. 8.

    sigma_d^2 = alpha_d / (SNR^s (eta B)^2) and sigma_v^2 = alpha_v / (SNR^s Ts^2).
    """
    snr = echo_snr(range_m, radar_gain)
    var_d = alpha_d / (snr * (np.asarray(eta) * B) ** 2)
    var_v = alpha_v / (snr * Ts**2) * np.ones_like(var_d)
    return var_d, var_v


def measure(x: FloatArray, uav_xy: FloatArray) -> FloatArray:
    """h(x) [2M] of eq. 6 for target state x [4]."""
    r = x[None, :2] - uav_xy
    d = np.linalg.norm(r, axis=1)
    v = (r @ x[2:]) / d
    return np.concatenate([d, v])


def measurement_jacobian(x: FloatArray, uav_xy: FloatArray) -> FloatArray:
    """H [2M, 4] = dh/dx at x [4] (eq. 10): rows d_1..d_M then v_1..v_M."""
    r = x[None, :2] - uav_xy
    d = np.linalg.norm(r, axis=1)
    u = r / d[:, None]
    v_r = u @ x[2:]
    m = uav_xy.shape[0]
    H = np.zeros((2 * m, 4))
    H[:m, :2] = u
    H[m:, :2] = (x[None, 2:] - v_r[:, None] * u) / d[:, None]
    H[m:, 2:] = u
    return H
