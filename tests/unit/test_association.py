"""Association (P1-F.1): LP + rounding against brute force over every assignment."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from isac_mission.planning.association import (
    AssociationLP,
    optimal_assignment,
    round_association,
)


def _brute_force(costs: np.ndarray, capacity: int) -> float:
    M, K = costs.shape
    best = np.inf
    for choice in itertools.product(range(K), repeat=M):
        if np.bincount(choice, minlength=K).max() <= capacity:
            best = min(best, sum(costs[m, k] for m, k in enumerate(choice)))
    return best


@settings(max_examples=40, deadline=None)
@given(
    M=st.integers(1, 5),
    K=st.integers(1, 4),
    capacity=st.integers(1, 3),
    seed=st.integers(0, 10_000),
)
def test_lp_rounding_is_the_integral_optimum_under_capacity(
    M: int, K: int, capacity: int, seed: int
) -> None:
    if M > K * capacity:
        return
    costs = np.random.default_rng(seed).uniform(1.0, 10.0, (M, K))
    relaxed = AssociationLP(M, K, capacity).solve(costs)
    assert relaxed is not None
    chosen = round_association(relaxed, costs, capacity)
    assert np.bincount(chosen, minlength=K).max() <= capacity
    assert costs[np.arange(M), chosen].sum() == pytest.approx(
        _brute_force(costs, capacity), rel=1e-9
    )


def test_argmax_rounding_on_ties_is_repaired_to_respect_capacity() -> None:
    # Three UAVs equally happy with either BS, capacity 2: a half-half LP answer rounds by
    # argmax to BS 0 for all three, which breaks N_a; the repair must not.
    costs = np.ones((3, 2))
    relaxed = np.full((3, 2), 0.5)
    naive = np.argmax(relaxed, axis=1)
    assert np.bincount(naive).max() == 3
    chosen = round_association(relaxed, costs, capacity=2)
    assert np.bincount(chosen, minlength=2).max() <= 2


def test_optimal_assignment_prefers_cheaper_bs() -> None:
    costs = np.array([[1.0, 5.0], [1.0, 2.0], [1.0, 9.0]])
    chosen = optimal_assignment(costs, capacity=2)
    assert chosen.tolist() == [0, 1, 0]
