"""The horizon's own assumption, by Monte Carlo: the L-step constant-velocity prediction and its
covariance (docs/model.md, "The horizon's prediction, checked").

The receding-horizon planner plans slots n+1..n+L along the prediction of the EKF's posterior of
slot n: x_{n+l|n} = F^l x_hat_n, P_{n+l|n} = F^l P_n F^l' + sum_{j<l} F^j W F^j'. In the paper's
scenario (config/paper.yaml, the target of the constant-velocity model, the proposed method
flying the UAVs) over RUNS runs and every slot n = 1..N-L:

1. NEES: e' P_{n+L|n}^-1 e with e = x_{n+L} - x_{n+L|n} (the true state) is chi-square(4) if the
   prediction is consistent. The mean over runs and slots must lie in the two-sided 95 % interval
   of the mean of R independent chi-square(4) values, [chi2_{4R}(0.025), chi2_{4R}(0.975)] / R.
   The runs are independent, the slots of one run are not; the mean of a run's slots has at most
   the variance of one value (Cauchy-Schwarz), so this interval is conservative (never too narrow)
   for the grand mean. Bar-Shalom's check per slot (the run-averaged NEES of each slot inside
   chi2_{4R} / R's interval) is printed beside it.
2. Constraint breaks: the 14j rule (planning/margins.py) keeps the planned point q at
   target_clearance_m(P) = D_s + k sigma_max + e from the predicted target; a point at exactly that
   clearance in the worst direction (the eigenvector of the largest eigenvalue of the predicted
   position covariance, both signs) is broken when the true target comes within D_s of it.
   The rule states that the true target is within k sigma_max of the prediction along any
   direction with probability Phi(k) or more: the break rate of one such point must stay below
   1 - Phi(k). Checked with the tracking margin e = 0 (it is the vehicles' share, not the
   prediction's) at k = 1, 2, 3 (where breaks are frequent enough to count) and at the scenario's
   own k; allowance 3 sqrt(p (1 - p) / R) above p = 1 - Phi(k) (runs independent, the same
   variance argument as above).

The posteriors come from the proposed method's runs (8 at CI size, 60 at full size with --full,
tests/conftest.py) and, with --full only, from 20 runs of the `horizon` method (its own geometry,
the one whose assumption this is); `pytest -s` prints the table.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from isac_mission.config import Scenario
from isac_mission.experiment.closed_loop import (
    SlotOutcome,
    draw_run_noise,
    run_closed_loop,
)
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.margins import target_clearance_m
from isac_mission.types import FloatArray

HORIZON = 5
LEVEL = 0.95
K_CHECKED = (1.0, 2.0, 3.0)


FLOWN_BY = ("proposed", pytest.param("horizon", marks=pytest.mark.full_size_only))
"""The methods whose runs give the posteriors; the horizon's (a few seconds a run) at full size
only."""


def _runs(method: str, full_size: bool) -> int:
    if method == "horizon":
        return 20
    return 60 if full_size else 8


def predict_ahead(
    F: FloatArray, W: FloatArray, x: FloatArray, P: FloatArray, steps: int
) -> tuple[FloatArray, FloatArray]:
    """The constant-velocity prediction `steps` slots ahead: (x [4], P [4, 4])."""
    for _ in range(steps):
        x = F @ x
        P = F @ P @ F.T + W
    return x, P


@pytest.fixture(scope="module", params=FLOWN_BY)
def posteriors(
    request: pytest.FixtureRequest, paper: Scenario, full_size: bool
) -> list[list[SlotOutcome]]:
    """The slots of the closed-loop runs of one method on paper.yaml (seeds 1..)."""
    method = request.param
    kit = SolverKit(paper)
    runs: list[list[SlotOutcome]] = []
    for r in range(_runs(method, full_size)):
        slots: list[SlotOutcome] = []
        run_closed_loop(paper, method, draw_run_noise(paper, paper.seed + r), kit, slots.append)
        runs.append(slots)
    return runs


def _nees_and_offsets(
    s: Scenario, runs: list[list[SlotOutcome]], steps: int
) -> tuple[FloatArray, list[tuple[FloatArray, FloatArray]]]:
    """NEES [R, N - steps] of the `steps`-ahead prediction, and per sample (true - predicted
    position [2], predicted position covariance [2, 2])."""
    F, W = transition_matrix(s.dt), process_noise(s.dt, s.kappa)
    nees = np.empty((len(runs), len(runs[0]) - steps))
    offsets = []
    for r, slots in enumerate(runs):
        for i in range(len(slots) - steps):
            x, P = predict_ahead(F, W, slots[i].target_est, slots[i].P, steps)
            e = slots[i + steps].target_true - x
            nees[r, i] = float(e @ np.linalg.solve(P, e))
            offsets.append((e[:2], P[:2, :2]))
    return nees, offsets


def break_rate(
    s: Scenario, offsets: list[tuple[FloatArray, FloatArray]], k: float, margin_m: float
) -> float:
    """Share of (sample, sign) where a point at D_s + k sigma_max + margin_m from the predicted
    target along +-(largest-eigenvalue direction) is within D_s of the true target."""
    broken = 0
    for delta, P in offsets:
        lam, vec = np.linalg.eigh(P)
        u = vec[:, -1]
        clearance = s.d_safe + k * math.sqrt(lam[-1]) + margin_m
        for sign in (1.0, -1.0):
            broken += float(np.linalg.norm(sign * clearance * u - delta)) < s.d_safe
    return broken / (2 * len(offsets))


def nees_interval(runs: int) -> tuple[float, float]:
    lo, hi = stats.chi2.ppf([(1 - LEVEL) / 2, (1 + LEVEL) / 2], 4 * runs) / runs
    return float(lo), float(hi)


@pytest.mark.parametrize("steps", range(1, HORIZON + 1))
def test_mean_nees_of_the_l_step_prediction_is_chi_square_4(
    paper: Scenario, posteriors: list[list[SlotOutcome]], steps: int
) -> None:
    nees, _ = _nees_and_offsets(paper, posteriors, steps)
    runs = nees.shape[0]
    lo, hi = nees_interval(runs)
    per_slot = nees.mean(axis=0)
    inside = float(np.mean((per_slot >= lo) & (per_slot <= hi)))
    print(
        f"\n{posteriors[0][0].method} L={steps}: mean NEES {nees.mean():.3f} (95 % interval {lo:.3f}-{hi:.3f}, {runs} runs "
        f"x {nees.shape[1]} slots); median {np.median(nees):.3f} (chi2(4) median "
        f"{stats.chi2.median(4):.3f}); slots with the run-mean inside: {inside:.0%}"
    )
    assert lo <= nees.mean() <= hi, (nees.mean(), lo, hi)


@pytest.mark.parametrize("steps", range(1, HORIZON + 1))
def test_a_distance_kept_on_the_prediction_holds_at_the_rules_level(
    paper: Scenario, posteriors: list[list[SlotOutcome]], steps: int
) -> None:
    _, offsets = _nees_and_offsets(paper, posteriors, steps)
    runs = len(posteriors)
    own_k = paper.planner.safety_confidence_sigma
    rule = target_clearance_m(paper, offsets[0][1])  # the scenario's rule is on
    assert rule > paper.d_safe
    line = []
    for k in (*K_CHECKED, own_k):
        p = float(stats.norm.sf(k))
        rate = break_rate(paper, offsets, k, 0.0)
        line.append(f"k={k:g}: {rate:.4f} (level {p:.2g})")
        assert rate <= p + 3 * math.sqrt(p * (1 - p) / runs), (k, rate, p)
    # the rule as the planner applies it (tracking margin included): no breaks at all here
    with_margin = break_rate(paper, offsets, own_k, paper.planner.tracking_margin_m)
    print(
        f"\n{posteriors[0][0].method} L={steps}, {2 * len(offsets)} points: "
        + "; ".join(line)
        + f"; rule {with_margin}"
    )
    assert with_margin <= float(stats.norm.sf(own_k)) + 3 * math.sqrt(stats.norm.sf(own_k) / runs)
