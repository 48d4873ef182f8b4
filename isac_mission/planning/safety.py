"""The safety rule (docs/model.md, "Safety"): distances the plan keeps so that the true ones hold.

The paper keeps D_s between the *planned* UAV positions and the *predicted* target (14j) and
between planned UAVs (14i). The true target is off its prediction by the tracker's prediction
error, and a vehicle is off its planned leg by its tracking error, so with planner.safety_margin
= "covariance" the plan keeps:

- 14j: D_s + k sigma_max + e from the predicted target, with sigma_max^2 the largest eigenvalue
  of the predicted position covariance over the slot (at each sampled instant of the leg,
  planning/legs.py: the target's possible motion within the slot; the true target is within
  k sigma_max of its prediction along any direction with probability Phi(k) or more) and
  e = planner.tracking_margin_m; kept along the legs, not only at their ends;
- 14i: D_s + 2 e between planned UAVs (and D_s + 2 e from keep-out points);
- 14a and 14b: the rate and the control range at a distance e farther from the BS.

With "none" every margin is 0 and D_s is the paper's. Pure: numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.planning.legs import leg_fractions
from isac_mission.types import FloatArray


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

    The covariance at tau dt is the constant-velocity prediction from the slot's start,
    F(tau dt) P_0 F(tau dt)^T + W(tau dt), with P_0 = F(dt)^-1 (P_pred - W(dt)) F(dt)^-T the
    start's covariance recovered from the end's (clipped to be positive semidefinite)."""
    P = np.asarray(target_cov_pred, dtype=float)
    P = 0.5 * (P + P.T)
    if P.shape == (2, 2):
        return float(np.sqrt(max(np.linalg.eigvalsh(P)[-1], 0.0)))
    var = [float(np.linalg.eigvalsh(P[:2, :2])[-1])]
    fractions = leg_fractions(leg_samples(s))[:-1]
    if len(fractions):
        F_inv = np.linalg.inv(transition_matrix(s.dt))
        P0 = F_inv @ (P - process_noise(s.dt, s.kappa)) @ F_inv.T
        w, V = np.linalg.eigh(0.5 * (P0 + P0.T))
        P0 = (V * np.maximum(w, 0.0)) @ V.T
        for tau in fractions:
            F = transition_matrix(tau * s.dt)
            Pt = F @ P0 @ F.T + process_noise(tau * s.dt, s.kappa)
            var.append(float(np.linalg.eigvalsh(0.5 * (Pt[:2, :2] + Pt[:2, :2].T))[-1]))
    return float(np.sqrt(max(max(var), 0.0)))


def target_clearance_m(s: Scenario, target_cov_pred: FloatArray | None) -> float:
    """The planned distance (m) from the predicted target that 14j keeps: D_s, plus (rule on)
    k sigma_max + e for the predicted covariance target_cov_pred [4, 4] (or [2, 2]; None: no
    covariance term), sigma_max over the slot's sampled instants (`slot_sigma_max_m`)."""
    cfg = s.planner
    if not rule_on(s):
        return s.d_safe
    sigma = 0.0 if target_cov_pred is None else slot_sigma_max_m(s, target_cov_pred)
    return s.d_safe + cfg.safety_confidence_sigma * sigma + cfg.tracking_margin_m
