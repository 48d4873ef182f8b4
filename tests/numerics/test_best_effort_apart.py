"""The best-effort plan of an infeasible slot keeps the UAVs apart (planning/fallback.py
`kept_apart`): two UAVs served by one BS were sent to its one link-optimal point (seen on
config/manoeuvring.yaml, `horizon`, seed 3: two UAVs on the same point for four slots); now
those that would meet hold. Checked against a brute-force pairwise check."""

from __future__ import annotations

import numpy as np

from isac_mission.planning.fallback import kept_apart

SEPARATION_M = 30.0


def _closest_pair_m(xy: np.ndarray) -> float:
    return min(
        float(np.hypot(*(xy[i] - xy[j]))) for i in range(len(xy)) for j in range(i + 1, len(xy))
    )


def test_two_uavs_sent_to_one_point_are_kept_apart_and_the_others_fly() -> None:
    prev = np.array([[0.0, 0.0], [40.0, 0.0], [500.0, 500.0], [900.0, 0.0]])
    planned = np.array([[20.0, 5.0], [20.0, 5.0], [520.0, 480.0], [880.0, 10.0]])
    got = kept_apart(planned, prev, SEPARATION_M)
    assert _closest_pair_m(got) >= SEPARATION_M
    # The two that met hold; the others fly their waypoints.
    np.testing.assert_array_equal(got[:2], prev[:2])
    np.testing.assert_array_equal(got[2:], planned[2:])


def test_a_chain_of_conflicts_is_resolved_and_nothing_apart_moves() -> None:
    rng = np.random.default_rng(4)
    for _ in range(200):
        prev = np.column_stack([np.arange(6) * 60.0, rng.uniform(-5, 5, 6)])
        planned = prev + rng.uniform(-40, 40, size=prev.shape)
        got = kept_apart(planned, prev, SEPARATION_M)
        assert _closest_pair_m(got) >= SEPARATION_M - 1e-9
        # A UAV is either where it was planned or where it was.
        each = np.all(got == planned, axis=1) | np.all(got == prev, axis=1)
        assert each.all()
        if _closest_pair_m(planned) >= SEPARATION_M:
            np.testing.assert_array_equal(got, planned)
