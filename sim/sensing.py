"""Simulated radar detections from the truth (pure: numpy only, seeded).

For every UAV m at horizontal position q_m, the true range d_m and radial velocity v_m of the
target come from the model's h(x) (`isac_mission.model.radar.measure`, eq. 6); Gaussian noise with
the model's variances at the UAV's bandwidth share eta_m (eq. 8) is added; the noisy values come
from `isac_mission.model.detections.noisy_detections`, the function the offline loop uses too:

    d_m + N(0, sigma_d^2(d_m, eta_m)),   v_m + N(0, sigma_v^2(d_m)).

A detection is missed with probability `missed_detection_prob` (both the range and the radial
velocity of that UAV are then NaN). A UAV with share eta_m <= 0 has no sensing bandwidth and
returns NaN too, as does a UAV exactly above the target (d_m = 0, radial velocity undefined).

The random draws per call are fixed in number and order (M range normals, M velocity normals, M
uniforms for the misses) whatever the shares and misses, so runs with the same seed see the same
noise sequence: common random numbers across methods.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from isac_mission.model.detections import noisy_detections
from isac_mission.tracking.pcrb import SensingParams
from isac_mission.types import Detections, FloatArray

if TYPE_CHECKING:
    from isac_mission.config import Scenario


@dataclass(frozen=True)
class SensingModel:
    """Constants of eq. 7-8: radar_gain c0 (m^4, SNR^s = c0 / d^4), alpha_d (m^2 Hz^2),
    alpha_v (m^2/s^2 s^2), total bandwidth B (Hz), CPI Ts (s) and the miss probability in [0, 1)."""

    radar_gain: float
    alpha_d: float
    alpha_v: float
    B: float
    Ts: float
    missed_detection_prob: float = 0.0

    @classmethod
    def from_scenario(cls, s: Scenario) -> SensingModel:
        """The sensing model a scenario resolves to."""
        return cls(
            radar_gain=s.radar_gain,
            alpha_d=s.alpha_d,
            alpha_v=s.alpha_v,
            B=s.B,
            Ts=s.Ts,
            missed_detection_prob=s.missed_detection_prob,
        )

    @property
    def params(self) -> SensingParams:
        """The eq. 8 constants as the tracking code holds them (one variance formula)."""
        return SensingParams(self.radar_gain, self.alpha_d, self.alpha_v, self.B, self.Ts)

    def variances(self, range_m: FloatArray, eta: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(sigma_d^2 [M] in m^2, sigma_v^2 [M] in m^2/s^2) at ranges range_m [M], shares eta [M]."""
        r = np.asarray(range_m, dtype=float)
        r_diag = self.params.variances(r, np.asarray(eta, dtype=float))
        return r_diag[: r.size], r_diag[r.size :]


class Sensor:
    """Draws one slot's detections for all UAVs from a seeded generator.

    rng is the only source of randomness (give it its own stream, e.g. spawned from the world's
    seed, so that target noise and sensing noise do not shift each other).
    """

    def __init__(self, model: SensingModel, rng: np.random.Generator) -> None:
        if not 0.0 <= model.missed_detection_prob < 1.0:
            raise ValueError(
                f"missed_detection_prob must be in [0, 1), got {model.missed_detection_prob}"
            )
        self.model = model
        self._params = model.params
        self._rng = rng

    def sense(
        self, slot: int, target_x: FloatArray, uav_xy_m: FloatArray, eta: FloatArray
    ) -> Detections:
        """Detections of one slot.

        target_x [4]: true target state; uav_xy_m [M, 2]: the UAVs' actual horizontal positions;
        eta [M]: bandwidth shares in use. Returns `Detections` with range_m [M] (m),
        radial_velocity_mps [M] (m/s), NaN where missed, and uav_xy_m [M, 2] as given.
        """
        x = np.asarray(target_x, dtype=float)
        q = np.asarray(uav_xy_m, dtype=float)
        e = np.asarray(eta, dtype=float)
        if x.shape != (4,):
            raise ValueError(f"target_x must have shape (4,), got {x.shape}")
        if q.ndim != 2 or q.shape[1] != 2:
            raise ValueError(f"uav_xy_m must have shape (M, 2), got {q.shape}")
        m = q.shape[0]
        if e.shape != (m,):
            raise ValueError(f"eta must have shape ({m},), got {e.shape}")
        z_d: FloatArray = self._rng.standard_normal(size=(m,))
        z_v: FloatArray = self._rng.standard_normal(size=(m,))
        u: FloatArray = self._rng.random(size=(m,))
        z = noisy_detections(
            x,
            q,
            e,
            self._params,
            np.concatenate([z_d, z_v]),
            u,
            self.model.missed_detection_prob,
        )
        rng_m, vel_mps = z[:m], z[m:]
        return Detections(slot=slot, range_m=rng_m, radial_velocity_mps=vel_mps, uav_xy_m=q.copy())


def equal_shares(m: int) -> FloatArray:
    """eta [M] = 1/M each: the shares in use before the first plan arrives."""
    if m < 1:
        raise ValueError(f"need at least one UAV, got {m}")
    return np.full(m, 1.0 / m)
