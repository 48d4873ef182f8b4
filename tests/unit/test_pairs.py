"""The horizon's pairs within reach (planning/pairs.py), checked by brute force on random fleets
flying random legs that keep the horizon's rows."""

from __future__ import annotations

import functools
import itertools

import numpy as np
import pytest

from isac_mission.model.vehicle import hermite_position, velocity_control_points
from isac_mission.planning.pairs import (
    band_pair_count,
    banded_order,
    bandwidth,
    horizon_reach_m,
    pair_bands,
    pairs_within_reach,
)

V_MAX_MPS = 22.5
DT_S = 1.0
LENGTH = 5
CLEARANCE_M = 33.0


def _random_legs(
    rng: np.random.Generator, prev_xy: np.ndarray, prev_v: np.ndarray, meet_xy: np.ndarray
) -> np.ndarray:
    """Positions [LENGTH, 40, M, 2] at 40 instants of every leg of a random plan that keeps the
    step rows (|q_h - q_h-1| <= V_max dt) and the velocity rows (the leg's middle and end
    velocity control points within V_max), the UAVs heading for meet_xy [2] at near full speed
    (so that pairs close in)."""
    fracs = np.linspace(0.0, 1.0, 40)
    out = np.empty((LENGTH, len(fracs), len(prev_xy), 2))
    for m in range(len(prev_xy)):
        q0, v0 = prev_xy[m].copy(), prev_v[m].copy()
        for h in range(LENGTH):
            for _ in range(200):
                heading = meet_xy - q0
                heading = heading / max(float(np.linalg.norm(heading)), 1e-9)
                v1 = V_MAX_MPS * rng.uniform(0.6, 1.0) * heading + rng.normal(0, 1, 2)
                q1 = q0 + DT_S * (v0 + v1) / 2 + rng.normal(0, 0.5, 2)
                _, mid, end = velocity_control_points(q0, v0, q1, v1, DT_S)
                ok_speed = max(np.linalg.norm(mid), np.linalg.norm(end)) <= V_MAX_MPS
                if ok_speed and np.linalg.norm(q1 - q0) <= V_MAX_MPS * DT_S:
                    break
            else:  # a slow leg straight on keeps every row
                v1 = -0.2 * v0
                q1 = q0 + DT_S * (v0 + v1) / 2
            out[h, :, m] = [hermite_position(q0, v0, q1, v1, DT_S, f) for f in fracs]
            q0, v0 = q1, v1
    return out


@functools.cache
def _checked_draw(seed: int) -> tuple[int, int]:
    """One draw: a fleet of 6-16 UAVs around a meeting point, heading there; asserts that every
    pair that comes within the rows' distance somewhere on its legs is within reach and within
    the order's bandwidth. Returns (the pairs that came that close, the pairs dropped)."""
    rng = np.random.default_rng(seed)
    M = int(rng.integers(6, 17))
    meet_xy = rng.uniform(300, 700, 2)
    angle, radius = rng.uniform(0, 2 * np.pi, M), rng.uniform(30, 450, M)
    prev_xy = meet_xy + radius[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    prev_v = rng.normal(0, 1, size=(M, 2))
    prev_v *= (rng.uniform(0, 1.2 * V_MAX_MPS, M) / np.linalg.norm(prev_v, axis=1))[:, None]
    legs = _random_legs(rng, prev_xy, prev_v, meet_xy)

    reach = horizon_reach_m(prev_v, V_MAX_MPS, DT_S, LENGTH)
    moved = np.linalg.norm(legs - prev_xy[None, None], axis=-1).max(axis=(0, 1))
    assert np.all(moved <= reach + 1e-9), "a UAV left its reach"

    within = pairs_within_reach(prev_xy, reach, CLEARANCE_M)
    order, width = banded_order(within)
    position = np.argsort(order)
    close = 0
    for i, j in itertools.combinations(range(M), 2):
        nearest = np.linalg.norm(legs[:, :, i] - legs[:, :, j], axis=-1).min()
        if nearest < CLEARANCE_M:
            close += 1
            assert within[i, j] and abs(position[i] - position[j]) <= width, (i, j, nearest)
    return close, M * (M - 1) // 2 - int(within.sum()) // 2


SEEDS = range(12)


@pytest.mark.parametrize("seed", SEEDS)
def test_no_pair_that_could_bind_is_left_out(seed: int) -> None:
    _checked_draw(seed)


def test_the_draws_had_close_pairs_and_dropped_pairs() -> None:
    """The brute force tested something: most draws had a pair closer than the rows' distance
    and pairs out of reach."""
    drawn = [_checked_draw(seed) for seed in SEEDS]
    assert sum(close > 0 and dropped > 0 for close, dropped in drawn) >= 9, drawn


def test_the_reach_is_the_bound_on_a_leg_at_the_limits() -> None:
    """A UAV flying straight at V_max (and one starting faster) reaches its bound: the bound is
    not loose where it matters."""
    prev_v = np.array([[V_MAX_MPS, 0.0], [1.2 * V_MAX_MPS, 0.0]])
    reach = horizon_reach_m(prev_v, V_MAX_MPS, DT_S, LENGTH)
    np.testing.assert_allclose(reach, [5 * V_MAX_MPS, 5.2 * V_MAX_MPS])


def test_banded_order_reports_its_bandwidth_and_finds_a_hidden_chain() -> None:
    rng = np.random.default_rng(3)
    M = 15
    chain = rng.permutation(M)
    within = np.zeros((M, M), dtype=bool)
    for a, b in itertools.pairwise(chain):
        within[a, b] = within[b, a] = True
    order, width = banded_order(within)
    assert sorted(order.tolist()) == list(range(M))
    assert width == bandwidth(within, order) == 1
    assert banded_order(np.zeros((M, M), dtype=bool))[1] == 0


def test_band_sizes_and_the_bands_a_fleet_gets() -> None:
    for n in range(1, 30):
        for band in range(1, n + 2):
            brute = sum(1 for a, b in itertools.combinations(range(n), 2) if b - a <= band)
            assert band_pair_count(n, band) == brute
    assert pair_bands(3, 4) == (2,) and pair_bands(9, 4) == (8,)
    assert pair_bands(12, 4) == (4, 11) and pair_bands(24, 4) == (4, 8)
