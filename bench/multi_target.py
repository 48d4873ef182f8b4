"""The multi-target tracker alone (docs/performance.md, "The multi-target tracker"): its time per
slot at two sizes, and beside Stone Soup's JPDA tracker on the same recorded detections.

Detections are drawn once per run (model/detections.py, the run's own random numbers) for UAVs
parked at their start with equal shares, so every tracker sees the same reports:

- `3 targets, 6 UAVs, 2 FA`: config/multi-target.yaml as shipped (one target known at the start,
  one entering at 20 s, one turning, both to be found);
- `10 targets, 24 UAVs, 5 FA`: 24 UAVs on a grid over the 3 km area with the paper's bandwidth per
  UAV (B = 20 MHz x 24 / 6), ten constant-velocity intruders (five known at the start, five to be
  found), P_d = 0.9, 5 false alarms per UAV per slot.

Time per slot: `predict` plus `update` of tracking/multi_target.py (association, initiation,
management, every track's bound), perf_counter, median and p95 over every slot of every run.

Against Stone Soup (1.9, its EKF predictor and updater, `PDAHypothesiser` with the same P_d,
clutter density and gate probability, `JPDA`, and a range-plus-Doppler measurement model from
a moving platform written here): every target known, both trackers start from the same tracks
at each target's appearance and take the UAVs' reports one after another; Stone Soup has no
initiator for a measurement that a single sensor cannot invert, so initiation is off in ours
too, and neither deletes. Mission-mean GOSPA (c = 10 m) of the tracks, and the time per slot.

The small case again with the IMM of config/manoeuvring.yaml on every track (tracker.motion
imm) against the constant-velocity EKF, on the same detections: time per slot and its ratio.

Run: python bench/multi_target.py [--runs 5] [--slots 60]
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from isac_mission.config import Scenario, load_scenario, parse_scenario
from isac_mission.model.detections import unlabelled_detections
from isac_mission.model.radar import SensingParams
from isac_mission.model.run_noise import draw_multi_target_noise
from isac_mission.model.targets import target_paths, target_radar_gains
from isac_mission.tracking.gospa import gospa
from isac_mission.tracking.initiation import InitiationSettings
from isac_mission.tracking.multi_target import MultiTargetTracker, TrackerSettings
from isac_mission.types import FloatArray, Gaussian


@dataclass(frozen=True)
class Recorded:
    """One run's detections: truth [N + 1, T, 4]; reports [N][M] arrays [k, 2]; the UAVs'
    positions [M, 2] and shares [M]; each known target's first belief, by target."""

    truth: FloatArray
    reports: list[list[FloatArray]]
    uav_xy_m: FloatArray
    eta: FloatArray
    first_beliefs: dict[int, Gaussian]


def large_scenario(slots: int) -> Scenario:
    """Ten intruders, 24 UAVs, 5 false alarms per UAV per slot (module docstring)."""
    rng = np.random.default_rng(2026)
    grid = (np.arange(6) + 0.5) / 6, (np.arange(4) + 0.5) / 4
    uavs = [[float(300 + 2400 * x), float(300 + 2400 * y)] for y in grid[1] for x in grid[0]]
    targets = []
    for i in range(10):
        xy = rng.uniform(500, 2500, 2)
        heading = rng.uniform(0, 2 * np.pi)
        speed = rng.uniform(10, 25)
        v = speed * np.array([np.cos(heading), np.sin(heading)])
        targets.append(
            {
                "name": f"t{i}",
                "initial_state": [float(xy[0]), float(xy[1]), float(v[0]), float(v[1])],
                "prior": "known" if i < 5 else "unknown",
            }
        )
    return parse_scenario(
        {
            "mission_id": "bench-10-targets",
            "timing": {"duration_s": slots, "slot_s": 1.0},
            "radio": {"bandwidth_hz": 20e6 * 24 / 6, "bs_capacity": 4},
            "base_stations": {"count": 8},
            "uavs": {"start_xy_m": uavs},
            "targets": targets,
            "sensing": {"missed_detection_prob": 0.1},
            "detection": {"false_alarms_per_slot": 5},
        }
    )


def record(s: Scenario, seed: int) -> Recorded:
    """One run's detections for UAVs parked at their start with equal shares."""
    noise = draw_multi_target_noise(s, seed)
    paths = target_paths(s.targets, s.dt, s.kappa, s.N, noise.target_normals)
    sensing = SensingParams.from_scenario(s)
    gains = target_radar_gains(s)
    eta = np.full(s.M, 1.0 / s.M)
    assert s.detection is not None
    reports = [
        [
            r.measurements
            for r in unlabelled_detections(
                paths.states[n],
                gains,
                s.uav_start_xy,
                eta,
                sensing,
                s.detection,
                noise.slots[n - 1],
            )
        ]
        for n in range(1, s.N + 1)
    ]
    first = {
        t: Gaussian(paths.states[spec.first_slot, t] + noise.initial_errors[t], s.P0.copy())
        for t, spec in enumerate(s.targets)
        if spec.prior_known
    }
    return Recorded(paths.states, reports, s.uav_start_xy, eta, first)


def known_everywhere(s: Scenario) -> Scenario:
    """s with every target known from its appearance."""
    return s.with_changes(targets=tuple(replace(t, prior_known=True) for t in s.targets))


def run_ours(
    s: Scenario, rec: Recorded, initiation: bool = True
) -> tuple[list[float], list[FloatArray]]:
    """(time per slot in s, each slot's confirmed track positions [k, 2])."""
    settings = TrackerSettings.from_scenario(s)
    if not initiation:
        settings = replace(settings, initiation=InitiationSettings(min_uavs=10**6))
    tracker = MultiTargetTracker(settings)
    sensing = SensingParams.from_scenario(s)
    times, estimates = [], []
    for n in range(1, s.N + 1):
        for t, spec in enumerate(s.targets):
            if t in rec.first_beliefs and spec.first_slot == n - 1:
                tracker.add_confirmed(rec.first_beliefs[t])
        start = time.perf_counter()
        tracker.predict()
        out = tracker.update(rec.reports[n - 1], rec.uav_xy_m, rec.eta, sensing)
        times.append(time.perf_counter() - start)
        estimates.append(np.array([t.belief.x[:2] for t in out.confirmed]).reshape(-1, 2))
    return times, estimates


def run_stone_soup(s: Scenario, rec: Recorded) -> tuple[list[float], list[FloatArray]]:
    """Stone Soup's EKF-JPDA on the same reports (module docstring)."""
    from stonesoup.base import Property
    from stonesoup.dataassociator.probability import JPDA
    from stonesoup.functions import gm_reduce_single
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.models.measurement.nonlinear import NonLinearGaussianMeasurement
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor
    from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.types.update import GaussianStateUpdate
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    class RangeDopplerFromPlatform(NonLinearGaussianMeasurement):  # type: ignore[misc]
        """Range and radial velocity of [x, vx, y, vy] seen from a UAV at sensor_xy."""

        sensor_xy: np.ndarray = Property(doc="The UAV's position, m")

        @property
        def ndim_meas(self) -> int:
            return 2

        def function(self, state, noise=False, **kwargs):  # type: ignore[no-untyped-def]
            x = state.state_vector
            r = np.array([x[0, 0] - self.sensor_xy[0], x[2, 0] - self.sensor_xy[1]])
            d = float(np.hypot(*r))
            out = StateVector([d, float(r @ [x[1, 0], x[3, 0]]) / d])
            if noise:
                out = out + self.rvs(num_samples=1, **kwargs)
            return out

        def jacobian(self, state, **kwargs):  # type: ignore[no-untyped-def]
            x = state.state_vector
            r = np.array([x[0, 0] - self.sensor_xy[0], x[2, 0] - self.sensor_xy[1]])
            v = np.array([x[1, 0], x[3, 0]])
            d = float(np.hypot(*r))
            u = r / d
            k = (v - (u @ v) * u) / d
            return np.array([[u[0], 0, u[1], 0], [k[0], u[0], k[1], u[1]]])

        def covar(self, **kwargs):  # type: ignore[no-untyped-def]
            return self.noise_covar

    settings = TrackerSettings.from_scenario(s)
    kappa = (
        s.kappa
        if s.multi_tracker.process_noise_intensity is None
        else (s.multi_tracker.process_noise_intensity)
    )
    transition = CombinedLinearGaussianTransitionModel(
        [ConstantVelocity(kappa), ConstantVelocity(kappa)]
    )
    predictor = ExtendedKalmanPredictor(transition)
    updater = ExtendedKalmanUpdater(measurement_model=None)
    assert s.detection is not None
    hypothesiser = PDAHypothesiser(
        predictor,
        updater,
        clutter_spatial_density=settings.clutter_density,
        prob_detect=s.detection.detection_prob,
        prob_gate=settings.gate_prob,
    )
    associator = JPDA(hypothesiser=hypothesiser)
    sensing = SensingParams.from_scenario(s)
    order = [0, 2, 1, 3]  # ours [x, y, vx, vy] -> Stone Soup's [x, vx, y, vy]
    t0 = datetime.datetime(2026, 1, 1)
    tracks: set[Track] = set()
    times, estimates = [], []
    for n in range(1, s.N + 1):
        stamp = t0 + datetime.timedelta(seconds=n * s.dt)
        for t, spec in enumerate(s.targets):
            if t in rec.first_beliefs and spec.first_slot == n - 1:
                b = rec.first_beliefs[t]
                prior = GaussianState(
                    StateVector(b.x[order]),
                    CovarianceMatrix(b.P[np.ix_(order, order)]),
                    timestamp=stamp - datetime.timedelta(seconds=s.dt),
                )
                tracks.add(Track([prior]))
        start = time.perf_counter()
        for m, z in enumerate(rec.reports[n - 1]):
            detections = set()
            for row in z:
                r = sensing.variances(np.array([row[0]]), rec.eta[m : m + 1])
                model = RangeDopplerFromPlatform(
                    ndim_state=4,
                    mapping=(0, 1, 2, 3),
                    noise_covar=CovarianceMatrix(np.diag(r)),
                    sensor_xy=rec.uav_xy_m[m],
                )
                detections.add(
                    Detection(StateVector(row), timestamp=stamp, measurement_model=model)
                )
            hypotheses = associator.associate(tracks, detections, stamp)
            for track, multi in hypotheses.items():
                states, weights = [], []
                for hypothesis in multi:
                    states.append(
                        updater.update(hypothesis) if hypothesis else hypothesis.prediction
                    )
                    weights.append(float(hypothesis.probability))
                means = StateVectors([state.state_vector for state in states])
                covars = np.stack([state.covar for state in states], axis=2)
                mean, covar = gm_reduce_single(means, covars, np.asarray(weights))
                track.append(GaussianStateUpdate(mean, covar, multi, stamp))
        times.append(time.perf_counter() - start)
        estimates.append(
            np.array([[tr.state_vector[0, 0], tr.state_vector[2, 0]] for tr in tracks]).reshape(
                -1, 2
            )
        )
    return times, estimates


def mission_gospa(rec: Recorded, estimates: list[FloatArray], c: float) -> float:
    """Mean over slots of GOSPA between the targets in the scene and the estimates."""
    values = []
    for n, est in enumerate(estimates, start=1):
        truth = rec.truth[n]
        present = truth[np.all(np.isfinite(truth), axis=1), :2]
        values.append(gospa(present, est, c=c).distance)
    return float(np.mean(values))


def percentile_ms(times: list[float], q: float) -> float:
    return 1e3 * float(np.percentile(times, q))


def print_imm_against_cv(s: Scenario, seeds: range) -> None:
    """The tracker's time per slot with the IMM of config/manoeuvring.yaml on every track
    against the constant-velocity EKF, on the same recorded detections, in this run."""
    imm = s.with_changes(tracker_motion="imm", imm=load_scenario("manoeuvring").imm)
    cells = {}
    for label, scenario in (("cv", s), ("imm", imm)):
        times: list[float] = []
        gospas = []
        for seed in seeds:
            rec = record(s, seed)
            t, est = run_ours(scenario, rec)
            times += t
            gospas.append(mission_gospa(rec, est, s.multi_tracker.gospa_cutoff_m))
        cells[label] = (percentile_ms(times, 50), percentile_ms(times, 95), float(np.mean(gospas)))
    print("The IMM (config/manoeuvring.yaml's modes) against the CV EKF, 3 targets, 6 UAVs, 2 FA:")
    print()
    print("| motion | median / p95 per slot (ms) | ratio of medians | mission GOSPA (m) |")
    print("|---|---|---|---|")
    for label, (med, p95, mean_gospa) in cells.items():
        ratio = med / cells["cv"][0]
        print(f"| {label} | {med:.1f} / {p95:.1f} | {ratio:.2f} | {mean_gospa:.2f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--slots", type=int, default=60)
    args = parser.parse_args()
    small = load_scenario("multi-target").with_changes(N=args.slots)
    large = large_scenario(args.slots)
    seeds = range(1, args.runs + 1)
    print(f"{args.runs} runs x {args.slots} slots; load {Path('/proc/loadavg').read_text()[:14]}")
    print()
    print("| case | tracker median / p95 per slot (ms) | mission GOSPA (m) |")
    print("|---|---|---|")
    for label, s in (("3 targets, 6 UAVs, 2 FA", small), ("10 targets, 24 UAVs, 5 FA", large)):
        times, gospas = [], []
        for seed in seeds:
            rec = record(s, seed)
            t, est = run_ours(s, rec)
            times += t
            gospas.append(mission_gospa(rec, est, s.multi_tracker.gospa_cutoff_m))
        print(
            f"| {label} | {percentile_ms(times, 50):.1f} / {percentile_ms(times, 95):.1f} "
            f"| {np.mean(gospas):.2f} |"
        )
    print()
    print_imm_against_cv(small, seeds)
    print()
    known = known_everywhere(small)
    c = known.multi_tracker.gospa_cutoff_m
    rows = []
    for seed in seeds:
        rec = record(known, seed)
        ours_t, ours_est = run_ours(known, rec, initiation=False)
        ss_t, ss_est = run_stone_soup(known, rec)
        rows.append(
            (
                mission_gospa(rec, ours_est, c),
                mission_gospa(rec, ss_est, c),
                float(np.median(ours_t)),
                float(np.median(ss_t)),
            )
        )
    r = np.array(rows)
    print("Against Stone Soup's JPDA (every target known; per run, then the mean):")
    print()
    print(
        "| seed | GOSPA ours / Stone Soup (m) | ratio | time per slot ours / Stone Soup (ms) | ratio |"
    )
    print("|---|---|---|---|---|")
    for seed, (g_o, g_s, t_o, t_s) in zip(seeds, r, strict=True):
        print(
            f"| {seed} | {g_o:.3f} / {g_s:.3f} | {g_o / g_s:.3f} | {1e3 * t_o:.1f} / "
            f"{1e3 * t_s:.1f} | {t_o / t_s:.2f} |"
        )
    g_o, g_s, t_o, t_s = r.mean(axis=0)
    print(
        f"| mean | {g_o:.3f} / {g_s:.3f} | {g_o / g_s:.3f} | {1e3 * t_o:.1f} / {1e3 * t_s:.1f} "
        f"| {t_o / t_s:.2f} |"
    )


if __name__ == "__main__":
    main()
