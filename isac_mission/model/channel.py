"""LoS UAV-BS channel, FDMA rate and the control-link range (eq. 1-2, 14b, 19a, 20a).

Distances are horizontal (m); dH = H - H^B (m); rho0 = Pu beta0 / sigma0^2 (m^2); B in Hz; rates
in bit/s. Following eq. 2, the noise power sigma0^2 does not scale with the share eta
(docs/model.md, "Communication").
"""

from __future__ import annotations

import numpy as np

from isac_mission.types import FloatArray


def channel_gain(horizontal_m: FloatArray, dH: float, beta0: float) -> FloatArray:
    """h = beta0 / (d^2 + dH^2), eq. 1; linear."""
    return beta0 / (np.asarray(horizontal_m) ** 2 + dH**2)


def full_band_rate(horizontal_m: FloatArray, dH: float, rho0: float, B: float) -> FloatArray:
    """R~ = B log2(1 + rho0 / (d^2 + dH^2)) (Lemma 1): the rate with the whole band, bit/s."""
    return B * np.log2(1.0 + rho0 / (np.asarray(horizontal_m) ** 2 + dH**2))


def rate(eta: FloatArray, horizontal_m: FloatArray, dH: float, rho0: float, B: float) -> FloatArray:
    """R = eta B log2(1 + Pu h / sigma0^2), eq. 2 for the associated BS; bit/s."""
    return np.asarray(eta) * full_band_rate(horizontal_m, dH, rho0, B)


def control_range(P_bs: float, beta0: float, noise_w: float, gamma_th: float, dH: float) -> float:
    """d_th = sqrt(P_bs beta0 / (sigma0^2 Gamma_th) - dH^2) (14b); 0 if the link never closes."""
    sq = P_bs * beta0 / (noise_w * gamma_th) - dH**2
    return float(np.sqrt(sq)) if sq > 0 else 0.0


def min_share(
    horizontal_m: FloatArray, r_th: float, dH: float, rho0: float, B: float
) -> FloatArray:
    """eta_min = R_th / R~ (20a): the smallest share that meets R_th at this distance."""
    return r_th / full_band_rate(horizontal_m, dH, rho0, B)


def rate_radius(eta: FloatArray, r_th: float, dH: float, rho0: float, B: float) -> FloatArray:
    """The horizontal distance within which share eta meets R_th (19a), m; 0 where none does.

    sqrt(rho0 / (2^(R_th / (eta B)) - 1) - dH^2); the exponent is clipped so tiny shares give 0.
    """
    exponent = np.minimum(r_th / (np.asarray(eta, dtype=float) * B), 1000.0)
    sq = rho0 / np.expm1(exponent * np.log(2.0)) - dH**2
    return np.asarray(np.sqrt(np.maximum(sq, 0.0)))
