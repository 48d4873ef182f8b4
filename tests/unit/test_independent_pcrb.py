"""The independent trace checker, PCRB recursion: right against finite differences, brute-force
information and exact rational arithmetic, and its comparison flags what is wrong only."""

from __future__ import annotations

import math
from dataclasses import replace
from fractions import Fraction
from typing import Any

import numpy as np
import pytest

from isac_mission.records import SlotRecord, Trace
from tests.support.checker_cases import base_config, mutate
from tests.support.independent.pcrb import (
    bound_update,
    compare_pcrb,
    cv_model,
    jacobian,
    measurement,
    recompute_pcrb,
)

# ---------------------------------------------------------------------------------------------
# PCRB recursion

X = np.array([600.0, 1600.0, 30.0, -4.0])
UAVS = np.array([[1500.0, 2300.0], [807.0, 1100.0], [2193.0, 1100.0]])
P0 = np.diag([100.0, 100.0, 4.0, 4.0])


def pcrb_config(**changes: Any) -> dict[str, Any]:
    return base_config(**{"M": 3, "P0": P0.tolist(), **changes})


def fd_jacobian(x: np.ndarray, uav_xy: np.ndarray, step: float = 1e-3) -> np.ndarray:
    cols = []
    for i in range(4):
        e = np.zeros(4)
        e[i] = step
        cols.append((measurement(x + e, uav_xy) - measurement(x - e, uav_xy)) / (2 * step))
    return np.array(cols).T


def test_measurement_is_range_and_radial_velocity() -> None:
    z = measurement(X, UAVS)
    for m, q in enumerate(UAVS):
        los = X[:2] - q
        assert z[m] == pytest.approx(np.linalg.norm(los), rel=1e-15)
        assert z[3 + m] == pytest.approx(los @ X[2:] / np.linalg.norm(los), rel=1e-14)


def test_jacobian_matches_central_differences() -> None:
    # central-difference error: truncation ~ step^2 |h'''| <= 1e-6 * 1e-6, rounding ~
    # eps * |h| / step ~ 1e-16 * 2e3 / 1e-3 = 2e-10
    np.testing.assert_allclose(jacobian(X, UAVS), fd_jacobian(X, UAVS), rtol=0, atol=1e-8)


def slot_trace(r_diag: np.ndarray, config: dict[str, Any] | None = None) -> Trace:
    rec = SlotRecord(
        slot=1,
        method="proposed",
        status="ok",
        uav_xy_m=UAVS,
        bandwidth_share=np.full(3, 1 / 3),
        assoc=np.array([0, 1, 1]),
        target_true=None,
        target_est=X,
        target_pred=X,
        r_diag=r_diag,
        pcrb_trace=0.0,
        solve_ms=0.0,
        P=np.eye(4),
        J=np.eye(4),
    )
    return Trace(config=config or pcrb_config(), slots=[rec])


def test_one_slot_matches_brute_force_information() -> None:
    r = np.array([4.0, 9.0, 2.0, 0.01, 0.04, 0.02])
    F, W = cv_model(1.0, 0.5)
    H = fd_jacobian(X, UAVS)
    J = np.linalg.inv(F @ P0 @ F.T + W)
    for i in range(6):
        J += np.outer(H[i], H[i]) / r[i]
    ((slot, tr, J_ours),) = recompute_pcrb(slot_trace(r))
    assert slot == 1
    # H from differences is good to ~1e-10 relative, J and tr(J^-1) as well
    np.testing.assert_allclose(J_ours, J, rtol=1e-7, atol=1e-9 * np.abs(J).max())
    assert tr == pytest.approx(np.trace(np.linalg.inv(J)), rel=1e-7)


def _exact_inverse(a: list[list[Fraction]]) -> list[list[Fraction]]:
    n = len(a)
    rows = [[*row, *(Fraction(int(i == j)) for j in range(n))] for i, row in enumerate(a)]
    for c in range(n):
        p = next(r for r in range(c, n) if rows[r][c] != 0)
        rows[c], rows[p] = rows[p], rows[c]
        rows[c] = [v / rows[c][c] for v in rows[c]]
        for r in range(n):
            if r != c and rows[r][c] != 0:
                f = rows[r][c]
                rows[r] = [a_ - f * b_ for a_, b_ in zip(rows[r], rows[c], strict=True)]
    return [row[n:] for row in rows]


def test_degenerate_variances_keep_the_bound_exact() -> None:
    # literal eq. 8: range variances ~1e-20 m^2 make cond(J) ~1e17; the covariance-form update
    # loses every digit of the position variance there. Reference: exact rational arithmetic on
    # the same float inputs (F P0 F^T + W and H are exact in floating point here).
    r = np.array([1.1e-20, 2.3e-20, 0.7e-20, 2.6e-4, 1.3e-4, 4.1e-4])
    F, W = cv_model(1.0, 0.5)
    H = jacobian(X, UAVS)
    fr = lambda a: [[Fraction(float(v)) for v in row] for row in a]  # noqa: E731
    prior = _exact_inverse(fr(F @ P0 @ F.T + W))
    Hf = fr(H)
    J = [
        [
            prior[i][j] + sum(Hf[k][i] * Hf[k][j] / Fraction(float(r[k])) for k in range(6))
            for j in range(4)
        ]
        for i in range(4)
    ]
    C = _exact_inverse(J)
    ((_, tr, J_ours),) = recompute_pcrb(slot_trace(r))
    assert tr == pytest.approx(float(sum(C[i][i] for i in range(4))), rel=1e-12)
    J_exact = np.array([[float(v) for v in row] for row in J])
    scale = np.sqrt(np.outer(np.diag(J_exact), np.diag(J_exact)))
    assert np.max(np.abs(J_ours - J_exact) / scale) < 1e-14
    assert np.linalg.cond(J_exact) > 1e15  # the case really is degenerate
    # every entry of C, the 1e-20 m^2 position variances included, not only the trace
    C_ours, _ = bound_update(P0, F, W, H, r)
    C_exact = np.array([[float(v) for v in row] for row in C])
    np.testing.assert_allclose(np.diag(C_ours), np.diag(C_exact), rtol=1e-12)


def test_missing_measurement_carries_no_information() -> None:
    r = np.array([4.0, np.nan, 2.0, 0.01, np.nan, 0.02])
    ((_, tr, J),) = recompute_pcrb(slot_trace(r))
    two = Trace(
        config=pcrb_config(M=2),
        slots=[
            replace(
                slot_trace(np.ones(6)).slots[0],
                uav_xy_m=UAVS[[0, 2]],
                bandwidth_share=np.array([0.5, 0.5]),
                assoc=np.array([0, 1]),
                r_diag=np.array([4.0, 2.0, 0.01, 0.02]),
            )
        ],
    )
    ((_, tr_two, J_two),) = recompute_pcrb(two)
    assert tr == pytest.approx(tr_two, rel=1e-14)
    np.testing.assert_allclose(J, J_two, rtol=1e-14)


def logged_trace(n_slots: int, r: np.ndarray) -> Trace:
    """A trace whose pcrb_trace and J come from a plain information-form numpy recursion."""
    F, W = cv_model(1.0, 0.5)
    J = np.linalg.inv(P0)
    slots = []
    x = X.copy()
    for n in range(1, n_slots + 1):
        x = F @ x
        uav = UAVS + 5.0 * n
        H = fd_jacobian(x, uav)
        J = np.linalg.inv(F @ np.linalg.inv(J) @ F.T + W) + H.T @ np.diag(1 / r) @ H
        base = slot_trace(r).slots[0]
        slots.append(
            replace(
                base,
                slot=n,
                uav_xy_m=uav,
                target_pred=x,
                pcrb_trace=float(np.trace(np.linalg.inv(J))),
                J=J,
            )
        )
    return Trace(config=pcrb_config(), slots=slots)


def test_compare_accepts_an_independently_logged_recursion() -> None:
    trace = logged_trace(3, np.array([4.0, 9.0, 2.0, 0.01, 0.04, 0.02]))
    assert compare_pcrb(trace) == []


def test_compare_flags_a_wrong_trace_and_a_wrong_information_entry() -> None:
    trace = logged_trace(3, np.array([4.0, 9.0, 2.0, 0.01, 0.04, 0.02]))
    s2 = trace.slots[1]
    trace = mutate(trace, 1, pcrb_trace=s2.pcrb_trace * (1 + 1e-5))
    J = trace.slots[0].J.copy()
    J[0, 2] += 1e-5 * math.sqrt(J[0, 0] * J[2, 2])
    J[2, 0] = J[0, 2]
    trace = mutate(trace, 0, J=J)
    msgs = compare_pcrb(trace)
    assert len(msgs) == 2
    assert msgs[0].startswith("slot 1: J[0,2]")
    assert msgs[1].startswith("slot 2: pcrb_trace")
    assert compare_pcrb(trace, rtol=1e-4) == []


def test_compare_does_not_flag_a_degenerate_but_correct_trace() -> None:
    # information form with a Jacobi-scaled inverse is accurate at cond(J) ~1e17
    r = np.array([1.1e-20, 2.3e-20, 0.7e-20, 2.6e-4, 1.3e-4, 4.1e-4])
    F, W = cv_model(1.0, 0.5)
    J = np.linalg.inv(F @ P0 @ F.T + W) + jacobian(X, UAVS).T @ np.diag(1 / r) @ jacobian(X, UAVS)
    s = 1 / np.sqrt(np.diag(J))
    C = np.linalg.inv(J * np.outer(s, s)) * np.outer(s, s)
    trace = slot_trace(r)
    trace = mutate(trace, 0, J=J, pcrb_trace=float(np.trace(C)))
    assert compare_pcrb(trace) == []
