"""The safety rule (docs/model.md, "Safety"): distances the plan keeps so that the true ones hold.

The paper keeps D_s between the *planned* UAV positions and the *predicted* target (14j) and
between planned UAVs (14i). The true target is off its prediction by the tracker's prediction
error, and a vehicle is off its planned leg by its tracking error, so with planner.safety_margin
= "covariance" the plan keeps:

- 14j: D_s + k sigma_max + e from the predicted target, with sigma_max^2 the largest eigenvalue
  of the predicted position covariance (the true target is within k sigma_max of its prediction
  along any direction with probability Phi(k) or more) and e = planner.tracking_margin_m;
- 14i: D_s + 2 e between planned UAVs (and D_s + 2 e from keep-out points);
- 14a and 14b: the rate and the control range at a distance e farther from the BS.

With "none" every margin is 0 and D_s is the paper's. Pure: numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
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
        e = s.planner.tracking_margin_m if s.planner.safety_margin == "covariance" else 0.0
        return cls(tracking_m=e, separation_m=s.d_safe + 2 * e, link_m=e)


def target_clearance_m(s: Scenario, target_cov_pred: FloatArray | None) -> float:
    """The planned distance (m) from the predicted target that 14j keeps: D_s, plus (rule on)
    k sqrt(lambda_max(P_pos)) + e for the predicted covariance target_cov_pred [4, 4] (or
    [2, 2]; None: no covariance term)."""
    cfg = s.planner
    if cfg.safety_margin == "none":
        return s.d_safe
    sigma = 0.0
    if target_cov_pred is not None:
        P = np.asarray(target_cov_pred, dtype=float)[:2, :2]
        sigma = float(np.sqrt(max(np.linalg.eigvalsh(0.5 * (P + P.T))[-1], 0.0)))
    return s.d_safe + cfg.safety_confidence_sigma * sigma + cfg.tracking_margin_m
