"""The independent trace checker: each of (14a)-(14j) is caught alone, and the PCRB recursion is
right (against finite differences, brute-force information and exact rational arithmetic)."""

from __future__ import annotations

import ast
import math
from dataclasses import replace
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from isac_mission.records import SlotRecord, Trace, TraceWriter
from tests.support.independent_check import (
    bound_update,
    check_constraints,
    compare_pcrb,
    control_range_m,
    cv_model,
    jacobian,
    measurement,
    recompute_pcrb,
    uplink_rate_bps,
)

# ---------------------------------------------------------------------------------------------
# A small hand-built scenario: 2 BSs on the x axis, 2 UAVs between them, one target to the north.
# Every number is chosen so that each constraint holds with a clear margin (see the comments in
# the mutation tests for the margins each mutation crosses).

BETA0 = 7.26e-7
NOISE_W = 1e-16
GAMMA_TH = 12.59
DH = 100.0 - 15.0


def base_config(**changes: Any) -> dict[str, Any]:
    cfg: dict[str, Any] = {
        "M": 2,
        "K": 2,
        "dt": 1.0,
        "B": 20e6,
        "Pu": 0.1,
        "P_bs": 1.0,  # d_th about 24 km
        "noise_w": NOISE_W,
        "beta0": BETA0,
        "H": 100.0,
        "H_bs": 15.0,
        "gamma_th": GAMMA_TH,
        "r_th": 10e6,
        "n_a": 1,
        "v_max": 25.0,
        "d_safe": 30.0,
        "kappa": 0.5,
        "bs_xy": [[0.0, 0.0], [1000.0, 0.0]],
        "uav_start_xy": [[390.0, 300.0], [470.0, 300.0]],
        "P0": np.diag([100.0, 100.0, 4.0, 4.0]).tolist(),
    }
    cfg.update(changes)
    return cfg


def p_bs_for_range(d_th: float) -> float:
    """The BS power that makes the control range exactly d_th (14b)."""
    return (d_th**2 + DH**2) * NOISE_W * GAMMA_TH / BETA0


def record(slot: int, uav_xy: list[list[float]], target_pred: list[float], **kw: Any) -> SlotRecord:
    fields: dict[str, Any] = {
        "slot": slot,
        "method": "proposed",
        "status": "ok",
        "uav_xy": np.array(uav_xy),
        "eta": np.array([0.5, 0.5]),
        "assoc": np.array([0, 1]),
        "target_true": np.array(target_pred) + 1.0,
        "target_est": np.array(target_pred) + 0.5,
        "target_pred": np.array(target_pred),
        "r_diag": np.array([4.0, 9.0, 0.01, 0.04]),
        "pcrb_trace": 1.0,
        "solve_ms": 1.0,
        "P": np.eye(4),
        "J": np.eye(4),
    }
    fields.update(kw)
    return SlotRecord(**fields)


def valid_trace(config: dict[str, Any] | None = None) -> Trace:
    slots = [
        # each UAV moves 10 m per slot (limit 25 m); UAVs 60 m then 40 m apart (D_s = 30 m)
        record(1, [[400.0, 300.0], [460.0, 300.0]], [430.0, 600.0, 20.0, 0.0]),
        record(2, [[410.0, 300.0], [450.0, 300.0]], [450.0, 600.0, 20.0, 0.0]),
    ]
    return Trace(config=config or base_config(), slots=slots)


def mutate(trace: Trace, index: int, **changes: Any) -> Trace:
    slots = list(trace.slots)
    slots[index] = replace(slots[index], **changes)
    return Trace(config=trace.config, slots=slots)


def flagged(trace: Trace, **kw: Any) -> set[tuple[str, int, tuple[int, ...]]]:
    return {(v.constraint, v.slot, v.uavs) for v in check_constraints(trace, **kw)}


# ---------------------------------------------------------------------------------------------
# Constraints


def test_valid_trace_has_no_violation() -> None:
    assert check_constraints(valid_trace()) == []


def test_14a_low_share_breaks_the_rate_alone() -> None:
    # UAV 1 is 618 m from BS 1: full-band rate about 217 Mbit/s, so 1 % of the band is ~2 Mbit/s.
    got = flagged(mutate(valid_trace(), 0, eta=np.array([0.99, 0.01])))
    assert got == {("14a", 1, (1,))}


def test_14a_uses_a_relative_tolerance_of_1e_9() -> None:
    trace = valid_trace()
    q1 = trace.slots[0].uav_xy[1]
    full = uplink_rate_bps(1.0, math.dist(q1, (1000.0, 0.0)), trace.config)
    exact = 10e6 / full  # the share that meets R_th exactly
    at_limit = mutate(trace, 0, eta=np.array([1.0 - exact, exact]))
    assert flagged(at_limit) == set()
    below = mutate(trace, 0, eta=np.array([1.0 - exact * (1 - 1e-7), exact * (1 - 1e-7)]))
    assert flagged(below) == {("14a", 1, (1,))}


def test_14b_control_range_breaks_alone() -> None:
    # d_th = 520 m: UAV 0 is 500 m / 510 m from BS 0, UAV 1 549 m / 541 m from its nearest BS.
    cfg = base_config(P_bs=p_bs_for_range(520.0))
    assert control_range_m(cfg) == pytest.approx(520.0, rel=1e-12)
    assert flagged(valid_trace(cfg)) == {("14b", 1, (1,)), ("14b", 2, (1,))}


def test_14c_shares_not_summing_to_one_break_alone() -> None:
    got = flagged(mutate(valid_trace(), 1, eta=np.array([0.5, 0.4])))
    assert got == {("14c", 2, (0, 1))}


def test_14d_share_outside_unit_interval_breaks_alone() -> None:
    # sum is still 1; the negative share's rate is not checked (reported under 14d instead)
    got = flagged(mutate(valid_trace(), 0, eta=np.array([1.25, -0.25])))
    assert got == {("14d", 1, (0,)), ("14d", 1, (1,))}


def test_14e_two_uavs_on_a_capacity_one_bs_break_alone() -> None:
    # UAV 1 to BS 0 is 549 m: half the band still carries ~109 Mbit/s
    got = flagged(mutate(valid_trace(), 1, assoc=np.array([0, 0])))
    assert got == {("14e", 2, (0, 1))}


@pytest.mark.parametrize("bad", [2, -1])
def test_14fg_invalid_bs_index_breaks_alone(bad: int) -> None:
    got = flagged(mutate(valid_trace(), 0, assoc=np.array([0, bad])))
    assert got == {("14f/g", 1, (1,))}


def test_a_vehicle_outside_the_plan_is_exempt_from_14a_and_14fg_only() -> None:
    """BS -1 with share 0 marks a vehicle planned around (link lost): no link to check."""
    out = mutate(valid_trace(), 0, assoc=np.array([0, -1]), eta=np.array([1.0, 0.0]))
    assert flagged(out) == set()
    # ... but a share with no BS is still an invalid association,
    with_share = mutate(valid_trace(), 0, assoc=np.array([0, -1]), eta=np.array([0.5, 0.5]))
    assert flagged(with_share) == {("14f/g", 1, (1,))}
    # and separations still count: move it onto UAV 0.
    close = mutate(
        valid_trace(),
        0,
        assoc=np.array([0, -1]),
        eta=np.array([1.0, 0.0]),
        uav_xy=np.array([[400.0, 300.0], [410.0, 300.0]]),
    )
    assert ("14i", 1, (0, 1)) in flagged(close)


def test_14h_too_fast_breaks_alone() -> None:
    # UAV 0 moves 30 m west in slot 2 (limit 25 m); it stays 80 m from UAV 1
    got = flagged(mutate(valid_trace(), 1, uav_xy=np.array([[370.0, 300.0], [450.0, 300.0]])))
    assert got == {("14h", 2, (0,))}


def test_14h_first_slot_is_checked_against_the_start_positions() -> None:
    cfg = base_config(uav_start_xy=[[390.0, 300.0], [500.0, 300.0]])  # UAV 1 then moves 40 m
    assert flagged(valid_trace(cfg)) == {("14h", 1, (1,))}


def test_14i_uavs_too_close_break_alone() -> None:
    # D_s = 50 m: the UAVs are 60 m apart in slot 1, 40 m in slot 2; the target is >= 300 m away
    got = flagged(valid_trace(base_config(d_safe=50.0)))
    assert got == {("14i", 2, (0, 1))}


def test_14j_uav_too_close_to_predicted_target_breaks_alone() -> None:
    # predicted target 11 m from UAV 0 and 56 m from UAV 1
    got = flagged(mutate(valid_trace(), 0, target_pred=np.array([405.0, 310.0, 20.0, 0.0])))
    assert got == {("14j", 1, (0,))}


def test_distance_tolerance_is_tol_m_and_status_is_reported() -> None:
    # UAV 0 is 29.5 m from the predicted target: within 1 m of D_s = 30 m, not within 1e-6 m
    trace = mutate(
        valid_trace(), 0, target_pred=np.array([400.0, 329.5, 20.0, 0.0]), status="infeasible"
    )
    assert check_constraints(trace, tol_m=1.0) == []
    (violation,) = check_constraints(trace)
    assert violation.constraint == "14j"
    assert violation.status == "infeasible"
    assert violation.value == pytest.approx(29.5)
    assert violation.limit == 30.0
    assert "slot 1 (infeasible): 14j UAV 0" in str(violation)


def test_non_finite_position_is_a_violation() -> None:
    trace = mutate(valid_trace(), 1, uav_xy=np.array([[np.nan, 300.0], [450.0, 300.0]]))
    assert {"14a", "14b", "14h", "14i", "14j"} <= {v.constraint for v in check_constraints(trace)}


def test_missing_config_key_is_named() -> None:
    cfg = base_config()
    del cfg["n_a"]
    with pytest.raises(ValueError, match="'n_a'"):
        check_constraints(valid_trace(cfg))


def test_checker_reads_a_trace_file(tmp_path: Path) -> None:
    trace = mutate(valid_trace(), 1, eta=np.array([0.5, 0.4]))
    path = tmp_path / "run.jsonl"
    with TraceWriter(path, trace.config) as writer:
        for rec in trace.slots:
            writer.write_slot(rec)
    assert {v.constraint for v in check_constraints(path)} == {"14c"}


def test_checker_does_not_import_the_library_it_checks() -> None:
    source = Path(__file__).parents[1] / "support" / "independent_check.py"
    imported: set[str] = set()
    for node in ast.walk(ast.parse(source.read_text())):
        if isinstance(node, ast.Import):
            imported |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            imported.add(node.module)
    forbidden = ("isac_mission.model", "isac_mission.tracking", "isac_mission.planning")
    assert not [m for m in imported if m.startswith(forbidden)]
    assert {m for m in imported if m.startswith("isac_mission")} <= {"isac_mission.records"}


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
        uav_xy=UAVS,
        eta=np.full(3, 1 / 3),
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
                uav_xy=UAVS[[0, 2]],
                eta=np.array([0.5, 0.5]),
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
                uav_xy=uav,
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
