"""The IMM filter core (tracking/imm.py): the coordinated turn's Jacobian against central
differences and against model/targets.coordinated_turn_matrix; one mixing step computed by hand;
the mode probabilities and the turn rate on a scripted manoeuvre; a one-mode IMM against the EKF
(tracking/ekf.py); the likelihoods against the batch Gaussian density; the PDA update against the
labelled one; NEES by Monte Carlo on targets that follow the model's own Markov chain; the
stationary distribution, the mixed kappa and the model's validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from isac_mission.config.sections import ImmModeSpec, ImmSpec
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.model.motion import ct_jacobian, ct_transition, stationary_probabilities
from isac_mission.model.radar import measure, measurement_jacobian
from isac_mission.model.targets import coordinated_turn_matrix
from isac_mission.tracking.ekf import ekf_predict, ekf_update
from isac_mission.tracking.imm import (
    ImmBelief,
    ImmMode,
    ImmModel,
    imm_model,
    imm_predict,
    imm_start,
    imm_update,
    mix,
    mixed_kappa,
    mode_pda_updates,
    mode_updates,
    with_likelihoods,
)
from isac_mission.types import Gaussian

EPS = float(np.finfo(float).eps)
SENSORS = np.array([[300.0, -400.0], [800.0, 300.0], [0.0, 600.0], [-400.0, 0.0]])
"""Four fixed sensors 300-700 m from the targets' paths (m)."""
R_DIAG = np.r_[np.full(4, 1.0**2), np.full(4, 0.3**2)]
"""Range std 1 m, Doppler std 0.3 m/s."""


def two_mode_model(
    kappa_cv: float = 0.05,
    kappa_ct: float = 0.05,
    turn_noise: float = 0.004,
    switching: tuple[tuple[float, float], tuple[float, float]] = ((0.9, 0.1), (0.1, 0.9)),
) -> ImmModel:
    return ImmModel(
        modes=(ImmMode("cv", kappa_cv), ImmMode("ct", kappa_ct, turn_noise)),
        switching=np.array(switching),
        dt_s=1.0,
        initial_probabilities=np.array([0.5, 0.5]),
        initial_turn_rate_std_radps=0.1,
    )


# 1. The coordinated turn.


@pytest.mark.parametrize("omega", [0.0, 1e-9, -1e-9, 0.05, 0.3, -0.3, 1.2])
@pytest.mark.parametrize("dt", [1.0, 2.0])
def test_ct_jacobian_matches_central_differences(omega: float, dt: float) -> None:
    x = np.array([120.0, -40.0, 17.0, -9.0, omega])
    F = ct_jacobian(x, dt)
    num = np.empty((5, 5))
    for k in range(5):
        h = 1e-6 * max(1.0, abs(x[k])) if k < 4 else 1e-6
        e = np.zeros(5)
        e[k] = h
        num[:, k] = (ct_transition(x + e, dt) - ct_transition(x - e, dt)) / (2 * h)
    # Central differences: rounding |f| eps / h (|f| <= ~200, h >= 1e-6: ~5e-8) plus the
    # truncation h^2 |f'''| / 6 (|f'''| <= |v| dt^4 <= 320: ~5e-11).
    np.testing.assert_allclose(F, num, rtol=0, atol=1e-7)


def test_ct_jacobian_is_continuous_across_the_series_switch() -> None:
    # |omega dt| = 0.1 is where the Taylor series hands over to sin/cos: the two sides agree to
    # the series' truncation (< 1e-17) plus the closed form's cancellation (~eps / 0.1^2).
    below = ct_jacobian(np.array([0.0, 0.0, 17.0, -9.0, 0.1 * (1 - 1e-12)]), 1.0)
    above = ct_jacobian(np.array([0.0, 0.0, 17.0, -9.0, 0.1 * (1 + 1e-12)]), 1.0)
    np.testing.assert_allclose(below, above, rtol=0, atol=1e-11 * 20)


def test_ct_at_zero_turn_rate_is_constant_velocity() -> None:
    x = np.array([120.0, -40.0, 17.0, -9.0, 0.0])
    np.testing.assert_allclose(ct_transition(x, 1.5)[:4], transition_matrix(1.5) @ x[:4], atol=0)
    F = ct_jacobian(x, 1.5)
    np.testing.assert_allclose(F[:4, :4], transition_matrix(1.5), atol=0)
    # d/domega at omega = 0: the arc bends the position by (-vy, vx) dt^2 / 2, the velocity by
    # (-vy, vx) dt.
    np.testing.assert_allclose(F[:4, 4], [9.0 * 1.125, 17.0 * 1.125, 9.0 * 1.5, 17.0 * 1.5])


@pytest.mark.parametrize("omega", [1e-6, 0.05, 0.3, -0.7])
def test_ct_transition_is_the_coordinated_turn_matrix(omega: float) -> None:
    x = np.array([120.0, -40.0, 17.0, -9.0, omega])
    want = coordinated_turn_matrix(1.0, omega) @ x[:4]
    # The reference's (1 - cos(omega dt)) / omega cancels: an absolute error of about
    # eps / |omega| per m/s of speed (|v| < 20 m/s); the rest is rounding of values ~100 m.
    atol = 4 * 20 * EPS / abs(omega) + 1e-12 * 200
    np.testing.assert_allclose(ct_transition(x, 1.0)[:4], want, rtol=0, atol=atol)
    assert ct_transition(x, 1.0)[4] == omega


# 2. Mixing, by hand.


def test_mixing_step_matches_hand_computation() -> None:
    model = two_mode_model(switching=((0.9, 0.1), (0.2, 0.8)))
    x1 = np.array([0.0, 0.0, 10.0, 0.0, 0.0])
    x2 = np.array([1.0, 2.0, 10.0, -1.0, 0.1])
    P1 = np.diag([4.0, 4.0, 1.0, 1.0, 0.0])
    P2 = np.diag([9.0, 9.0, 2.0, 2.0, 0.01])
    belief = ImmBelief(np.array([x1, x2]), np.array([P1, P2]), np.array([0.6, 0.4]))
    # c_1 = 0.9 * 0.6 + 0.2 * 0.4 = 0.62, c_2 = 0.1 * 0.6 + 0.8 * 0.4 = 0.38.
    c = np.array([0.62, 0.38])
    # mu_{i|j} = p_ij mu_i / c_j: into mode 1 (0.54, 0.08) / 0.62, into mode 2 (0.06, 0.32) / 0.38.
    w = {1: (0.54 / 0.62, 0.08 / 0.62), 2: (0.06 / 0.38, 0.32 / 0.38)}
    d = x2 - x1  # [1, 2, 0, -1, 0.1]
    mixed = mix(model, belief)
    np.testing.assert_allclose(mixed.probabilities, c, rtol=1e-14)
    for j in (1, 2):
        a, b = w[j]
        mean = a * x1 + b * x2
        # Two components: spread a (x1 - m)(x1 - m)^T + b (x2 - m)(...)^T = a b d d^T.
        cov = a * P1 + b * P2 + a * b * np.outer(d, d)
        np.testing.assert_allclose(mixed.means[j - 1], mean, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(mixed.covariances[j - 1], cov, rtol=1e-13, atol=1e-15)
    assert mixed.means[0, 0] == pytest.approx(0.08 / 0.62)
    # imm_predict's probabilities are the c_j; its means are the modes' steps of the mixed ones.
    pred = imm_predict(model, belief)
    np.testing.assert_allclose(pred.probabilities, c, rtol=1e-14)
    np.testing.assert_allclose(pred.means[1], ct_transition(mixed.means[1], 1.0), rtol=1e-14)
    # The belief's own moment match: 0.6 x1 + 0.4 x2 and 0.6 P1 + 0.4 P2 + 0.24 d d^T.
    g = belief.mixed()
    np.testing.assert_allclose(g.x, 0.6 * x1 + 0.4 * x2, atol=1e-15)
    np.testing.assert_allclose(g.P, 0.6 * P1 + 0.4 * P2 + 0.24 * np.outer(d, d), atol=1e-14)
    np.testing.assert_allclose(belief.marginal().P, g.P[:4, :4])


# 3. A scripted manoeuvre.


def test_turn_mode_takes_over_during_the_turn_and_tracks_its_rate() -> None:
    # Truth: 20 m/s east, straight for 20 s, a 0.2 rad/s coordinated turn for 15 s, straight 20 s.
    # Slot n's state comes from slot n - 1's by the turn at omega_n.
    omega = np.array([0.2 if 20 < n <= 35 else 0.0 for n in range(56)])
    truth = [np.array([0.0, 0.0, 20.0, 0.0])]
    for n in range(1, 56):
        truth.append(coordinated_turn_matrix(1.0, float(omega[n])) @ truth[-1])
    model = two_mode_model(
        kappa_cv=0.01, kappa_ct=0.1, turn_noise=1e-3, switching=((0.95, 0.05), (0.1, 0.9))
    )
    model = ImmModel(
        model.modes, model.switching, 1.0, np.array([0.9, 0.1]), model.initial_turn_rate_std_radps
    )
    sensors = np.array([[200.0, -300.0], [700.0, -200.0], [500.0, 600.0], [-100.0, 500.0]])
    rng = np.random.default_rng(7)
    P0 = np.diag([25.0, 25.0, 1.0, 1.0])
    belief = imm_start(model, Gaussian(truth[0] + rng.normal(0, np.sqrt(np.diag(P0))), P0))
    p_ct, omega_hat = [], []
    for n in range(56):
        if n:
            belief = imm_predict(model, belief)
        z = measure(truth[n], sensors) + rng.normal(0, np.sqrt(R_DIAG))
        belief = imm_update(belief, z, sensors, R_DIAG)
        p_ct.append(belief.probabilities[1])
        omega_hat.append(belief.mixed().x[4])
    p, w = np.array(p_ct), np.array(omega_hat)
    turn = np.arange(24, 36)  # the turn's slots 21..35 after 3 slots of lag
    straight = np.r_[3:21, 39:56]  # the straight slots, 3 slots of lag after each change
    assert np.mean(p[turn] > 0.8) >= 0.9, p[turn]
    assert np.mean(p[straight] < 0.3) >= 0.9, p[straight]
    np.testing.assert_allclose(w[28:36], 0.2, atol=0.05)


# 4. One cv mode is the EKF.


@pytest.mark.parametrize("iterations", [1, 3])
def test_single_cv_mode_equals_the_ekf(iterations: int) -> None:
    kappa = 0.7
    model = ImmModel((ImmMode("cv", kappa),), np.array([[1.0]]), 1.0, np.array([1.0]), 0.0)
    rng = np.random.default_rng(3)
    g = Gaussian(np.array([50.0, 80.0, 12.0, -4.0]), np.diag([25.0, 16.0, 2.0, 3.0]))
    belief = imm_start(model, g)
    F, W = transition_matrix(1.0), process_noise(1.0, kappa)
    x = g.x.copy()
    for n in range(12):
        x = F @ x
        g = ekf_predict(g, F, W)
        belief = imm_predict(model, belief)
        z = measure(x, SENSORS) + rng.normal(0, np.sqrt(R_DIAG))
        if n % 3 == 1:
            z[[1, 5]] = np.nan  # a missed UAV
        g = ekf_update(g, z, SENSORS, R_DIAG, iterations)
        belief = imm_update(belief, z, SENSORS, R_DIAG, iterations)
        m = belief.marginal()
        # The same operations in the same order (Joseph form); rounding accumulates only.
        np.testing.assert_allclose(m.x, g.x, rtol=1e-9)
        np.testing.assert_allclose(m.P, g.P, rtol=1e-9, atol=1e-12 * np.abs(g.P).max())
        assert np.all(belief.covariances[0, 4] == 0)


# 5. The mode likelihoods.


def test_mode_log_likelihood_is_the_batch_gaussian_density() -> None:
    rng = np.random.default_rng(5)
    A = rng.normal(size=(5, 5))
    P = A @ A.T + np.diag([20.0, 20.0, 2.0, 2.0, 0.01])
    x = np.array([100.0, 50.0, 15.0, 5.0, 0.1])
    belief = ImmBelief(
        np.array([x, x + np.array([3, -2, 0.5, 0, -0.1])]), np.array([P, 1.5 * P]), np.ones(2) / 2
    )
    r = np.r_[np.full(4, 4.0), np.full(4, 0.25)]
    z = measure(x[:4], SENSORS) + rng.normal(0, np.sqrt(r))
    z[2] = np.nan
    _, log_lik = mode_updates(belief, z, SENSORS, r)
    use = np.isfinite(z)
    for j in range(2):
        xj, Pj = belief.means[j], belief.covariances[j]
        H = np.hstack([measurement_jacobian(xj[:4], SENSORS), np.zeros((8, 1))])[use]
        S = H @ Pj @ H.T + np.diag(r[use])
        want = stats.multivariate_normal(measure(xj[:4], SENSORS)[use], S).logpdf(z[use])
        assert log_lik[j] == pytest.approx(want, rel=1e-9)


# 6. The PDA update.


def test_pda_update_with_one_hot_beta_is_the_labelled_update() -> None:
    pd, lam, pg = 0.9, 1e-3, 0.99
    belief = imm_start(
        two_mode_model(),
        Gaussian(np.array([100.0, 50.0, 15.0, 5.0]), np.diag([9.0, 9.0, 1.0, 1.0])),
    )
    belief = imm_predict(two_mode_model(), belief)
    uav = SENSORS[1]
    r_pair = np.array([1.0, 0.09])
    own = measure(np.array([101.0, 49.0, 15.2, 4.9]), uav[None])
    report = np.array([[400.0, 3.0], own, [120.0, -7.0]])
    beta = np.array([0.0, 1.0, 0.0, 0.0])
    pda, log_pda = mode_pda_updates(belief, report, uav, r_pair, beta, pd, lam, pg)
    labelled, log_lab = mode_updates(belief, own, uav[None], r_pair)
    # Batch (PDA, 2x2 inverse) against sequential Joseph updates: equal up to rounding.
    np.testing.assert_allclose(pda.means, labelled.means, rtol=1e-9)
    np.testing.assert_allclose(pda.covariances, labelled.covariances, rtol=1e-9, atol=1e-14)
    # The mode likelihood's measurement terms are the labelled densities (the far-away false
    # alarms add < 1e-300): log[(1 - Pd Pg) + Pd / lambda N(own)].
    want = np.logaddexp(math.log(1 - pd * pg), math.log(pd / lam) + log_lab)
    np.testing.assert_allclose(log_pda, want, rtol=1e-12)


def test_pda_update_with_no_measurement_keeps_the_prediction() -> None:
    belief = imm_start(two_mode_model(), Gaussian(np.array([100.0, 50.0, 15.0, 5.0]), np.eye(4)))
    out, log_lik = mode_pda_updates(
        belief,
        np.zeros((0, 2)),
        SENSORS[0],
        np.array([1.0, 0.09]),
        np.array([1.0]),
        0.9,
        1e-3,
        0.99,
    )
    np.testing.assert_allclose(log_lik, math.log(1 - 0.9 * 0.99), rtol=1e-15)
    np.testing.assert_allclose(out.means, belief.means)
    np.testing.assert_allclose(out.covariances, belief.covariances)


def test_mode_probabilities_are_floored_and_stable() -> None:
    belief = ImmBelief(np.zeros((2, 5)), np.zeros((2, 5, 5)), np.array([0.5, 0.5]))
    out = with_likelihoods(belief, np.array([-1e5, -1e5 - 2000.0]))
    assert out.probabilities.sum() == pytest.approx(1.0)
    assert out.probabilities[1] == pytest.approx(1e-6, rel=1e-5)
    out = with_likelihoods(belief, np.array([-1e5, -1e5 + math.log(3.0)]))
    np.testing.assert_allclose(out.probabilities, [0.25, 0.75], rtol=1e-12)


# 7. NEES by Monte Carlo.


def test_nees_is_consistent_on_the_models_own_targets() -> None:
    # 200 targets that switch by the model's own chain, step by the active mode's transition and
    # draw its noise (a ct mode entered from cv starts at omega = 0, as the mixing assumes).
    # The IMM approximates the mode-sequence mixture by one Gaussian per mode, so its NEES is
    # near, not exactly, chi-square(4): the band 2..6 around the mean 4 holds in >= 90 % of
    # slots and the grand mean within 3..5 (the exact filter's 95 % band for the mean of 200
    # chi-square(4) values is 3.62..4.41).
    model = two_mode_model()
    runs, slots = 200, 30
    rng = np.random.default_rng(1)
    P0 = np.diag([25.0, 25.0, 1.0, 1.0])
    nees = np.empty((runs, slots))
    for run in range(runs):
        x = np.array([0.0, 0.0, 15.0, 5.0, 0.0])
        m = int(rng.random() < 0.5)
        if m == 1:
            x[4] = rng.normal(0.0, model.initial_turn_rate_std_radps)
        belief = imm_start(model, Gaussian(x[:4] + rng.multivariate_normal(np.zeros(4), P0), P0))
        for n in range(slots):
            if n:
                m = int(rng.choice(2, p=model.switching[m]))
                mode = model.modes[m]
                x = mode.transition(x, 1.0)[0] + rng.multivariate_normal(
                    np.zeros(5), mode.noise(1.0)
                )
                belief = imm_predict(model, belief)
            z = measure(x[:4], SENSORS) + rng.normal(0, np.sqrt(R_DIAG))
            belief = imm_update(belief, z, SENSORS, R_DIAG)
            g = belief.marginal()
            e = x[:4] - g.x
            nees[run, n] = e @ np.linalg.solve(g.P, e)
    per_slot = nees.mean(axis=0)
    assert np.mean((per_slot > 2) & (per_slot < 6)) >= 0.9, per_slot
    assert 3 < per_slot.mean() < 5, per_slot


# 8. The chain and the bound's kappa.


def test_stationary_probabilities_are_the_limit_of_the_chain() -> None:
    p = np.array([[0.8, 0.15, 0.05], [0.1, 0.85, 0.05], [0.3, 0.2, 0.5]])
    pi = stationary_probabilities(p)
    limit = np.linalg.matrix_power(p, 500)
    np.testing.assert_allclose(pi, limit[0], rtol=1e-12)
    np.testing.assert_allclose(pi @ p, pi, rtol=1e-12)


def test_mixed_kappa_weighs_each_modes_intensity_by_its_probability() -> None:
    model = two_mode_model(kappa_cv=0.1, kappa_ct=0.4, switching=((0.9, 0.1), (0.2, 0.8)))
    assert mixed_kappa(model, np.array([0.25, 0.75])) == pytest.approx(0.325, rel=1e-12)
    assert mixed_kappa(model, np.array([1.0, 0.0])) == 0.1


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"switching": np.array([[0.9, 0.2], [0.1, 0.9]])}, "switching"),
        ({"switching": np.eye(3)}, "switching"),
        ({"dt_s": 0.0}, "dt_s"),
        ({"initial_probabilities": np.array([0.5, 0.6])}, "initial_probabilities"),
        ({"initial_turn_rate_std_radps": -1.0}, "initial_turn_rate_std_radps"),
        ({"modes": ()}, "modes"),
    ],
)
def test_model_validation_names_the_field(change: dict[str, object], field: str) -> None:
    base = two_mode_model()
    kwargs: dict[str, object] = {
        "modes": base.modes,
        "switching": base.switching,
        "dt_s": base.dt_s,
        "initial_probabilities": base.initial_probabilities,
        "initial_turn_rate_std_radps": base.initial_turn_rate_std_radps,
    }
    kwargs.update(change)
    with pytest.raises(ValueError, match=field):
        ImmModel(**kwargs)  # type: ignore[arg-type]


def test_mode_validation_names_the_field() -> None:
    with pytest.raises(ValueError, match="turn_noise_rad2ps3"):
        ImmMode("cv", 0.1, 0.01)
    with pytest.raises(ValueError, match="kappa_m2ps3"):
        ImmMode("ct", -0.1)
    with pytest.raises(ValueError, match="model"):
        ImmMode("ca", 0.1)  # type: ignore[arg-type]


def test_imm_model_from_the_scenarios_spec() -> None:
    spec = ImmSpec(
        modes=(ImmModeSpec("cv", 0.01), ImmModeSpec("ct", 0.05, 0.003)),
        switching=((0.95, 0.05), (0.05, 0.95)),
        initial_probabilities=(0.8, 0.2),
        initial_turn_rate_std_radps=0.2,
    )
    model = imm_model(spec, 0.5)
    assert model.modes == (ImmMode("cv", 0.01), ImmMode("ct", 0.05, 0.003))
    np.testing.assert_array_equal(model.switching, [[0.95, 0.05], [0.05, 0.95]])
    np.testing.assert_array_equal(model.initial_probabilities, [0.8, 0.2])
    assert (model.dt_s, model.initial_turn_rate_std_radps) == (0.5, 0.2)
