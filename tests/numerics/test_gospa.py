"""GOSPA (tracking/gospa.py) against a brute-force enumeration of every assignment, against a direct
computation on small hand cases, and against Stone Soup's GOSPAMetric on random sets."""

from __future__ import annotations

import datetime
import itertools

import numpy as np
import pytest
from stonesoup.metricgenerator.ospametric import GOSPAMetric
from stonesoup.types.state import State

from isac_mission.tracking.gospa import UNASSIGNED, gospa, mission_gospa


def brute_force_gospa_p(x: np.ndarray, y: np.ndarray, c: float, p: float, alpha: float) -> float:
    """GOSPA^p by its definition over every partial assignment (any number of pairs, each pair at
    d^p, every point left out at c^p / alpha): the min over all of them."""
    n, m = len(x), len(y)
    best = c**p / alpha * (n + m)
    for k in range(1, min(n, m) + 1):
        for rows in itertools.combinations(range(n), k):
            for cols in itertools.permutations(range(m), k):
                cost = sum(
                    np.linalg.norm(x[i] - y[j]) ** p for i, j in zip(rows, cols, strict=True)
                )
                best = min(best, cost + c**p / alpha * (n + m - 2 * k))
    return float(best)


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_gospa_equals_brute_force_at_alpha_two(rng: np.random.Generator, p: float) -> None:
    c = 10.0
    for _ in range(150):
        x = rng.uniform(0, 25, (rng.integers(0, 5), 2))
        y = rng.uniform(0, 25, (rng.integers(0, 5), 2))
        g = gospa(x, y, c=c, p=p)
        want = brute_force_gospa_p(x, y, c, p, 2.0)
        assert g.distance**p == pytest.approx(want, rel=1e-9, abs=1e-9)
        assert g.localisation + g.missed + g.false == pytest.approx(want, rel=1e-9, abs=1e-9)
        # the parts: counts and the assignment agree with each other
        assert g.n_missed == len(x) - int(np.sum(g.assignment != UNASSIGNED))
        assert g.missed == pytest.approx(c**p / 2 * g.n_missed)
        assert g.false == pytest.approx(c**p / 2 * g.n_false)
        assigned = g.assignment[g.assignment != UNASSIGNED]
        assert len(set(assigned.tolist())) == len(assigned)
        d = np.linalg.norm(x[g.assignment != UNASSIGNED] - y[assigned], axis=-1)
        assert np.all(d < c)
        assert g.localisation == pytest.approx(float(np.sum(d**p)))


def definition_gospa_p(x: np.ndarray, y: np.ndarray, c: float, p: float, alpha: float) -> float:
    """GOSPA^p by its definition for any alpha: the smaller set assigned whole, in every way, at
    min(d, c)^p a pair, plus c^p / alpha per point of the larger set left over."""
    small, large = (x, y) if len(x) <= len(y) else (y, x)
    leftover = c**p / alpha * (len(large) - len(small))
    if len(small) == 0:
        return float(leftover)
    pairs = [
        sum(min(float(np.linalg.norm(small[i] - large[j])), c) ** p for i, j in enumerate(perm))
        for perm in itertools.permutations(range(len(large)), len(small))
    ]
    return float(leftover + min(pairs))


@pytest.mark.parametrize("alpha", [0.5, 1.0, 2.0])
def test_gospa_distance_is_the_definition_at_any_alpha(
    rng: np.random.Generator, alpha: float
) -> None:
    for _ in range(60):
        x = rng.uniform(0, 25, (rng.integers(0, 5), 2))
        y = rng.uniform(0, 25, (rng.integers(0, 5), 2))
        g = gospa(x, y, c=10.0, p=2.0, alpha=alpha)
        want = definition_gospa_p(x, y, 10.0, 2.0, alpha)
        assert g.distance**2 == pytest.approx(want, rel=1e-9, abs=1e-9)
        if alpha != 2:
            assert np.isnan(g.localisation) and g.n_missed == -1


def test_gospa_hand_cases() -> None:
    truth = np.array([[0.0, 0.0], [100.0, 0.0]])
    # one estimate 3-4-5 from the first target, one false estimate far away, the second missed
    est = np.array([[3.0, 4.0], [500.0, 500.0]])
    g = gospa(truth, est, c=10.0, p=2.0)
    assert g.localisation == pytest.approx(25.0)
    assert (g.n_missed, g.n_false) == (1, 1)
    assert g.missed == pytest.approx(50.0) and g.false == pytest.approx(50.0)
    assert g.distance == pytest.approx(np.sqrt(125.0))
    assert g.assignment.tolist() == [0, UNASSIGNED]
    assert gospa(truth, truth).distance == 0.0
    assert gospa(np.zeros((0, 2)), est).distance == pytest.approx(np.sqrt(100.0))
    assert gospa(truth, np.zeros((0, 2))).n_missed == 2
    _, mean = mission_gospa([truth, truth], [truth, est])
    assert mean == pytest.approx(np.sqrt(125.0) / 2)


def test_gospa_rejects_bad_parameters() -> None:
    pts = np.zeros((1, 2))
    with pytest.raises(ValueError, match="cut-off"):
        gospa(pts, pts, c=0.0)
    with pytest.raises(ValueError, match="order p"):
        gospa(pts, pts, p=0.5)
    with pytest.raises(ValueError, match="alpha"):
        gospa(pts, pts, alpha=3.0)
    with pytest.raises(ValueError, match="coordinates"):
        gospa(pts, np.zeros((1, 3)))
    with pytest.raises(ValueError, match="slots"):
        mission_gospa([pts], [])


def test_gospa_equals_stone_soups(rng: np.random.Generator) -> None:
    metric = GOSPAMetric(c=10.0, p=2.0)  # its alpha is 2
    now = datetime.datetime(2026, 1, 1)
    for _ in range(100):
        x = rng.uniform(0, 30, (rng.integers(0, 6), 2))
        y = rng.uniform(0, 30, (rng.integers(1, 6), 2))  # Stone Soup needs one state's time
        theirs, _ = metric.compute_gospa_metric(
            [State(v.reshape(2, 1), timestamp=now) for v in y],
            [State(v.reshape(2, 1), timestamp=now) for v in x],
        )
        mine = gospa(x, y, c=10.0, p=2.0)
        parts = theirs.value
        assert mine.distance == pytest.approx(parts["distance"], rel=1e-9, abs=1e-9)
        assert mine.localisation == pytest.approx(parts["localisation"], rel=1e-9, abs=1e-9)
        assert mine.missed == pytest.approx(parts["missed"], rel=1e-9, abs=1e-9)
        assert mine.false == pytest.approx(parts["false"], rel=1e-9, abs=1e-9)
