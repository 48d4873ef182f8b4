"""Interacting multiple model (IMM) filter core for a manoeuvring target seen in range and Doppler.

The target moves by one of r modes at a time; the mode is a Markov chain with switching[i, j] =
P(mode j now | mode i before). Every mode keeps a Gaussian over the common state
x5 = [x_m, y_m, vx_mps, vy_mps, omega_radps] (turn rate, positive counter-clockwise): a "cv" mode
is constant velocity and knows no turn rate (its omega is 0 +- initial_turn_rate_std, so that a
ct mode mixed from it can take up a turn that starts), a "ct" mode is the nearly coordinated turn with the turn rate in the state (Li and
Jilkov, "Survey of maneuvering target tracking, Part I", IEEE T-AES 2003, sec. V.B): the exact
constant-turn arc at the current omega, omega a random walk.

One slot (Bar-Shalom, Li and Kirubarajan, "Estimation with Applications to Tracking and
Navigation", 2001, sec. 11.6.6): (1) mixing: predicted mode probabilities c_j = sum_i p_ij mu_i,
weights mu_{i|j} = p_ij mu_i / c_j, each mode restarted from the moment-matched mixture of all
modes' posteriors; (2) each mode's EKF prediction; (3) each mode's EKF update (labelled
measurements: `mode_updates`; one UAV's unlabelled report with the caller's PDA marginals:
`mode_pda_updates`) and its measurement likelihood; (4) mode probabilities mu_j ~ c_j L_j
(`with_likelihoods`). The rest of the system reads `ImmBelief.marginal()`, the 4-D moment-matched
Gaussian. `mixed_kappa` gives the white-noise intensity of a track's bound under this model:
the modes' own, mixed by their probabilities. Pure numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, cast

import numpy as np

from isac_mission.model.motion import ConstantVelocity, ct_jacobian, ct_transition
from isac_mission.model.radar import measure, measurement_jacobian
from isac_mission.tracking.association import Hypotheses, pda_update
from isac_mission.types import BoolArray, FloatArray, Gaussian

if TYPE_CHECKING:
    from isac_mission.config.sections import ImmSpec

ModeKind = Literal["cv", "ct"]

N_STATE = 5
"""The common state's dimension: [x_m, y_m, vx_mps, vy_mps, omega_radps]."""


@dataclass(frozen=True)
class ImmMode:
    """One motion mode. kappa_m2ps3: white-acceleration intensity on x and y (m^2/s^3, as
    model/motion.ConstantVelocity); turn_noise_rad2ps3 (ct only): omega's random-walk
    intensity (rad^2/s^3), its variance grows turn_noise dt per step."""

    model: ModeKind
    kappa_m2ps3: float
    turn_noise_rad2ps3: float = 0.0

    def __post_init__(self) -> None:
        if self.model not in ("cv", "ct"):
            raise ValueError(f"ImmMode.model must be 'cv' or 'ct' (got {self.model!r})")
        if not (math.isfinite(self.kappa_m2ps3) and self.kappa_m2ps3 >= 0):
            raise ValueError(
                f"ImmMode.kappa_m2ps3 must be finite and >= 0 (got {self.kappa_m2ps3})"
            )
        t = self.turn_noise_rad2ps3
        if not (math.isfinite(t) and t >= 0):
            raise ValueError(f"ImmMode.turn_noise_rad2ps3 must be finite and >= 0 (got {t})")
        if self.model == "cv" and t != 0:
            raise ValueError(f"ImmMode.turn_noise_rad2ps3 must be 0 for a cv mode (got {t})")

    def transition(self, x: FloatArray, dt_s: float) -> tuple[FloatArray, FloatArray]:
        """(f(x) [5], F [5, 5] = df/dx at x [5]) over dt_s (s)."""
        if self.model == "ct":
            return ct_transition(x, dt_s), ct_jacobian(x, dt_s)
        F = np.zeros((N_STATE, N_STATE))
        F[:4, :4] = ConstantVelocity(0.0).transition(dt_s)
        return F @ x, F

    def noise(self, dt_s: float) -> FloatArray:
        """Q [5, 5]: the CV block of kappa on [x, y, vx, vy], turn_noise dt on omega."""
        Q = np.zeros((N_STATE, N_STATE))
        Q[:4, :4] = ConstantVelocity(self.kappa_m2ps3).process_noise(dt_s)
        Q[4, 4] = self.turn_noise_rad2ps3 * dt_s
        return Q


@dataclass(frozen=True)
class ImmModel:
    """modes (r); switching [r, r] (row i: P(mode j now | mode i before)); dt_s (s) the slot;
    initial_probabilities [r]; initial_turn_rate_std_radps: omega's std where a mode knows no
    turn rate (a new track's modes, every cv mode's prediction)."""

    modes: tuple[ImmMode, ...]
    switching: FloatArray
    dt_s: float
    initial_probabilities: FloatArray
    initial_turn_rate_std_radps: float

    def __post_init__(self) -> None:
        r = len(self.modes)
        if r == 0:
            raise ValueError("ImmModel.modes must hold at least one mode (got none)")
        p = np.asarray(self.switching, dtype=float)
        if p.shape != (r, r) or not np.all(np.isfinite(p)) or np.any(p < 0):
            raise ValueError(f"ImmModel.switching must be [{r}, {r}], finite, >= 0 (got {p})")
        if not np.allclose(p.sum(axis=1), 1.0, rtol=0, atol=1e-9):
            raise ValueError(f"ImmModel.switching rows must sum to 1 (got {p.sum(axis=1)})")
        if not (math.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"ImmModel.dt_s must be finite and > 0 (got {self.dt_s})")
        mu = np.asarray(self.initial_probabilities, dtype=float)
        if mu.shape != (r,) or np.any(mu < 0) or not math.isclose(mu.sum(), 1.0, abs_tol=1e-9):
            raise ValueError(
                f"ImmModel.initial_probabilities must be [{r}], >= 0, sum 1 (got {mu})"
            )
        std = self.initial_turn_rate_std_radps
        if not (math.isfinite(std) and std >= 0):
            raise ValueError(f"ImmModel.initial_turn_rate_std_radps must be >= 0 (got {std})")


@dataclass(frozen=True, eq=False)
class ImmBelief:
    """The IMM's belief: per mode j the Gaussian means [r, 5], covariances [r, 5, 5] (m, m/s,
    rad/s) and the mode probabilities [r] (sum 1)."""

    means: FloatArray
    covariances: FloatArray
    probabilities: FloatArray

    def mixed(self) -> Gaussian:
        """The moment-matched 5-D Gaussian: x = sum mu_j x_j, P = sum mu_j (P_j + dx_j dx_j^T)."""
        x, P = _moment_match(self.probabilities, self.means, self.covariances)
        return Gaussian(x=x, P=P)

    def marginal(self) -> Gaussian:
        """The [x, y, vx, vy] part [4], [4, 4] of mixed(): what the rest of the system sees."""
        g = self.mixed()
        return Gaussian(x=g.x[:4].copy(), P=g.P[:4, :4].copy())


def _moment_match(
    w: FloatArray, means: FloatArray, covs: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """(x [n], P [n, n]) of the mixture with weights w [r] of means [r, n], covs [r, n, n]."""
    x = w @ means
    d = means - x
    P = np.einsum("j,jab->ab", w, covs) + np.einsum("j,ja,jb->ab", w, d, d)
    return np.asarray(x), np.asarray(0.5 * (P + P.T))


def imm_start(model: ImmModel, g: Gaussian) -> ImmBelief:
    """Every mode from the 4-D Gaussian g (x [4], P [4, 4]) with omega = 0 and its variance
    initial_turn_rate_std^2; probabilities initial_probabilities."""
    r = len(model.modes)
    means = np.zeros((r, N_STATE))
    means[:, :4] = np.asarray(g.x, dtype=float)
    covs = np.zeros((r, N_STATE, N_STATE))
    covs[:, :4, :4] = np.asarray(g.P, dtype=float)
    covs[:, 4, 4] = model.initial_turn_rate_std_radps**2
    return ImmBelief(means, covs, np.asarray(model.initial_probabilities, dtype=float).copy())


def mix(model: ImmModel, belief: ImmBelief) -> ImmBelief:
    """IMM step 1: each mode j restarted from the mixture with weights mu_{i|j} = p_ij mu_i / c_j
    of all modes' posteriors (means and covariances with the spread); probabilities c_j =
    sum_i p_ij mu_i, the predicted mode probabilities."""
    joint = np.asarray(model.switching, dtype=float) * belief.probabilities[:, None]  # [i, j]
    c = joint.sum(axis=0)
    weights = joint / np.where(c > 0, c, 1.0)[None, :]
    means = np.empty_like(belief.means)
    covs = np.empty_like(belief.covariances)
    for j in range(len(c)):
        means[j], covs[j] = _moment_match(weights[:, j], belief.means, belief.covariances)
    return ImmBelief(means, covs, c / c.sum())


def imm_predict(model: ImmModel, belief: ImmBelief) -> ImmBelief:
    """IMM steps 1-2 over model.dt_s: `mix`, then each mode's EKF prediction x_j = f_j(x0j),
    P_j = F_j P0j F_j^T + Q_j (F_j the Jacobian at x0j). Probabilities: c_j."""
    mixed = mix(model, belief)
    means = np.empty_like(mixed.means)
    covs = np.empty_like(mixed.covariances)
    for j, mode in enumerate(model.modes):
        means[j], F = mode.transition(mixed.means[j], model.dt_s)
        P = F @ mixed.covariances[j] @ F.T + mode.noise(model.dt_s)
        if mode.model == "cv":
            # A cv mode knows nothing of a turn rate: 0 +- the initial std, so that a ct mode
            # mixed from it can take up a turn that starts (0 variance would pin omega at 0).
            P[4, 4] = model.initial_turn_rate_std_radps**2
        covs[j] = 0.5 * (P + P.T)
    return ImmBelief(means, covs, mixed.probabilities)


@dataclass(frozen=True)
class ImmPath:
    """The IMM's open-loop prediction of a track over the next slots (tracking/beliefs.py
    `PathOffsets`): `predicted`, the modes predicted to the end of slot n, predicted on by
    `imm_predict` (mixing every slot, no measurement); its offsets are the moment-matched mean's
    departure from the straight constant-velocity path from the same start, the curve of a turn
    that the turn mode follows, shrinking as the modes mix toward their long-run shares."""

    model: ImmModel
    predicted: ImmBelief

    def offsets(self, n_slots: int) -> FloatArray:
        """[n_slots, 4] (m, m/s): row h the mixture's mean at the end of slot n + h minus F^h
        times the one at the end of slot n (row 0 zeros)."""
        F = ConstantVelocity(0.0).transition(self.model.dt_s)
        out = np.zeros((n_slots, 4))
        belief = self.predicted
        straight = belief.marginal().x
        for h in range(1, n_slots):
            belief = imm_predict(self.model, belief)
            straight = F @ straight
            out[h] = belief.marginal().x - straight
        return out


def _padded_jacobian(x: FloatArray, uav_xy: FloatArray) -> FloatArray:
    """H [2M, 5]: measurement_jacobian at x[:4] with a zero column for omega."""
    H4 = measurement_jacobian(x[:4], uav_xy)
    return np.hstack([H4, np.zeros((H4.shape[0], 1))])


def _sequential_update(
    x0: FloatArray,
    P0: FloatArray,
    z: FloatArray,
    uav_xy: FloatArray,
    r_diag: FloatArray,
    x_lin: FloatArray,
) -> tuple[FloatArray, FloatArray, float]:
    """(x [5], P [5, 5], log-likelihood): the EKF update of (x0 [5], P0) with h linearised at
    x_lin [5], the scalar measurements folded in one at a time against h_i + H_i (x - x_lin)
    (Joseph form), and log N(z; h(x_lin) + H (x0 - x_lin), H P0 H^T + R) as the sum of the
    scalar innovations' log densities (the chain rule; exact for the linearised model)."""
    H_all = _padded_jacobian(x_lin, uav_xy)
    h_all = measure(x_lin[:4], uav_xy)
    x, P = x0.copy(), P0.copy()
    log_lik = 0.0
    eye = np.eye(len(x0))
    for i in np.flatnonzero(np.isfinite(z) & np.isfinite(r_diag)):
        H_i = H_all[i]
        nu = float(z[i] - h_all[i] - H_i @ (x - x_lin))
        PHt = P @ H_i
        s = float(H_i @ PHt) + float(r_diag[i])
        K = PHt / s
        A = eye - np.outer(K, H_i)
        P = A @ P @ A.T + float(r_diag[i]) * np.outer(K, K)
        x = x + K * nu
        log_lik -= 0.5 * (math.log(2 * math.pi * s) + nu * nu / s)
    return x, 0.5 * (P + P.T), log_lik


def mode_updates(
    belief: ImmBelief,
    z: FloatArray,
    uav_xy: FloatArray,
    r_diag: FloatArray,
    iterations: int = 1,
) -> tuple[ImmBelief, FloatArray]:
    """(updated belief, log-likelihoods [r]): each mode's EKF update with labelled measurements
    z [2M] (ranges m then radial velocities m/s; NaN = missing, as ekf.ekf_update) from uav_xy
    [M, 2] with variances r_diag [2M] (non-finite = missing), linearised at the mode's own
    prediction; log_lik_j = log N(z; h(x_j), H P_j H^T + R). Probabilities unchanged.

    iterations > 1: each mode's iterated EKF (as ekf.ekf_update): the update recomputed from the
    same prediction with h linearised at the previous iterate, the likelihood that of the last
    linearisation. It matters where R is far below the linearisation error (a prediction metres
    off with Doppler noise of mm/s)."""
    z = np.asarray(z, dtype=float)
    r_diag = np.asarray(r_diag, dtype=float)
    means = np.empty_like(belief.means)
    covs = np.empty_like(belief.covariances)
    log_lik = np.empty(len(belief.probabilities))
    for j in range(len(log_lik)):
        x0, P0 = belief.means[j], belief.covariances[j]
        x_lin = x0
        for _ in range(iterations):
            means[j], covs[j], log_lik[j] = _sequential_update(x0, P0, z, uav_xy, r_diag, x_lin)
            x_lin = means[j]
    return ImmBelief(means, covs, belief.probabilities.copy()), log_lik


@dataclass(frozen=True)
class ModePredictions:
    """Each mode's predicted measurement for one UAV's report: z_hat [r, 2] (range m, radial
    velocity m/s), H [r, 2, 5], S [r, 2, 2] = H P H^T + R, S_inv [r, 2, 2] and
    log det(2 pi S) [r]. Computed once per track and report: the association row and the
    modes' updates take the same."""

    z_hat: FloatArray
    H: FloatArray
    S: FloatArray
    S_inv: FloatArray
    log_det_2pi_S: FloatArray

    def distances2(self, z: FloatArray) -> FloatArray:
        """[r, k]: each measurement's squared Mahalanobis distance from each mode's z_hat."""
        nu = z[None, :, :] - self.z_hat[:, None, :]
        return np.asarray(np.einsum("jkd,jde,jke->jk", nu, self.S_inv, nu))


def mode_predictions(belief: ImmBelief, uav_xy: FloatArray, r_pair: FloatArray) -> ModePredictions:
    """ModePredictions of every mode of belief for a report taken at uav_xy [2] with measurement
    variances r_pair [2] (m^2, m^2/s^2)."""
    xy = np.asarray(uav_xy, dtype=float).reshape(1, 2)
    R = np.diag(np.asarray(r_pair, dtype=float))
    r = len(belief.probabilities)
    z_hat = np.empty((r, 2))
    H = np.empty((r, 2, N_STATE))
    for j in range(r):
        z_hat[j] = measure(belief.means[j, :4], xy)
        H[j] = _padded_jacobian(belief.means[j], xy)
    S = np.einsum("jdn,jnm,jem->jde", H, belief.covariances, H) + R
    det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] * S[:, 1, 0]
    S_inv = np.empty_like(S)
    S_inv[:, 0, 0], S_inv[:, 1, 1] = S[:, 1, 1] / det, S[:, 0, 0] / det
    S_inv[:, 0, 1], S_inv[:, 1, 0] = -S[:, 0, 1] / det, -S[:, 1, 0] / det
    return ModePredictions(z_hat, H, S, S_inv, np.log((2 * math.pi) ** 2 * det))


def _log_sum_exp(terms: FloatArray) -> float:
    """log sum exp(terms [n]), shifted by the maximum (-inf when every term is)."""
    top = float(np.max(terms))
    if not math.isfinite(top):
        return top
    return top + math.log(float(np.sum(np.exp(terms - top))))


def mode_pda_updates(
    belief: ImmBelief,
    z: FloatArray,
    uav_xy: FloatArray,
    r_pair: FloatArray,
    beta: FloatArray,
    detection_prob: float,
    clutter_density: float,
    gate_prob: float,
    predicted: ModePredictions | None = None,
) -> tuple[ImmBelief, FloatArray]:
    """(updated belief, log-likelihoods [r]) for one UAV's unlabelled report z [k, 2] (range m,
    radial velocity m/s) taken at uav_xy [2] with variances r_pair [2] (m^2, m^2/s^2), and the
    caller's association marginals beta [k + 1] (the miss last; from the mixed prediction).
    predicted: `mode_predictions(belief, uav_xy, r_pair)` when the caller has it already.

    Mode j: association.pda_update with z_hat_j, H_j [2, 5], S_j = H_j P_j H_j^T + R, and the
    IMM-PDAF mode likelihood (clutter_density lambda per m * m/s, P_d, P_g)

        log[(1 - P_d P_g) + (P_d / lambda) sum_k N(z_k; z_hat_j, S_j)]

    with every measurement of the report in the sum, gated or not (no mode-dependent gate, so
    the likelihood is smooth in the state; outside the gate gamma a measurement's density is
    below exp(-gamma / 2) of the peak: 1 % at P_g = 0.99). k = 0 gives log(1 - P_d P_g)."""
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    pred = predicted if predicted is not None else mode_predictions(belief, uav_xy, r_pair)
    beta = np.asarray(beta, dtype=float)
    means = np.empty_like(belief.means)
    covs = np.empty_like(belief.covariances)
    log_pd = math.log(detection_prob / clutter_density) if detection_prob > 0 else -math.inf
    log_n = -0.5 * (pred.log_det_2pi_S[:, None] + pred.distances2(z))
    miss = math.log1p(-detection_prob * gate_prob)
    log_lik = np.empty(len(belief.probabilities))
    for j in range(len(log_lik)):
        means[j], covs[j] = pda_update(
            belief.means[j], belief.covariances[j], pred.z_hat[j], pred.H[j], pred.S[j], z, beta
        )
        log_lik[j] = _log_sum_exp(np.concatenate([[miss], log_pd + log_n[j]]))
    return ImmBelief(means, covs, belief.probabilities.copy()), log_lik


@dataclass(frozen=True)
class ModeRows:
    """One IMM track's row of a report's hypotheses (tracking/association.py) from its modes:
    likelihood_ratio [k] = sum_j c_j l_j (l_j: mode j's ratio, 0 outside its gate), gated [k]:
    inside some mode's gate, distance2 [k]: the smallest mode's Mahalanobis distance squared."""

    likelihood_ratio: FloatArray
    gated: BoolArray
    distance2: FloatArray

    def put(self, h: Hypotheses, i: int) -> None:
        """Write the row into track i of h (in place)."""
        h.likelihood_ratio[i] = self.likelihood_ratio
        h.gated[i] = self.gated
        h.distance2[i] = self.distance2


def mode_rows(
    belief: ImmBelief,
    z: FloatArray,
    uav_xy: FloatArray,
    r_pair: FloatArray,
    detection_prob: float,
    clutter_density: float,
    gate: float,
    predicted: ModePredictions | None = None,
) -> ModeRows:
    """The IMM-JPDA association row of one track (Blom and Bloem, "Probabilistic data
    association avoiding track coalescence", IEEE T-AC 2000): each measurement of the report
    z [k, 2] taken at uav_xy [2] with variances r_pair [2] is weighed by the mixture of the
    modes' predictions, sum_j c_j P_d N(z; z_hat_j, S_j) / lambda (c_j the predicted mode
    probabilities), and is in the track's gate gamma when it is in some mode's. So a
    measurement only the manoeuvring mode expects (a turn that has just begun) is the track's,
    where the moment-matched prediction would gate it out. predicted: as mode_pda_updates."""
    z = np.asarray(z, dtype=float).reshape(-1, 2)
    pred = predicted if predicted is not None else mode_predictions(belief, uav_xy, r_pair)
    d2 = pred.distances2(z)
    inside = d2 <= gate
    density = np.exp(-0.5 * (pred.log_det_2pi_S[:, None] + d2))
    weight = belief.probabilities[:, None] * detection_prob / clutter_density
    ratio = np.where(inside, weight * density, 0.0).sum(axis=0)
    gated = np.asarray(inside.any(axis=0), dtype=bool)
    return ModeRows(ratio, gated, d2.min(axis=0, initial=np.inf))


def with_likelihoods(
    belief: ImmBelief, log_likelihoods: FloatArray, floor: float = 1e-6
) -> ImmBelief:
    """IMM step 4: mode probabilities ~ probabilities * exp(log_likelihoods [r]), computed in
    the log domain (shifted by the maximum), then floored at `floor` and renormalised: a mode
    never dies, so it can take over at the next manoeuvre. Means and covariances unchanged."""
    with np.errstate(divide="ignore"):
        log_w = np.log(belief.probabilities) + np.asarray(log_likelihoods, dtype=float)
    p = np.exp(log_w - np.max(log_w))
    p = np.maximum(p / p.sum(), floor)
    return ImmBelief(belief.means, belief.covariances, p / p.sum())


def imm_update(
    belief: ImmBelief, z: FloatArray, uav_xy: FloatArray, r_diag: FloatArray, iterations: int = 1
) -> ImmBelief:
    """IMM steps 3-4 with labelled measurements: `mode_updates`, then `with_likelihoods`."""
    updated, log_lik = mode_updates(belief, z, uav_xy, r_diag, iterations)
    return with_likelihoods(updated, log_lik)


def mixed_kappa(model: ImmModel, probabilities: FloatArray) -> float:
    """sum_j mu_j kappa_j (m^2/s^3): the modes' white-noise intensities mixed by the mode
    probabilities [r]; the process noise of a track's bound under the IMM (a turn mode's turn
    is its dynamics, known to the bound as to the filter; only its noise is not)."""
    kappas = np.array([m.kappa_m2ps3 for m in model.modes])
    return float(np.asarray(probabilities, dtype=float) @ kappas)


def imm_model(spec: ImmSpec, dt_s: float) -> ImmModel:
    """The ImmModel of a scenario's resolved `tracker.imm:` (config ImmSpec) at slot dt_s (s)."""
    return ImmModel(
        modes=tuple(
            ImmMode(cast(ModeKind, m.model), m.kappa_m2ps3, m.turn_noise_rad2ps3)
            for m in spec.modes
        ),
        switching=np.array(spec.switching, dtype=float),
        dt_s=dt_s,
        initial_probabilities=np.array(spec.initial_probabilities, dtype=float),
        initial_turn_rate_std_radps=spec.initial_turn_rate_std_radps,
    )
