"""The independent trace checker, constraints: each of (14a)-(14j) is caught alone, with the
tolerances it states; the checker reads a trace file and imports nothing it checks."""

from __future__ import annotations

import ast
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from isac_mission.records import Trace, TraceWriter
from tests.support.checker_cases import (
    base_config,
    flagged,
    mutate,
    p_bs_for_range,
    valid_trace,
)
from tests.support.independent.constraints import (
    check_constraints,
    control_range_m,
    uplink_rate_bps,
)

# ---------------------------------------------------------------------------------------------
# Constraints


def test_valid_trace_has_no_violation() -> None:
    assert check_constraints(valid_trace()) == []


def test_14a_low_share_breaks_the_rate_alone() -> None:
    # UAV 1 is 618 m from BS 1: full-band rate about 217 Mbit/s, so 1 % of the band is ~2 Mbit/s.
    got = flagged(mutate(valid_trace(), 0, bandwidth_share=np.array([0.99, 0.01])))
    assert got == {("14a", 1, (1,))}


def test_14a_uses_a_relative_tolerance_of_1e_9() -> None:
    trace = valid_trace()
    q1 = trace.slots[0].uav_xy_m[1]
    full = uplink_rate_bps(1.0, math.dist(q1, (1000.0, 0.0)), trace.config)
    exact = 10e6 / full  # the share that meets R_th exactly
    at_limit = mutate(trace, 0, bandwidth_share=np.array([1.0 - exact, exact]))
    assert flagged(at_limit) == set()
    below = mutate(
        trace, 0, bandwidth_share=np.array([1.0 - exact * (1 - 1e-7), exact * (1 - 1e-7)])
    )
    assert flagged(below) == {("14a", 1, (1,))}


def test_14b_control_range_breaks_alone() -> None:
    # d_th = 520 m: UAV 0 is 500 m / 510 m from BS 0, UAV 1 549 m / 541 m from its nearest BS.
    cfg = base_config(P_bs=p_bs_for_range(520.0))
    assert control_range_m(cfg) == pytest.approx(520.0, rel=1e-12)
    assert flagged(valid_trace(cfg)) == {("14b", 1, (1,)), ("14b", 2, (1,))}


def test_14c_shares_not_summing_to_one_break_alone() -> None:
    got = flagged(mutate(valid_trace(), 1, bandwidth_share=np.array([0.5, 0.4])))
    assert got == {("14c", 2, (0, 1))}


def test_nobody_served_is_no_14c_but_a_share_left_over_is() -> None:
    """An operator's hold of the whole fleet: every BS -1 and every share 0 (docs/trace.md,
    `operator hold`): no bandwidth to share. One vehicle still served keeps 14c."""
    held = mutate(valid_trace(), 1, assoc=np.array([-1, -1]), bandwidth_share=np.zeros(2))
    assert flagged(held) == set()
    half = mutate(valid_trace(), 1, assoc=np.array([0, -1]), bandwidth_share=np.array([0.5, 0.0]))
    assert ("14c", 2, (0, 1)) in flagged(half)


def test_14d_share_outside_unit_interval_breaks_alone() -> None:
    # sum is still 1; the negative share's rate is not checked (reported under 14d instead)
    got = flagged(mutate(valid_trace(), 0, bandwidth_share=np.array([1.25, -0.25])))
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
    out = mutate(valid_trace(), 0, assoc=np.array([0, -1]), bandwidth_share=np.array([1.0, 0.0]))
    assert flagged(out) == set()
    # ... but a share with no BS is still an invalid association,
    with_share = mutate(
        valid_trace(), 0, assoc=np.array([0, -1]), bandwidth_share=np.array([0.5, 0.5])
    )
    assert flagged(with_share) == {("14f/g", 1, (1,))}
    # and separations still count: move it onto UAV 0.
    close = mutate(
        valid_trace(),
        0,
        assoc=np.array([0, -1]),
        bandwidth_share=np.array([1.0, 0.0]),
        uav_xy_m=np.array([[400.0, 300.0], [410.0, 300.0]]),
    )
    assert ("14i", 1, (0, 1)) in flagged(close)


def test_14h_too_fast_breaks_alone() -> None:
    # UAV 0 moves 30 m west in slot 2 (limit 25 m); it stays 80 m from UAV 1
    got = flagged(mutate(valid_trace(), 1, uav_xy_m=np.array([[370.0, 300.0], [450.0, 300.0]])))
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
    trace = mutate(valid_trace(), 1, uav_xy_m=np.array([[np.nan, 300.0], [450.0, 300.0]]))
    assert {"14a", "14b", "14h", "14i", "14j"} <= {v.constraint for v in check_constraints(trace)}


@pytest.mark.parametrize("status", ["unobserved", "held"])
def test_an_unobserved_position_is_skipped_and_14h_spans_the_gap(status: str) -> None:
    """A null position in a slot the ground did not plan is not a violation; the next known
    position is held to V_max dt per slot since the last known one (2 slots: 50 m)."""
    trace = valid_trace()
    gap = replace(trace.slots[1], slot=2, status=status, uav_xy_m=np.full((2, 2), np.nan))
    # 40 m in the two slots since slot 1: within 2 x 25 m, beyond 25 m
    third = replace(trace.slots[1], slot=3, uav_xy_m=np.array([[440.0, 300.0], [500.0, 300.0]]))
    assert check_constraints(Trace(trace.config, [trace.slots[0], gap, third])) == []
    # 60 m (UAV 0) in those two slots: over 50 m, flagged at slot 3 against slot 1
    far = replace(third, uav_xy_m=np.array([[460.0, 300.0], [500.0, 300.0]]))
    got = flagged(Trace(trace.config, [trace.slots[0], gap, far]))
    assert got == {("14h", 3, (0,))}


def test_a_null_position_in_a_planned_slot_is_still_a_violation() -> None:
    trace = mutate(valid_trace(), 1, uav_xy_m=np.array([[np.nan, np.nan], [450.0, 300.0]]))
    assert {"14b", "14h", "14j"} <= {v.constraint for v in check_constraints(trace)}


def test_missing_config_key_is_named() -> None:
    cfg = base_config()
    del cfg["n_a"]
    with pytest.raises(ValueError, match="'n_a'"):
        check_constraints(valid_trace(cfg))


def test_checker_reads_a_trace_file(tmp_path: Path) -> None:
    trace = mutate(valid_trace(), 1, bandwidth_share=np.array([0.5, 0.4]))
    path = tmp_path / "run.jsonl"
    with TraceWriter(path, trace.config) as writer:
        for rec in trace.slots:
            writer.write_slot(rec)
    assert {v.constraint for v in check_constraints(path)} == {"14c"}


def test_checker_does_not_import_the_library_it_checks() -> None:
    package = Path(__file__).parents[1] / "support" / "independent"
    imported: set[str] = set()
    for source in sorted(package.glob("*.py")):
        for node in ast.walk(ast.parse(source.read_text())):
            if isinstance(node, ast.Import):
                imported |= {alias.name for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module:
                imported.add(node.module)
    forbidden = ("isac_mission.model", "isac_mission.tracking", "isac_mission.planning")
    assert not [m for m in imported if m.startswith(forbidden)]
    assert {m for m in imported if m.startswith("isac_mission")} <= {"isac_mission.records"}
