"""The bound with misses and clutter (tracking/origin_uncertainty.py), checked independently:

- q against the Fisher information of a cluttered, gated report about the 4-vector state, by
  Monte Carlo in un-whitened coordinates with an anisotropic R, the score taken by finite
  differences of the report's exact log-likelihood (not by the beta formula);
- q against a direct Monte Carlo of its definition E|sum_j beta_j nu_j|^2 / 2 (whitened), and
  the fast quadrature against scipy's adaptive quadrature of the same integral, off any grid;
- the exact cases (no clutter: q = P_d; with P_d = 1 the bound step is today's, bit for bit),
  the limits, monotonicity in lambda_w and P_d, speed;
- the clutter density against the simulator's false alarms (model/detections.py);
- a PDA filter (tracking/association.py) in clutter: its position MSE stays above the bound.
"""

from __future__ import annotations

import math
import timeit
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate
from scipy.stats import chi2, ncx2

from isac_mission.config import Scenario, load_scenario
from isac_mission.model.detections import unlabelled_detections
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.model.radar import measure, measurement_jacobian
from isac_mission.model.run_noise import draw_multi_target_noise
from isac_mission.tracking.association import (
    Hypotheses,
    gate_threshold,
    jpda,
    pda_update,
)
from isac_mission.tracking.origin_uncertainty import (
    bound_step_with_origin,
    gated_information_fraction,
    information_reduction_factor,
    measurement_information_with_origin,
    reduction_factors,
    uav_reduction_factors,
    whitened_clutter_density,
)
from isac_mission.tracking.pcrb import Bound, SensingParams, bound_step, measurement_information

ROOT = Path(__file__).resolve().parents[2]
GATE = gate_threshold(0.99)
SIGMA_D_M, SIGMA_V_MPS = 3.0, 0.2
"""The anisotropic noise of the Monte Carlo checks: R = diag(9 m^2, 0.04 m^2/s^2)."""


# --------------------------------------------------------------------------------------------
# q is the Fisher information of a cluttered report


def finite_difference_scores(
    detection_prob: float, whitened_density: float, n_reports: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(scores [n, 4], x0 [4], uav_xy [1, 2], r_diag [2]): one UAV's reports about a target at
    x0, simulated in (range m, Doppler m/s) with R = diag(sigma_d^2, sigma_v^2): the target's
    measurement with probability P_d, Poisson clutter of density lambda = lambda_w / (sigma_d
    sigma_v) uniform over a window of +-10 sigma (~7 times the gate's area), then the gate
    (z - h(x0))^T R^-1 (z - h(x0)) <= gamma applied. The score is the central difference of
    each report's exact log-likelihood about the state,

        ln p(Z | x) = ln[(1 - P_d P_G(x)) + (P_d / lambda) sum_{z_j in gate} N(z_j; h(x), R)] + c,

    P_G(x) the probability that N(h(x), R) falls in the fixed gate (a noncentral chi-square)."""
    uav = np.zeros((1, 2))
    x0 = np.array([800.0, 600.0, 12.0, -20.0])
    r = np.array([SIGMA_D_M**2, SIGMA_V_MPS**2])
    lam = whitened_density / (SIGMA_D_M * SIGMA_V_MPS)
    z0 = measure(x0, uav)
    half = 10.0 * np.sqrt(r)
    n_clutter = rng.poisson(lam * 4.0 * half[0] * half[1], n_reports)
    clutter = z0 + rng.uniform(-1.0, 1.0, (int(n_clutter.sum()), 2)) * half
    detected = rng.uniform(size=n_reports) < detection_prob
    own = z0 + rng.standard_normal((n_reports, 2)) * np.sqrt(r)
    z = np.vstack([clutter, own[detected]])
    report = np.concatenate([np.repeat(np.arange(n_reports), n_clutter), np.flatnonzero(detected)])
    inside = np.sum((z - z0) ** 2 / r, axis=1) <= GATE
    z, report = z[inside], report[inside]
    norm = 1.0 / (2.0 * math.pi * math.sqrt(float(np.prod(r))))

    def log_likelihood(x: np.ndarray) -> np.ndarray:
        mu = measure(x, uav)
        shift2 = float(np.sum((mu - z0) ** 2 / r))
        p_gate = float(ncx2.cdf(GATE, 2, shift2)) if shift2 > 0 else float(chi2.cdf(GATE, 2))
        density = norm * np.exp(-0.5 * np.sum((z - mu) ** 2 / r, axis=1))
        total = np.bincount(report, density, n_reports)
        return np.asarray(np.log((1.0 - detection_prob * p_gate) + detection_prob / lam * total))

    step = np.array([3e-3, 3e-3, 2e-4, 2e-4])  # m, m, m/s, m/s: ~1e-3 sigma of the measurement
    scores = np.empty((n_reports, 4))
    for i in range(4):
        e = np.zeros(4)
        e[i] = step[i]
        scores[:, i] = (log_likelihood(x0 + e) - log_likelihood(x0 - e)) / (2.0 * step[i])
    return scores, x0, uav, r


@pytest.mark.parametrize(
    ("detection_prob", "whitened_density", "n_reports"),
    [(0.9, 0.03, 150_000), (1.0, 0.005, 100_000), (0.6, 0.1, 80_000)],
)
def test_q_is_the_fisher_information_of_a_cluttered_report_about_the_state(
    detection_prob: float, whitened_density: float, n_reports: int
) -> None:
    """E[s s^T] of the finite-difference scores s [4] against q H^T R^-1 H, entry by entry and in
    the measurement's two directions: with P = pinv(H) [4, 2], sigma_i (P^T s)_i estimates the
    range's and the Doppler's factors separately (both q if the reduction is one scalar despite
    sigma_d / sigma_v = 15 m/(m/s)), and their product the cross term (0). Tolerances: 4.5
    Monte Carlo standard errors of each mean (std / sqrt(n)); each standard error is asserted
    small enough (< 1.2 % of q) that a q off by 5 % fails."""
    rng = np.random.default_rng(2026)
    scores, x0, uav, r = finite_difference_scores(detection_prob, whitened_density, n_reports, rng)
    q = information_reduction_factor(detection_prob, whitened_density, GATE)
    if whitened_density == 0.03:
        assert 0.3 < q < 0.9, q
    n = len(scores)
    # Both measurement directions, each in its own units' sigma.
    P = np.linalg.pinv(measurement_jacobian(x0, uav))
    directional = scores @ P * np.sqrt(r)
    parts = np.stack(
        [directional[:, 0] ** 2, directional[:, 1] ** 2, directional[:, 0] * directional[:, 1]],
        axis=1,
    )
    estimate, se = parts.mean(axis=0), parts.std(axis=0) / math.sqrt(n)
    want = np.array([q, q, 0.0])
    assert np.all(se[:2] < 0.012 * q), se
    assert np.all(np.abs(estimate - want) <= 4.5 * se), (
        f"q = {q:.5f}; Monte Carlo (range, Doppler, cross) = {estimate} +- {se}"
    )
    # The whole 4 x 4 information.
    outer = scores[:, :, None] * scores[:, None, :]
    J_mc, J_se = outer.mean(axis=0), outer.std(axis=0) / math.sqrt(n)
    J_bound = measurement_information_with_origin(x0, uav, r, np.array([q]))
    z = np.abs(J_mc - J_bound) / J_se
    assert np.all(z <= 4.5), f"max |J_mc - q H^T R^-1 H| / se = {z.max():.2f}\n{J_mc}\n{J_bound}"


# --------------------------------------------------------------------------------------------
# q against its definition and against an adaptive quadrature


def direct_q(
    detection_prob: float, whitened_density: float, gate: float, n: int, rng: np.random.Generator
) -> tuple[float, float]:
    """(mean, standard error) of |sum_j beta_j nu_j|^2 / 2 over n simulated whitened reports:
    the target's nu ~ N(0, I) kept with probability P_d if |nu|^2 <= gamma, Poisson(lambda_w pi
    gamma) clutter uniform on the disc, beta_j = l_j / ((1 - P_d P_g) + sum_k l_k) with
    l_j = P_d N(nu_j; 0, I) / lambda_w (the brief's formula, read literally)."""
    p_gate = float(chi2.cdf(gate, 2))
    counts = rng.poisson(whitened_density * math.pi * gate, n)
    width = int(counts.max()) + 1
    radius = np.sqrt(gate * rng.uniform(size=(n, width)))
    angle = rng.uniform(0.0, 2.0 * math.pi, (n, width))
    nu = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=-1)
    present = np.arange(width)[None, :] < counts[:, None]
    own = rng.standard_normal((n, 2))
    kept = (rng.uniform(size=n) < detection_prob) & (np.sum(own**2, axis=1) <= gate)
    nu[:, -1], present[:, -1] = own, kept  # column width-1 holds no clutter (width > max count)
    ratio = detection_prob * np.exp(-0.5 * np.sum(nu**2, axis=-1)) / (2 * math.pi)
    ratio = np.where(present, ratio / whitened_density, 0.0)
    beta = ratio / ((1.0 - detection_prob * p_gate) + ratio.sum(axis=1, keepdims=True))
    half_norm2 = 0.5 * np.sum(np.einsum("nk,nkd->nd", beta, nu) ** 2, axis=1)
    return float(half_norm2.mean()), float(half_norm2.std() / math.sqrt(n))


def adaptive_q(detection_prob: float, whitened_density: float, gate: float) -> float:
    """The module's integral by scipy's adaptive quadrature (nested quad, its own tolerances):
    q = (P_d/2) int A(s) exp(-2 pi lambda_w (s (1/P_d - P_g) + B(s))) ds, over t = ln s."""
    half = gate / 2.0
    p_gate = -math.expm1(-half)

    def over_u(f: Callable[[float], float]) -> float:
        return float(integrate.quad(f, 0.0, half, epsabs=1e-15, epsrel=1e-12, limit=200)[0])

    def a(s: float) -> float:
        return over_u(lambda u: 2 * u * math.exp(-2 * u - s * math.exp(-u)))

    def b(s: float) -> float:
        return over_u(lambda u: -math.expm1(-s * math.exp(-u)))

    def integrand(t: float) -> float:
        s = math.exp(t)
        exponent = -2 * math.pi * whitened_density * (s * (1 / detection_prob - p_gate) + b(s))
        return s * a(s) * math.exp(exponent)

    upper = math.log(60.0) + half  # s = 60 / (1 - P_g): A(s) < e^-60 A(0) beyond
    value = integrate.quad(integrand, -60.0, upper, epsabs=1e-14, epsrel=1e-11, limit=500)[0]
    return 0.5 * detection_prob * float(value)


def test_the_quadrature_matches_scipys_adaptive_quadrature_off_any_grid() -> None:
    """Random (P_d, lambda_w, gate) with lambda_w log-uniform in [1e-7, 1e3]: |error| < 1e-9
    (the module claims < 1e-11; the spec asks ~1e-3)."""
    rng = np.random.default_rng(11)
    errors = []
    for _ in range(8):
        pd = float(rng.uniform(0.05, 1.0))
        lam = float(10 ** rng.uniform(-7.0, 3.0))
        gate = float(chi2.ppf(rng.uniform(0.9, 0.999), 2))
        errors.append(abs(information_reduction_factor(pd, lam, gate) - adaptive_q(pd, lam, gate)))
    assert max(errors) < 1e-9, errors


@pytest.mark.parametrize(
    ("detection_prob", "whitened_density", "gate_prob"),
    [(0.83, 0.0137, 0.97), (0.97, 0.0041, 0.995), (0.55, 0.21, 0.9)],
)
def test_q_matches_a_direct_monte_carlo_of_its_definition(
    detection_prob: float, whitened_density: float, gate_prob: float
) -> None:
    """500 000 simulated whitened reports: within 4.5 standard errors, each < 1.5e-3."""
    gate = gate_threshold(gate_prob)
    mean, se = direct_q(detection_prob, whitened_density, gate, 500_000, np.random.default_rng(5))
    q = information_reduction_factor(detection_prob, whitened_density, gate)
    assert se < 1.5e-3
    assert abs(q - mean) <= 4.5 * se, f"q = {q:.5f}, Monte Carlo {mean:.5f} +- {se:.5f}"


# --------------------------------------------------------------------------------------------
# Exact cases, limits, monotonicity, speed


def test_without_clutter_q_is_p_d_exactly_and_the_bound_step_is_todays(paper: Scenario) -> None:
    assert information_reduction_factor(1.0, 0.0, GATE) == 1.0
    for pd in (0.0, 0.1, 0.5, 0.9, 0.99, 1.0):
        assert information_reduction_factor(pd, 0.0, GATE) == pd
        assert np.all(reduction_factors(pd, np.zeros(5), GATE) == pd)
    s = paper
    F, W = transition_matrix(s.dt), process_noise(s.dt, s.kappa)
    sens = SensingParams.from_scenario(s)
    uav_xy = s.uav_start_xy
    x_pred = F @ s.x0
    r_diag = sens.variances(np.linalg.norm(x_pred[:2] - uav_xy, axis=1), np.full(s.M, 1 / s.M))
    prev = Bound.from_covariance(s.P0)
    today = bound_step(prev, F, W, x_pred, uav_xy, r_diag)
    q = uav_reduction_factors(1.0, 0.0, r_diag, GATE)
    assert np.all(q == 1.0)
    for reduction in (q, None):
        step = bound_step_with_origin(prev, F, W, x_pred, uav_xy, r_diag, reduction)
        assert np.array_equal(step.J, today.J)
        assert np.array_equal(step.C, today.C)
    assert np.array_equal(
        measurement_information_with_origin(x_pred, uav_xy, r_diag, np.ones(s.M)),
        measurement_information(x_pred, uav_xy, r_diag),
    )


def test_the_reduced_information_is_the_weighted_sum_of_each_uavs(paper: Scenario) -> None:
    """sum_m q_m H_m^T R_m^-1 H_m built here from measurement_jacobian; q = 0 or NaN (and a
    non-finite variance) adds nothing; q outside [0, 1] is refused."""
    s = paper
    x = np.array([1200.0, 900.0, 8.0, -3.0])
    uav_xy = s.uav_start_xy
    r_diag = np.linspace(1.0, 4.0, 2 * s.M) ** 2
    q = np.linspace(0.0, 1.0, s.M)
    q[1] = np.nan
    H = measurement_jacobian(x, uav_xy)
    M = s.M
    want = np.zeros((4, 4))
    for m in range(M):
        if np.isfinite(q[m]):
            Hm = H[[m, M + m]]
            want += q[m] * Hm.T @ np.diag(1.0 / r_diag[[m, M + m]]) @ Hm
    got = measurement_information_with_origin(x, uav_xy, r_diag, q)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15 * np.abs(want).max())
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        measurement_information_with_origin(x, uav_xy, r_diag, np.full(M, 1.5))


def test_the_limits_of_q() -> None:
    """lambda_w -> 0+: P_d times the chi-square(4) probability of the gate (only the gated part of
    the Gaussian counts); lambda_w -> inf: q lambda_w tends to a constant (q ~ 1/lambda_w), q(inf)
    = 0; NaN propagates."""
    for pd in (0.3, 0.9, 1.0):
        for p_gate in (0.9, 0.99, 0.999):
            gate = gate_threshold(p_gate)
            limit = pd * float(chi2.cdf(gate, 4))
            assert gated_information_fraction(gate) == pytest.approx(chi2.cdf(gate, 4), abs=1e-15)
            assert information_reduction_factor(pd, 1e-12, gate) == pytest.approx(limit, abs=1e-9)
            far = [lam * information_reduction_factor(pd, lam, gate) for lam in (1e8, 1e9, 1e11)]
            assert far[1] == pytest.approx(far[0], rel=1e-6)
            assert far[2] == pytest.approx(far[1], rel=1e-6)
            assert information_reduction_factor(pd, math.inf, gate) == 0.0
    assert math.isnan(information_reduction_factor(0.9, math.nan, GATE))
    with pytest.raises(ValueError, match="lambda_w"):
        information_reduction_factor(0.9, -1.0, GATE)
    with pytest.raises(ValueError, match="gate"):
        information_reduction_factor(0.9, 0.1, 0.0)


def test_q_falls_with_clutter_and_rises_with_detection_probability() -> None:
    """On a grid of 60 lambda_w in [1e-8, 1e2] x 20 P_d in [0.05, 1] x 3 gates: strictly
    monotone in both, and 0 < q <= P_d * (the gated fraction) for lambda_w > 0."""
    lam = np.logspace(-8.0, 2.0, 60)
    pds = np.linspace(0.05, 1.0, 20)
    for p_gate in (0.9, 0.99, 0.999):
        gate = gate_threshold(p_gate)
        grid = np.array([reduction_factors(pd, lam, gate) for pd in pds])  # [P_d, lambda_w]
        assert np.all(np.diff(grid, axis=1) < 0), "q must fall as the clutter grows"
        assert np.all(np.diff(grid, axis=0) > 0), "q must rise with P_d"
        assert np.all(grid > 0)
        assert np.all(grid <= pds[:, None] * gated_information_fraction(gate) + 1e-12)


def test_the_vectorised_form_agrees_and_both_are_fast() -> None:
    """reduction_factors over [M] equals the scalar function (P_d one or per UAV); timing: the
    best of 5 repeats (robust to a loaded machine), < 50 microseconds a scalar call and < 100
    for M = 6 at once."""
    lam = np.array([0.0, 1e-9, 3e-5, 0.012, 0.4, 7.0, 1e11])
    pd = np.array([0.9, 0.8, 1.0, 0.7, 0.95, 0.5, 0.9])
    each = [
        information_reduction_factor(float(p), float(x), GATE) for p, x in zip(pd, lam, strict=True)
    ]
    np.testing.assert_allclose(reduction_factors(pd, lam, GATE), each, rtol=1e-13, atol=0)
    np.testing.assert_allclose(
        reduction_factors(0.9, lam, GATE),
        [information_reduction_factor(0.9, float(x), GATE) for x in lam],
        rtol=1e-13,
        atol=0,
    )
    information_reduction_factor(0.9, 0.01, GATE)  # the gate's nodes, once
    n = 2000
    six = np.array([1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1])

    def best_us(call: Callable[[], object]) -> float:
        return min(timeit.repeat(call, number=n, repeat=5)) / n * 1e6

    scalar_us = best_us(lambda: information_reduction_factor(0.9, 0.01, GATE))
    vector_us = best_us(lambda: reduction_factors(0.9, six, GATE))
    assert scalar_us < 50, f"{scalar_us:.1f} us a scalar call"
    assert vector_us < 100, f"{vector_us:.1f} us for six UAVs"


# --------------------------------------------------------------------------------------------
# The clutter density, against the simulator


def test_clutter_density_is_the_simulators_false_alarm_rate() -> None:
    """config/multi-target.yaml's false alarms as model/detections.py draws them (no target in
    the scene): the count in a box inside the window, over 20 runs x 60 slots x 6 UAVs, is
    lambda * box area * reports within 4.5 Poisson standard deviations."""
    s = load_scenario(ROOT / "config" / "multi-target.yaml")
    d = s.detection
    assert d is not None
    lam = d.clutter_density
    assert lam == pytest.approx(2.0 / (math.hypot(math.hypot(3000, 3000), 100) * 120), rel=1e-12)
    sens = SensingParams.from_scenario(s)
    no_target = np.full((len(s.targets), 4), np.nan)
    gains = np.full(len(s.targets), s.radar_gain)
    eta = np.full(s.M, 1.0 / s.M)
    box_r, box_v = (1000.0, 2500.0), (-20.0, 35.0)
    count, reports = 0, 0
    for run in range(20):
        for draws in draw_multi_target_noise(s, 900 + run).slots:
            for rep in unlabelled_detections(no_target, gains, s.uav_start_xy, eta, sens, d, draws):
                z = rep.measurements
                count += int(
                    np.sum(
                        (z[:, 0] >= box_r[0])
                        & (z[:, 0] < box_r[1])
                        & (z[:, 1] >= box_v[0])
                        & (z[:, 1] < box_v[1])
                    )
                )
                reports += 1
    expected = lam * (box_r[1] - box_r[0]) * (box_v[1] - box_v[0]) * reports
    assert abs(count - expected) <= 4.5 * math.sqrt(expected), (count, expected)
    r_diag = np.array([4.0, 16.0, 0.01, 0.09])
    np.testing.assert_allclose(
        whitened_clutter_density(lam, r_diag), [lam * 2 * 0.1, lam * 4 * 0.3], rtol=1e-15
    )


# --------------------------------------------------------------------------------------------
# A filter in clutter stays above the bound


def test_a_pda_filter_in_clutter_stays_above_the_bound() -> None:
    """Three fixed UAVs, range-Doppler reports with R = diag(9, 0.04), P_d = 0.9 and clutter of
    lambda_w = 0.01 (q = 0.72 at P_g = 0.999) uniform over +-100 m x +-10 m/s about the truth
    (the filter's gate lies well inside), 200 runs of 6 slots from x0 ~ N(m0, P0): an EKF-PDA,
    each UAV's report in turn (`Hypotheses`, `jpda` with one track, `pda_update`). Its
    position MSE must not fall below the IRF bound's tr(C_pos) at any slot (the bound along
    the noise-free trajectory, `bound_step_with_origin`); the ratios are in the message (1.5 at
    slot 1 rising to ~11 at slot 6 here, as a few runs lose the target: the PDA is far from
    efficient in this clutter; with lambda_w ~ 0 the same filter sits at the bound, ratio
    0.95-1.05 within its Monte Carlo error)."""
    rng = np.random.default_rng(77)
    pd, lam_w, p_gate = 0.9, 0.01, 0.999
    gate = gate_threshold(p_gate)
    F, W = transition_matrix(1.0), process_noise(1.0, 0.5)
    uav = np.array([[0.0, 0.0], [1400.0, 100.0], [700.0, 1500.0]])
    m0 = np.array([700.0, 600.0, 10.0, 5.0])
    P0 = np.diag([9.0, 9.0, 0.25, 0.25])
    R = np.diag([SIGMA_D_M**2, SIGMA_V_MPS**2])
    r_diag = np.array([SIGMA_D_M**2] * 3 + [SIGMA_V_MPS**2] * 3)
    lam = lam_w / (SIGMA_D_M * SIGMA_V_MPS)
    half = np.array([100.0, 10.0])
    runs, slots = 200, 6
    q = uav_reduction_factors(pd, lam, r_diag, gate)
    np.testing.assert_allclose(q, information_reduction_factor(pd, lam_w, gate), rtol=1e-12)
    bound, plain = Bound.from_covariance(P0), Bound.from_covariance(P0)
    x = m0.copy()
    c_pos, c_plain = np.empty(slots), np.empty(slots)
    for n in range(slots):
        x = F @ x
        bound = bound_step_with_origin(bound, F, W, x, uav, r_diag, q)
        plain = bound_step(plain, F, W, x, uav, r_diag)
        c_pos[n], c_plain[n] = bound.position_trace, plain.position_trace
    sq_err = np.empty((runs, slots))
    for r in range(runs):
        x = m0 + rng.multivariate_normal(np.zeros(4), P0)
        x_hat, P = m0.copy(), P0.copy()
        for n in range(slots):
            x = F @ x + rng.multivariate_normal(np.zeros(4), W)
            x_hat, P = F @ x_hat, F @ P @ F.T + W
            for m in range(3):
                z_true = measure(x, uav[m : m + 1])
                z = z_true + rng.uniform(-1, 1, (rng.poisson(lam * 4 * half.prod()), 2)) * half
                if rng.uniform() < pd:
                    z = np.vstack([z, z_true + rng.standard_normal(2) * np.sqrt(np.diag(R))])
                z_hat = measure(x_hat, uav[m : m + 1])
                H = measurement_jacobian(x_hat, uav[m : m + 1])
                S = H @ P @ H.T + R
                h = Hypotheses.of(z_hat[None], S[None], z, pd, lam, gate, p_gate)
                x_hat, P = pda_update(x_hat, P, z_hat, H, S, z, jpda(h)[0])
            sq_err[r, n] = np.sum((x_hat[:2] - x[:2]) ** 2)
    mse = sq_err.mean(axis=0)
    ratio = mse / c_pos
    message = (
        f"PDA position MSE / IRF bound per slot {np.round(ratio, 2)}; / clutter-free bound "
        f"{np.round(mse / c_plain, 2)}; relative standard error of the MSE "
        f"{np.round(sq_err.std(axis=0) / math.sqrt(runs) / mse, 2)}"
    )
    assert np.all(c_pos > c_plain), message
    assert np.all(ratio >= 1.0), message
