"""Every margin the planner keeps, with its reason, in one place (docs/model.md, "Safety").

The safety rule: distances the plan keeps so that the true ones hold. The paper keeps D_s
between the *planned* UAV positions and the *predicted* target (14j) and between planned UAVs
(14i). The true target is off its prediction by the tracker's prediction error, and a vehicle is
off its planned leg by its tracking error, so with planner.safety_margin = "covariance" the plan
keeps:

- 14j: D_s + k sigma_max + e from the predicted target, with sigma_max^2 the largest eigenvalue
  of the predicted position covariance over the slot (at each sampled instant of the leg,
  planning/legs.py: the target's possible motion within the slot; the true target is within
  k sigma_max of its prediction along any direction with probability Phi(k) or more) and
  e = planner.tracking_margin_m, plus a_T dt^2 / 2 for a target that manoeuvres at up to
  a_T = target_motion.max_accel_mps2 off its prediction within the slot; kept along the legs,
  not only at their ends;
- 14i: D_s + 2 e between planned UAVs (and D_s + 2 e from keep-out points);
- 14a and 14b: the rate and the control range at a distance e farther from the BS.

With "none" every margin is 0 and D_s is the paper's.

The numerical margins, so that a solver's answer within its own tolerance passes the exact check
(planning/feasibility.py) unchanged: SOLVER_MARGIN_M (distances in the convex subproblem and the
NLPs), RATE_MARGIN (14a in the NLPs), MIN_SHARE (shares off 0 in the NLPs), SHARE_MARGIN (the
bandwidth subproblem's floor), LEG_LIMIT_TOLERANCE (the horizon's leg limits). The chord and sag
margins between leg samples are `chord_point_clearance_m` (planning/legs.py) plus `sag_m`, and
a Hermite leg's bulge off its straight plan `hermite_bulge_m`.

Pure: numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.planning.legs import leg_fractions
from isac_mission.types import FloatArray

SOLVER_MARGIN_M = 1e-3
"""Distance constraints of the convex subproblem (P1.1.2) and of the NLPs are tightened by this
much (m), so that a solver answer within its own tolerance still satisfies the original
constraints exactly."""

RATE_MARGIN = 1e-7
"""The NLPs' rate rows are eta R~ / R_th - 1 >= RATE_MARGIN (relative), so that a solution within
IPOPT's tolerance still passes the exact 14a check (relative tolerance 1e-12)."""

MIN_SHARE = 1e-9
"""The NLPs' shares stay at least this far from 0 (a_m is quadratic in eta: 0 is a stationary
point)."""

SHARE_MARGIN = 1e-9
"""The bandwidth subproblem keeps each share this much (relative) above the 14a floor eta_min."""

LEG_LIMIT_TOLERANCE = 1e-6
"""Relative slack of the horizon's exact leg checks against a_max and V_max (IPOPT's constraint
tolerance is 1e-8)."""


def hermite_bulge_m(a_max_mps2: float, dt_s: float, gap_s: float) -> float:
    """How much farther (m) the SCA subproblem and the polish keep a vehicle whose leg is the
    vehicle model's Hermite curve rather than the straight leg they plan: its bulge off the
    straight leg, at most (4/27) a_max dt^2 / 4, and the sagitta between samples gap_s apart."""
    return a_max_mps2 * (dt_s**2 / 27 + gap_s**2 / 8)


def sag_m(a_max_mps2: float, gap_s: float) -> float:
    """The most a leg of acceleration at most a_max_mps2 strays from its chord between two
    samples gap_s apart (the sagitta a h^2 / 8), m."""
    return a_max_mps2 * gap_s**2 / 8


@dataclass(frozen=True)
class SafetyMargins:
    """The scenario's fixed margins, m: tracking_m (e, 0 when the rule is off), separation_m
    (the planned UAV-UAV distance, D_s + 2 e), link_m (added to UAV-BS distances in 14a/14b)."""

    tracking_m: float
    separation_m: float
    link_m: float

    @classmethod
    def of(cls, s: Scenario) -> SafetyMargins:
        e = s.planner.tracking_margin_m if rule_on(s) else 0.0
        return cls(tracking_m=e, separation_m=s.d_safe + 2 * e, link_m=e)


def rule_on(s: Scenario) -> bool:
    """True when planner.safety_margin is "covariance" (the margins and the leg samples)."""
    return s.planner.safety_margin == "covariance"


def leg_samples(s: Scenario) -> int:
    """S, the sampled instants per leg: planner.horizon.leg_samples with the rule on, else 1
    (the slot instant only, as the paper)."""
    return s.planner.horizon.leg_samples if rule_on(s) else 1


def slot_sigma_max_m(s: Scenario, target_cov_pred: FloatArray) -> float:
    """sigma_max (m): the largest standard deviation of the predicted target position along any
    direction, over the leg's sampled instants tau_i dt (planning/legs.py) of the slot whose
    predicted covariance at its end is target_cov_pred [4, 4] ([2, 2]: that instant only).

    The covariance at tau dt is the motion model's prediction from the slot's start,
    F(tau dt) P_0 F(tau dt)^T + W(tau dt), with P_0 = F(dt)^-1 (P_pred - W(dt)) F(dt)^-T the
    start's covariance recovered from the end's (clipped to be positive semidefinite)."""
    P = np.asarray(target_cov_pred, dtype=float)
    P = 0.5 * (P + P.T)
    if P.shape == (2, 2):
        return float(np.sqrt(max(_largest_eigenvalue(P[None])[0], 0.0)))
    var = _largest_eigenvalue(P[None, :2, :2])
    fractions = leg_fractions(leg_samples(s))[:-1]
    if len(fractions):
        back = s.motion.transition(-s.dt)  # F(dt)^-1
        P0 = back @ (P - s.motion.process_noise(s.dt)) @ back.T
        w, V = np.linalg.eigh(0.5 * (P0 + P0.T))
        P0 = (V * np.maximum(w, 0.0)) @ V.T
        path = s.motion.predicted_path(np.zeros(4), P0, fractions * s.dt)
        var = np.concatenate([var, _largest_eigenvalue(path.covariances[:, :2, :2])])
    return float(np.sqrt(max(float(np.max(var)), 0.0)))


def _largest_eigenvalue(P: FloatArray) -> FloatArray:
    """[L] the largest eigenvalue of each symmetric 2 x 2 matrix of P [L, 2, 2] (closed form)."""
    a, b, c = P[:, 0, 0], 0.5 * (P[:, 0, 1] + P[:, 1, 0]), P[:, 1, 1]
    return np.asarray(0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b))


def target_clearance_m(s: Scenario, target_cov_pred: FloatArray | None) -> float:
    """The planned distance (m) from the predicted target that 14j keeps: D_s, plus (rule on)
    k sigma_max + e + the manoeuvre margin for the predicted covariance target_cov_pred [4, 4] (or
    [2, 2]; None: no covariance term), sigma_max over the slot's sampled instants
    (`slot_sigma_max_m`), plus the manoeuvre margin (`manoeuvre_margin_m`)."""
    cfg = s.planner
    if not rule_on(s):
        return s.d_safe
    sigma = 0.0 if target_cov_pred is None else slot_sigma_max_m(s, target_cov_pred)
    return (
        s.d_safe
        + cfg.safety_confidence_sigma * sigma
        + cfg.tracking_margin_m
        + manoeuvre_margin_m(s)
    )


def manoeuvre_margin_m(s: Scenario) -> float:
    """What 14j keeps (m, rule on; else 0) for a target that manoeuvres at up to a_T =
    s.a_target off its constant-velocity prediction: a_T dt^2 / 2, how far it can be off by the
    slot's end, plus, with the vehicle model (where the evasion guard checks the end state),
    the reaction margin (a_T dt)^2 / (2 (a_max - a_T)): a UAV that ends its slot at rest
    relative to the target, the target's velocity a_T dt off its prediction toward it, closes
    by at most that much before its own a_max - a_T opens the distance again
    (docs/model.md, "Safety")."""
    if not rule_on(s):
        return 0.0
    margin = 0.5 * s.a_target * s.dt**2
    if s.planner.vehicle_model and s.a_target > 0:
        surplus = max(s.a_max - s.a_target, 1e-3 * s.a_max)
        margin += (s.a_target * s.dt) ** 2 / (2 * surplus)
    return margin
