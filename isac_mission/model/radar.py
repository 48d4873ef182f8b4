"""Range/Doppler measurement model (eq. 5-8).

Measurement y = [d_1..d_M, v_1..v_M]: ranges (m) and radial velocities (m/s) of the target seen
from UAVs at uav_xy [M, 2]; UAVs and target fly at the same altitude, so distances are horizontal.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from isac_mission.types import FloatArray

if TYPE_CHECKING:
    from isac_mission.config import Scenario

Values = Any
"""numpy arrays, or CasADi expressions (the NLPs build eq. 8 symbolically from the same code)."""


@dataclass(frozen=True)
class SensingParams:
    """Constants of eq. 8: SNR^s = radar_gain / d^4 [m^4]; alpha_d, alpha_v; B [Hz]; Ts [s].

    The one definition of eq. 8's information: the objective (tracking/pcrb.py), the simulated
    detections (model/detections.py) and the polish and horizon NLPs (planning/nlp_model.py)
    all evaluate these methods, on numpy arrays or on CasADi symbols.
    """

    radar_gain: float
    alpha_d: float
    alpha_v: float
    B: float
    Ts: float

    @classmethod
    def from_scenario(cls, s: Scenario) -> SensingParams:
        return cls(s.radar_gain, s.alpha_d, s.alpha_v, s.B, s.Ts)

    def range_information(self, range_m: Values, eta: Values) -> Values:
        """a = 1 / sigma_d^2 = radar_gain (eta B)^2 / (alpha_d d^4) [1/m^2], shape of range_m."""
        return self.radar_gain * (_values(eta) * self.B) ** 2 / (self.alpha_d * range_m**4)

    def velocity_information(self, range_m: Values) -> Values:
        """b = 1 / sigma_v^2 = radar_gain Ts^2 / (alpha_v d^4) [s^2/m^2], shape of range_m."""
        return self.radar_gain * self.Ts**2 / (self.alpha_v * _values(range_m) ** 4)

    def variances(self, range_m: FloatArray, eta: FloatArray) -> FloatArray:
        """r_diag [2M]: sigma_d^2 (m^2) then sigma_v^2 (m^2/s^2) for ranges [M] and shares [M]."""
        return np.concatenate(
            [1.0 / self.range_information(range_m, eta), 1.0 / self.velocity_information(range_m)]
        )


def _values(x: Any) -> Any:
    """x as an array when it is a Python number or sequence; CasADi symbols and arrays as given."""
    return x if hasattr(x, "shape") else np.asarray(x)


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
    """(sigma_d^2 [M] in m^2, sigma_v^2 [M] in m^2/s^2) from eq. 8 (SensingParams.variances).

    sigma_d^2 = alpha_d / (SNR^s (eta B)^2) and sigma_v^2 = alpha_v / (SNR^s Ts^2).
    """
    r = np.asarray(range_m, dtype=float)
    variances = SensingParams(radar_gain, alpha_d, alpha_v, B, Ts).variances(r, np.asarray(eta))
    return variances[: r.size].reshape(r.shape), variances[r.size :].reshape(r.shape)


def measure(x: FloatArray, uav_xy: FloatArray) -> FloatArray:
    """h(x) [2M] of eq. 6 for target state x [4]."""
    r = x[None, :2] - uav_xy
    d = np.linalg.norm(r, axis=1)
    v = (r @ x[2:]) / d
    return np.concatenate([d, v])


def measurement_directions(
    x: FloatArray, uav_xy: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(g [M, 4], k [M, 4], d [M]): range and radial-velocity gradients d(d_m)/dx, d(v_m)/dx and
    the ranges, at target state x [4] seen from uav_xy [M, 2] (the rows of H in eq. 10)."""
    r = x[None, :2] - uav_xy
    d = np.linalg.norm(r, axis=1)
    u = r / d[:, None]
    v_r = u @ x[2:]
    m = uav_xy.shape[0]
    g = np.zeros((m, 4))
    g[:, :2] = u
    k = np.empty((m, 4))
    k[:, :2] = (x[None, 2:] - v_r[:, None] * u) / d[:, None]
    k[:, 2:] = u
    return g, k, d


def measurement_jacobian(x: FloatArray, uav_xy: FloatArray) -> FloatArray:
    """H [2M, 4] = dh/dx at x [4] (eq. 10): rows d_1..d_M then v_1..v_M."""
    g, k, _ = measurement_directions(x, uav_xy)
    return np.vstack([g, k])
