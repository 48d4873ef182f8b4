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

Several targets (`unlabelled_detections`; docs/model.md, "Several targets"): each UAV reports a
set of (range, Doppler) measurements with no target label, one per target it detects (the
detection probability fixed, or from the echo's SNR) plus its false alarms (a Poisson number,
uniform over its range-Doppler window), in a random order.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from isac_mission.config.targets import DetectionSpec
from isac_mission.model.radar import SensingParams, measure
from isac_mission.types import FloatArray, IntArray


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


CLUTTER = -1
"""UavReport.origin of a false alarm."""


@dataclass(frozen=True)
class UavReport:
    """One UAV's detections of one slot, unlabelled: measurements [k, 2] (range m, radial
    velocity m/s), in a random order; origin [k]: the target index of each, or CLUTTER (the
    truth, for traces and metrics only: a tracker never reads it)."""

    measurements: FloatArray
    origin: IntArray


@dataclass(frozen=True)
class SlotDraws:
    """The random numbers of one slot's unlabelled detections (the caller draws them).

    normals [M, T, 2]: standard normals of each UAV's measurement of each target;
    detect [M, T]: uniforms in [0, 1) of whether it is detected; target_keys [M, T]: uniforms
    that order the report; clutter: per UAV an array [c_m, 3] of uniforms (range, Doppler within
    the window, order key), c_m the Poisson number of its false alarms.
    """

    normals: FloatArray
    detect: FloatArray
    target_keys: FloatArray
    clutter: tuple[FloatArray, ...]


def detection_probability(
    range_m: FloatArray,
    radar_gain: FloatArray,
    detection: DetectionSpec,
    bandwidth_hz: float,
    cpi_s: float,
) -> FloatArray:
    """P_d [...] of echoes at range_m [...] (m) of targets with radar_gain [...] (m^4): fixed,
    or exp(-threshold / SNR) with SNR = SNR^s B T^s the echo's energy-to-noise ratio over the
    CPI (Swerling I: a Rayleigh-fluctuating echo against a square-law threshold)."""
    r = np.asarray(range_m, dtype=float)
    if detection.model == "fixed":
        return np.full(r.shape, detection.detection_prob)
    snr = np.asarray(radar_gain, dtype=float) / r**4 * bandwidth_hz * cpi_s
    return np.asarray(np.exp(-detection.snr_threshold / snr))


def unlabelled_detections(
    target_states: FloatArray,
    radar_gains: FloatArray,
    uav_xy_m: FloatArray,
    eta: FloatArray,
    sensing: SensingParams,
    detection: DetectionSpec,
    draws: SlotDraws,
) -> list[UavReport]:
    """Each UAV's report [M]: a (range, Doppler) measurement of every target it detects, with
    the noise of eq. 8 at its share, and its false alarms spread uniformly over the window.

    target_states [T, 4]: the true states (m, m/s), NaN rows for targets not in the scene;
    radar_gains [T]: each target's SNR^s d^4 (m^4, its RCS); uav_xy_m [M, 2]; eta [M]: a UAV
    with no share (eta <= 0) senses nothing, false alarms included.
    """
    states = np.asarray(target_states, dtype=float)
    present = np.all(np.isfinite(states), axis=1)
    M = len(uav_xy_m)
    reports = []
    (r_lo, r_hi), (v_lo, v_hi) = detection.range_window_m, detection.doppler_window_mps
    for m in range(M):
        rows, origin, keys = [], [], []
        if eta[m] > 0 and np.isfinite(eta[m]):
            for t in np.flatnonzero(present):
                with np.errstate(divide="ignore", invalid="ignore"):
                    clean = measure(states[t], uav_xy_m[m : m + 1])
                if not clean[0] > 0:
                    continue
                pd = detection_probability(
                    clean[:1], np.asarray([radar_gains[t]]), detection, sensing.B, sensing.Ts
                )[0]
                if draws.detect[m, t] >= pd:
                    continue
                target_sensing = replace(sensing, radar_gain=float(radar_gains[t]))
                var = target_sensing.variances(clean[:1], np.asarray([eta[m]]))
                rows.append(clean + np.sqrt(var) * draws.normals[m, t])
                origin.append(int(t))
                keys.append(float(draws.target_keys[m, t]))
            u = draws.clutter[m]
            for row in u:
                rows.append(
                    np.array([r_lo + row[0] * (r_hi - r_lo), v_lo + row[1] * (v_hi - v_lo)])
                )
                origin.append(CLUTTER)
                keys.append(float(row[2]))
        order = np.argsort(np.asarray(keys), kind="stable")
        z = np.asarray(rows, dtype=float).reshape(-1, 2)[order]
        reports.append(UavReport(z, np.asarray(origin, dtype=np.int64)[order]))
    return reports
