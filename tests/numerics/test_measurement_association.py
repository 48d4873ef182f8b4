"""Association (tracking/association.py) against brute force: every joint event enumerated for
GNN's heaviest event and JPDA's marginals on random small cases; the likelihood ratios against
scipy's Gaussian density; the gate's probability by Monte Carlo; the PDA update against the
mixture's moments computed directly."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from isac_mission.tracking.association import (
    MISSED,
    Hypotheses,
    clusters,
    gate_threshold,
    gnn,
    jpda,
    pda_update,
)

PD, LAMBDA, PG = 0.9, 1e-4, 0.99


def random_case(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    T, k = int(rng.integers(0, 5)), int(rng.integers(0, 6))
    z_hat = rng.uniform(0, 40, (T, 2))
    A = rng.normal(size=(T, 2, 2))
    S = np.einsum("tij,tkj->tik", A, A) * 4 + np.eye(2) * 2
    z = np.vstack(
        [
            z_hat[: min(T, k)] + rng.normal(0, 2, (min(T, k), 2)),
            rng.uniform(0, 40, (max(k - T, 0), 2)),
        ]
    )
    return z_hat, S, rng.permutation(z)


def events(T: int, k: int) -> list[tuple[int, ...]]:
    """Every joint event: a measurement index (or MISSED) per track, no measurement twice."""
    out = []
    for choice in itertools.product([MISSED, *range(k)], repeat=T):
        used = [c for c in choice if c != MISSED]
        if len(used) == len(set(used)):
            out.append(choice)
    return out


def weight(h: Hypotheses, event: tuple[int, ...]) -> float:
    w = 1.0
    for i, j in enumerate(event):
        w *= h.miss_weight if j == MISSED else h.likelihood_ratio[i, j]
    return w


def test_gnn_is_the_heaviest_joint_event_and_jpda_its_marginals(rng: np.random.Generator) -> None:
    gamma = gate_threshold(PG)
    for _ in range(200):
        z_hat, S, z = random_case(rng)
        h = Hypotheses.of(z_hat, S, z, PD, LAMBDA, gamma, PG)
        T, k = h.likelihood_ratio.shape
        all_events = events(T, k)
        weights = np.array([weight(h, e) for e in all_events])
        best = all_events[int(np.argmax(weights))]
        assert weight(h, tuple(gnn(h).tolist())) == pytest.approx(weights.max(), rel=1e-9)
        assert tuple(gnn(h).tolist()) == best or weights.max() == 0
        beta = jpda(h)
        want = np.zeros((T, k + 1))
        for e, w in zip(all_events, weights, strict=True):
            for i, j in enumerate(e):
                want[i, k if j == MISSED else j] += w
        want /= weights.sum()
        np.testing.assert_allclose(beta, want, atol=1e-12)
        np.testing.assert_allclose(beta.sum(axis=1), 1.0)


def test_likelihood_ratios_are_the_gaussian_densitys(rng: np.random.Generator) -> None:
    z_hat, S, z = (
        np.array([[10.0, 1.0], [30.0, -2.0]]),
        np.array([np.eye(2) * 4, [[9.0, 2.0], [2.0, 1.0]]]),
        rng.normal(20, 10, (6, 2)),
    )
    gamma = 1e9  # no gate here
    h = Hypotheses.of(z_hat, S, z, PD, LAMBDA, gamma, 1.0)
    for i in range(2):
        pdf = multivariate_normal(z_hat[i], S[i]).pdf(z)
        np.testing.assert_allclose(h.likelihood_ratio[i], PD * pdf / LAMBDA, rtol=1e-12)
    assert h.miss_weight == pytest.approx(1 - PD)


def test_the_gate_holds_its_probability(rng: np.random.Generator) -> None:
    S = np.array([[9.0, 2.0], [2.0, 1.0]])
    draws = rng.multivariate_normal(np.zeros(2), S, size=100000)
    gamma = gate_threshold(PG)
    h = Hypotheses.of(np.zeros((1, 2)), S[None], draws, PD, LAMBDA, gamma, PG)
    assert h.gated.mean() == pytest.approx(PG, abs=5 * np.sqrt(PG * (1 - PG) / 100000))


def test_clusters_partition_the_gated_tracks(rng: np.random.Generator) -> None:
    for _ in range(100):
        gated = rng.uniform(size=(int(rng.integers(1, 6)), int(rng.integers(0, 7)))) < 0.25
        groups = clusters(gated)
        tracks = np.concatenate([t for t, _ in groups])
        assert sorted(tracks.tolist()) == list(range(gated.shape[0]))
        for t, m in groups:
            outside = np.setdiff1d(np.arange(gated.shape[1]), m)
            assert not gated[np.ix_(t, outside)].any()  # nothing gated leaves its cluster


def test_gnn_leaves_a_track_without_a_plausible_measurement_missed() -> None:
    h = Hypotheses.of(
        np.zeros((1, 2)), np.eye(2)[None], np.array([[50.0, 50.0]]), PD, LAMBDA, 9.21, PG
    )
    assert gnn(h).tolist() == [MISSED]
    assert jpda(h)[0].tolist() == [0.0, 1.0]


def test_the_pda_update_is_the_mixtures_moments(rng: np.random.Generator) -> None:
    n, d = 4, 2
    A = rng.normal(size=(n, n))
    P = A @ A.T + np.eye(n)
    x = rng.normal(size=n)
    H = rng.normal(size=(d, n))
    R = np.diag([2.0, 0.5])
    S = H @ P @ H.T + R
    z_hat = H @ x
    z = z_hat + rng.normal(size=(3, d))
    K = P @ H.T @ np.linalg.inv(S)
    P_c = (np.eye(n) - K @ H) @ P
    # one-hot: the EKF update with that measurement, or the prediction
    for j in range(3):
        beta = np.eye(4)[j]
        xj, Pj = pda_update(x, P, z_hat, H, S, z, beta)
        np.testing.assert_allclose(xj, x + K @ (z[j] - z_hat), atol=1e-12)
        np.testing.assert_allclose(Pj, P_c, atol=1e-12)
    x0, P0 = pda_update(x, P, z_hat, H, S, z, np.eye(4)[3])
    np.testing.assert_allclose(x0, x)
    np.testing.assert_allclose(P0, P, atol=1e-12)
    # any beta: the mixture of the components' Gaussians
    beta = rng.dirichlet(np.ones(4))
    means = [x + K @ (z[j] - z_hat) for j in range(3)] + [x]
    covs = [P_c] * 3 + [P]
    mean = sum(b * m for b, m in zip(beta, means, strict=True))
    cov = sum(
        b * (c + np.outer(m - mean, m - mean)) for b, m, c in zip(beta, means, covs, strict=True)
    )
    xm, Pm = pda_update(x, P, z_hat, H, S, z, beta)
    np.testing.assert_allclose(xm, mean, atol=1e-12)
    np.testing.assert_allclose(Pm, cov, atol=1e-10)
