"""The multi-target tracker with the IMM (tracker.motion imm; tracking/imm.py,
tracking/multi_target.py) on scripted detections:

- a crafted crossing: a target that starts a turn at 4 m/s^2 two slots before it crosses the path
  of one flying straight, and passes within 20 m of it; with each UAV's report associated against the mixture of each track's modes
  (`mode_rows`), both tracks keep their IDs on their targets through the crossing, the turning
  track's turn mode takes over and the straight one's does not;
- the IMM-JPDA row of a track is the mixture of its modes' ratios, gated where some mode gates
  (against an independent computation);
- a tracker restored from `saved` goes on exactly, its modes included.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from isac_mission.config.sections import ImmModeSpec, ImmSpec
from isac_mission.model.radar import measure
from isac_mission.model.targets import coordinated_turn_matrix
from isac_mission.tracking.association import gate_threshold
from isac_mission.tracking.imm import ImmBelief, imm_model, imm_predict, imm_start, mode_rows
from isac_mission.tracking.multi_target import MultiTargetTracker
from isac_mission.tracking.tracker import TrackEstimate
from isac_mission.types import FloatArray, Gaussian
from tests.numerics.test_multi_target_tracker import ETA, SENSING, UAV_XY, report, settings

SPEC = ImmSpec(
    modes=(
        ImmModeSpec("cv", 0.05),
        ImmModeSpec("ct", 0.5, 0.001),
        ImmModeSpec("cv", 8.0),
    ),
    switching=((0.90, 0.05, 0.05), (0.05, 0.90, 0.05), (0.10, 0.10, 0.80)),
    initial_probabilities=(0.8, 0.1, 0.1),
)
IMM = imm_model(SPEC, 1.0)
SLOTS = 40
CROSS_SLOT = 20
TURN_SLOT = 18
OMEGA_RADPS = 0.2
"""The turning target's rate from TURN_SLOT on: 4 m/s^2 at 20 m/s."""


def straight_path() -> FloatArray:
    """[SLOTS + 1, 4]: east at 20 m/s, at (1000, 1000) at CROSS_SLOT."""
    t = np.arange(SLOTS + 1, dtype=float) - CROSS_SLOT
    return np.column_stack(
        [1000.0 + 20.0 * t, np.full_like(t, 1000.0), np.full_like(t, 20.0), np.zeros_like(t)]
    )


def turning_path() -> FloatArray:
    """[SLOTS + 1, 4]: south at 20 m/s through (1000, 1100) at TURN_SLOT, then turning at
    OMEGA_RADPS (4 m/s^2, counter-clockwise): it comes within 20 m of the straight target."""
    at_turn = np.array([1000.0, 1100.0, 0.0, -20.0])
    out = []
    for n in range(SLOTS + 1):
        if n <= TURN_SLOT:
            out.append(np.concatenate([at_turn[:2] + (n - TURN_SLOT) * at_turn[2:], at_turn[2:]]))
        else:
            out.append(coordinated_turn_matrix(n - TURN_SLOT, OMEGA_RADPS) @ at_turn)
    return np.array(out)


Slot = tuple[dict[int, TrackEstimate], dict[int, ImmBelief | None]]


def fly(
    tracker: MultiTargetTracker, paths: list[FloatArray], slots: range, seed: int
) -> list[Slot]:
    """Each slot's tracks (ID -> estimate) and their modes (ID -> modes) after feeding the
    targets' reports."""
    rng = np.random.default_rng(seed)
    out = []
    uavs = list(range(len(UAV_XY)))
    for n in slots:
        tracker.predict()
        per_target = [report(p[n], uavs, rng) for p in paths]
        # Each UAV sees every target with P_d = 0.95, in no particular order.
        reports = []
        for m in range(len(UAV_XY)):
            rows = [r[m] for r in per_target if rng.random() < 0.95]
            merged = np.vstack(rows) if rows else np.zeros((0, 2))
            reports.append(merged[rng.permutation(len(merged))])
        tracking = tracker.update(reports, UAV_XY, ETA, SENSING)
        modes = {t.track_id: t.modes for t in tracker._tracks if t.track_id > 0}
        out.append(({t.track_id: t for t in tracking.tracks}, modes))
    return out


def test_a_turning_and_a_straight_target_crossing_keep_their_tracks() -> None:
    straight, turning = straight_path(), turning_path()
    closest_m = np.hypot(*(straight[:, :2] - turning[:, :2]).T).min()
    assert 10.0 < closest_m < 20.0, closest_m
    tracker = MultiTargetTracker(settings(imm=IMM))
    p0 = np.diag([4.0, 4.0, 1.0, 1.0])
    ids = [
        tracker.add_confirmed(Gaussian(x=straight[0] + [1.0, -1.0, 0.2, 0.0], P=p0)),
        tracker.add_confirmed(Gaussian(x=turning[0] + [-1.0, 1.0, 0.0, 0.2], P=p0)),
    ]
    probabilities: dict[int, list[FloatArray]] = {i: [] for i in ids}
    slots = fly(tracker, [straight, turning], range(1, SLOTS + 1), seed=7)
    for n, (tracks, modes_of) in zip(range(1, SLOTS + 1), slots, strict=True):
        assert sorted(tracks) == ids, (n, sorted(tracks))  # none lost, none started
        for track_id, truth in zip(ids, (straight, turning), strict=True):
            off_m = np.hypot(*(tracks[track_id].belief.x[:2] - truth[n, :2]))
            assert off_m < 15.0, (n, track_id, off_m)
        for track_id in ids:
            modes = modes_of[track_id]
            assert modes is not None
            probabilities[track_id].append(modes.probabilities.copy())
    turn_share = {i: np.array(p)[:, 1] for i, p in probabilities.items()}
    # Slot n is entry n - 1. The turning track is in its turn mode from a few slots into the
    # turn, and not before it; the straight track never is.
    turning_share, straight_share = turn_share[ids[1]], turn_share[ids[0]]
    assert np.mean(turning_share[TURN_SLOT + 2 :]) > 0.8, turning_share
    assert np.mean(turning_share[5 : TURN_SLOT - 1]) < 0.3, turning_share
    assert np.mean(straight_share[5:]) < 0.3, straight_share
    last = slots[-1][1][ids[1]]
    assert last is not None
    omega = last.means[1, 4]
    assert abs(omega - OMEGA_RADPS) < 0.03, omega


def test_the_association_row_is_the_mixture_of_the_modes() -> None:
    belief = imm_predict(
        IMM,
        imm_start(
            IMM, Gaussian(x=np.array([900.0, 700.0, 12.0, -5.0]), P=np.diag([25.0, 25.0, 4.0, 4.0]))
        ),
    )
    # Spread the modes apart so that each gates a different measurement.
    means = belief.means.copy()
    means[2, 2] += 6.0  # the high-noise mode thinks it sped up
    belief = ImmBelief(means, belief.covariances, np.array([0.6, 0.3, 0.1]))
    uav = UAV_XY[0]
    r_pair = SENSING.variances(np.array([np.hypot(*(means[0, :2] - uav))]), ETA[:1])
    z = np.vstack([measure(means[j, :4], uav[None]) for j in range(3)])
    z[0, 0] += 400.0  # far from every mode
    gate = gate_threshold(0.99)
    pd, lam = 0.9, 1e-4
    row = mode_rows(belief, z, uav, r_pair, pd, lam, gate)
    # Independently: each mode's Gaussian at its own predicted measurement.
    want = np.zeros(3)
    inside = np.zeros(3, dtype=bool)
    R = np.diag(r_pair)
    for j, c in enumerate(belief.probabilities):
        x, P = means[j], belief.covariances[j]
        eps = 1e-6
        H = np.zeros((2, 5))
        for a in range(4):
            step = np.zeros(4)
            step[a] = eps
            H[:, a] = (measure(x[:4] + step, uav[None]) - measure(x[:4] - step, uav[None])) / (
                2 * eps
            )
        S = H @ P @ H.T + R
        nu = z - measure(x[:4], uav[None])
        d2 = np.array([v @ np.linalg.solve(S, v) for v in nu])
        dens = np.exp(-0.5 * d2) / np.sqrt(np.linalg.det(2 * np.pi * S))
        want += np.where(d2 <= gate, c * pd * dens / lam, 0.0)
        inside |= d2 <= gate
    np.testing.assert_allclose(row.likelihood_ratio, want, rtol=1e-5)
    np.testing.assert_array_equal(row.gated, inside)
    assert not row.gated[0] and row.gated[2]  # only the sped-up mode expects the third


def test_a_restored_imm_tracker_goes_on_exactly() -> None:
    straight, turning = straight_path(), turning_path()
    p0 = np.diag([4.0, 4.0, 1.0, 1.0])

    def fresh() -> MultiTargetTracker:
        t = MultiTargetTracker(settings(imm=IMM))
        t.add_confirmed(Gaussian(x=straight[0].copy(), P=p0))
        t.add_confirmed(Gaussian(x=turning[0].copy(), P=p0))
        return t

    whole = fresh()
    first = fly(whole, [straight, turning], range(1, 16), seed=3)
    assert first
    saved = whole.saved()
    assert all(t.modes is not None for t in saved.tracks)
    again = MultiTargetTracker.restored(replace(settings(imm=IMM)), saved)
    go_on = fly(whole, [straight, turning], range(16, 30), seed=4)
    resumed = fly(again, [straight, turning], range(16, 30), seed=4)
    for (a, modes_a), (b, modes_b) in zip(go_on, resumed, strict=True):
        assert sorted(a) == sorted(b)
        for i in a:
            ma, mb = modes_a[i], modes_b[i]
            assert ma is not None and mb is not None
            np.testing.assert_array_equal(ma.means, mb.means)
            np.testing.assert_array_equal(ma.probabilities, mb.probabilities)
            np.testing.assert_array_equal(a[i].belief.x, b[i].belief.x)
            np.testing.assert_array_equal(a[i].belief.P, b[i].belief.P)
            np.testing.assert_array_equal(a[i].bound.J, b[i].bound.J)
