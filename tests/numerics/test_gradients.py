"""Analytic Jacobian and PCRB gradients against central finite differences (relative error < 1e-5)."""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.model.radar import measure, measurement_jacobian
from isac_mission.tracking.pcrb import Bound, PlanningObjective, SensingParams, predict_information


def _random_case(
    s: Scenario, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = np.array([rng.uniform(500, 2500), rng.uniform(500, 2500), *rng.normal(0, 20, 2)])
    q = x[None, :2] + rng.uniform(80, 900, (s.M, 1)) * np.stack(
        [np.cos(a := rng.uniform(0, 2 * np.pi, s.M)), np.sin(a)], axis=1
    )
    eta = rng.dirichlet(np.ones(s.M)) * 0.8 + 0.2 / s.M
    return x, q, eta


def _rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("case", range(5))
def test_measurement_jacobian_matches_finite_differences(paper: Scenario, case: int) -> None:
    x, q, _ = _random_case(paper, np.random.default_rng(case))
    H = measurement_jacobian(x, q)
    fd = np.empty_like(H)
    for i in range(4):
        h = 1e-5 * max(1.0, abs(x[i]))
        e = np.zeros(4)
        e[i] = h
        fd[:, i] = (measure(x + e, q) - measure(x - e, q)) / (2 * h)
    assert _rel_err(H, fd) < 1e-5


@pytest.mark.parametrize("measurement_only", [False, True])
@pytest.mark.parametrize("case", range(4))
def test_objective_gradients_match_finite_differences(
    paper: Scenario, case: int, measurement_only: bool
) -> None:
    rng = np.random.default_rng(100 + case)
    x, q, eta = _random_case(paper, rng)
    F, W = transition_matrix(paper.dt), process_noise(paper.dt, paper.kappa)
    prior = predict_information(Bound.from_covariance(paper.P0 * rng.uniform(0.05, 2)), F, W)
    obj = PlanningObjective(prior, x, SensingParams.from_scenario(paper), measurement_only)
    f, grad_q, grad_eta = obj.value_and_gradients(q, eta)
    assert f == pytest.approx(obj.value(q, eta), rel=1e-12)
    fd_q = np.empty_like(q)
    for m in range(paper.M):
        for j in range(2):
            e = np.zeros_like(q)
            e[m, j] = 1e-2
            fd_q[m, j] = (obj.value(q + e, eta) - obj.value(q - e, eta)) / 2e-2
    fd_eta = np.array(
        [
            (
                obj.value(q, eta + 1e-5 * np.eye(paper.M)[m])
                - obj.value(q, eta - 1e-5 * np.eye(paper.M)[m])
            )
            / 2e-5
            for m in range(paper.M)
        ]
    )
    assert _rel_err(grad_q, fd_q) < 1e-5
    assert _rel_err(grad_eta, fd_eta) < 1e-5


def test_literal_model_gradients_match_finite_differences(paper_literal: Scenario) -> None:
    """The literal eq. 8 model mixes information of order 1e20 and 1: the scaled inverse must hold."""
    rng = np.random.default_rng(7)
    x, q, eta = _random_case(paper_literal, rng)
    F, W = transition_matrix(1.0), process_noise(1.0, paper_literal.kappa)
    prior = predict_information(Bound.from_covariance(paper_literal.P0), F, W)
    obj = PlanningObjective(prior, x, SensingParams.from_scenario(paper_literal))
    _, grad_q, grad_eta = obj.value_and_gradients(q, eta)
    fd_q = np.empty_like(q)
    for m in range(paper_literal.M):
        for j in range(2):
            e = np.zeros_like(q)
            e[m, j] = 1e-2
            fd_q[m, j] = (obj.value(q + e, eta) - obj.value(q - e, eta)) / 2e-2
    assert _rel_err(grad_q, fd_q) < 1e-5
    assert np.all(np.isfinite(grad_eta))


def test_batched_objective_equals_single_evaluations(paper: Scenario) -> None:
    rng = np.random.default_rng(3)
    x, q, _ = _random_case(paper, rng)
    obj = PlanningObjective(np.linalg.inv(paper.P0), x, SensingParams.from_scenario(paper))
    qs = q[None] + rng.normal(0, 30, (6, paper.M, 2))
    etas = rng.dirichlet(np.ones(paper.M), 6)
    batch = obj.values(qs, etas)
    single = np.array([obj.value(qs[i], etas[i]) for i in range(6)])
    np.testing.assert_allclose(batch, single, rtol=1e-10)
