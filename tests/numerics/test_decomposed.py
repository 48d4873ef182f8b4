"""The receding horizon decomposed by targets (planning/decomposed.py, `planner.horizon.decompose:
targets`): the grouping on crafted geometries, the decomposed plan against each group planned
centrally on its own and against the whole fleet planned centrally, the fallback where the
recombined plan fails the exact check, the one-group path, the warm start across slots, and
the config key."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest

from isac_mission.config import Scenario, parse_scenario
from isac_mission.config.sections import HorizonConfig
from isac_mission.errors import ConfigError
from isac_mission.model.channel import rate
from isac_mission.planning import decomposed, horizon_nlp
from isac_mission.planning.decomposed import (
    DECOMPOSED_KEY,
    DecomposedHorizon,
    Group,
    group_by_targets,
    slot_groups,
)
from isac_mission.planning.horizon import proposed_plan
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.problem import slot_association
from isac_mission.planning.slot import SlotInput, plan_slot
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.types import SlotPlan
from tests.support.two_clusters import scenario as _scenario

REACH_M = 75.0
"""A UAV's reach over the horizon in the crafted geometries (3 slots at 25 m/s)."""

PAIR_M = 33.0
"""The UAV-UAV rows' distance in the crafted geometries (D_s + 2 e + chord), m."""


def _groups(
    uav_xy: Sequence[Sequence[float]],
    target_xy: Sequence[Sequence[float]],
    clearance_m: float = 40.0,
    weight: list[float] | None = None,
) -> tuple[Group, ...]:
    uav = np.array(uav_xy, dtype=float)
    return group_by_targets(
        uav,
        np.full(len(uav), REACH_M),
        PAIR_M,
        np.array(target_xy, dtype=float),
        np.full(len(target_xy), clearance_m),
        target_weight=None if weight is None else np.array(weight),
    )


def test_two_far_apart_clusters_are_two_groups() -> None:
    groups = _groups(
        [[3300, 900], [500, 900], [900, 900], [3000, 900]], [[3250, 1000], [700, 1000]]
    )
    # Ordered by the smallest UAV index; targets are indices into the input's.
    assert groups == (Group((0, 3), (0,)), Group((1, 2), (1,)))


def test_clusters_within_reach_are_merged() -> None:
    # UAV 1 (target 0's) and UAV 2 (target 1's) 150 m apart: within the pair distance (33 m)
    # plus both reaches (2 x 75 m) plus 1 m of slack.
    near = _groups([[500, 900], [900, 900], [1050, 900], [1500, 900]], [[600, 1000], [1400, 1000]])
    assert near == (Group((0, 1, 2, 3), (0, 1)),)
    # 200 m apart: out of reach, two groups.
    far = _groups([[500, 900], [900, 900], [1100, 900], [1500, 900]], [[600, 1000], [1400, 1000]])
    assert far == (Group((0, 1), (0,)), Group((2, 3), (1,)))


def test_a_uav_within_reach_of_another_groups_target_merges_them() -> None:
    # UAV 1 is nearest to target 0 (100 m) and 110 m from target 1 (UAV 3's): within its reach
    # plus target 1's clearance (75 + 40 + 1 m), so the two groups couple.
    uavs = [[0, 0], [1000, 0], [3000, 0], [1000, 600]]
    groups = _groups(uavs, [[900, 0], [1000, 110], [3000, 100]])
    assert groups == (Group((0, 1, 3), (0, 1)), Group((2,), (2,)))
    # 130 m: out of reach.
    apart = _groups(uavs, [[900, 0], [1000, 130], [3000, 100]])
    assert apart == (Group((0, 1), (0,)), Group((2,), (2,)), Group((3,), (1,)))


def test_targets_whose_clearances_overlap_are_merged() -> None:
    # Each target has its own UAV far away, the targets 70 m apart (< 2 x 40 m clearance).
    groups = _groups([[0, 0], [3000, 0]], [[1000, 0], [1070, 0]], clearance_m=40.0)
    assert groups == (Group((0, 1), (0, 1)),)
    apart = _groups([[0, 0], [3000, 0]], [[1000, 0], [1200, 0]], clearance_m=40.0)
    assert apart == (Group((0,), (0,)), Group((1,), (1,)))


def test_a_uav_far_from_every_target_joins_its_nearest_targets_group() -> None:
    groups = _groups(
        [[500, 900], [900, 900], [3000, 900], [3300, 900], [2600, 2900]],
        [[700, 1000], [3250, 1000]],
    )
    assert groups == (Group((0, 1), (0,)), Group((2, 3, 4), (1,)))


def test_a_target_nearest_to_no_uav_joins_its_nearest_uavs_group() -> None:
    # Target 4 is no UAV's nearest: it joins UAV 1's group (its nearest UAV); target 3, of
    # weight 0, draws no UAV (UAV 1 is 250 m from it, 600 m from target 1) and joins it too.
    groups = _groups(
        [[0, 0], [1000, 0], [3000, 0]],
        [[0, 300], [1000, 600], [3000, 300], [1000, 250], [1000, 900]],
        weight=[1.0, 1.0, 1.0, 0.0, 1.0],
    )
    assert groups == (Group((0,), (0,)), Group((1,), (1, 3, 4)), Group((2,), (2,)))


# The two-cluster scenario: two targets SEPARATION_M apart, each with two UAVs 200 m off it and
# a BS below it, mirror-symmetric about the middle (so the centralized optimum splits the band
# 1/2 : 1/2 at every horizon slot); the BSs' capacity 3 does not bind (2 UAVs each).


def _input(s: Scenario, separation_m: float = 2500.0) -> SlotInput:
    J = np.asarray(np.linalg.inv(s.P0), dtype=np.float64)
    targets = tuple(
        TargetBelief(np.array([x, 1000.0, 0.0, 10.0]), J, s.motion, track_id=i + 1)
        for i, x in enumerate((1000.0, 1000.0 + separation_m))
    )
    return SlotInput(
        prev_xy_m=s.uav_start_xy,
        prev_bandwidth_share=np.full(s.M, 1.0 / s.M),
        prev_bs_of_uav=None,
        targets=targets,
    )


def _group_reference(
    s: Scenario, inp: SlotInput, uavs: list[int], target: int, budget: float
) -> SlotPlan:
    """Group `uavs` with its target planned centrally (the plain horizon) on its own scenario,
    written out here: its UAVs only, the band B * budget, the fleet's association kept."""
    assoc = slot_association(inp, SolverKit(s))
    planner = s.planner.model_copy(
        update={
            "association": "keep",
            "horizon": s.planner.horizon.model_copy(update={"decompose": "none"}),
        }
    )
    sub = s.with_changes(
        M=len(uavs), uav_start_xy=s.uav_start_xy[uavs], B=s.B * budget, planner=planner
    )
    sub_inp = SlotInput(
        prev_xy_m=inp.prev_xy_m[uavs],
        prev_bandwidth_share=np.full(len(uavs), 1.0 / len(uavs)),
        prev_bs_of_uav=assoc[uavs],
        targets=(inp.targets[target],),
    )
    return plan_slot(sub_inp, SolverKit(sub), "horizon")


@pytest.mark.parametrize("vehicle_model", [False, True])
def test_the_decomposed_plan_is_each_group_planned_centrally_on_its_own(
    vehicle_model: bool,
) -> None:
    """Two targets 2.5 km apart, each with its two UAVs: two groups, each with half the band.

    The reference is each group planned by the plain (centralized) horizon on its own
    scenario: its two UAVs, its target, the band B / 2, the fleet's association. That is the
    problem the decomposition claims to solve: the full fleet's problem couples the groups
    through the shares' sum over the whole fleet (and, negligibly, through the information a
    UAV gathers on the far target), so it equals the decomposed one only where the budgets are
    the full problem's optimal split (the next test). So the same waypoints (to 1e-6 m), the
    shares the reference's times 1/2, the fleet's shares summing to 1 and every UAV's rate at
    least R_th after the scaling, and the plan passes as the horizon's own (no fallback). On
    the paper's kinematics and on the vehicle model (the end velocities too)."""
    s = _scenario(vehicle_model=vehicle_model)
    inp = _input(s)
    plan = plan_slot(inp, SolverKit(s), "horizon")
    assert plan.report.fallback == "" and plan.report.status == "ok"
    assert plan.report.polish.startswith("horizon decomposed into 2 groups")
    assert plan.horizon is not None and plan.horizon.duals is None
    for uavs, target in (([0, 1], 0), ([2, 3], 1)):
        ref = _group_reference(s, inp, uavs, target, 0.5)
        assert ref.report.fallback == "" and ref.horizon is not None
        np.testing.assert_allclose(plan.uav_xy_m[uavs], ref.uav_xy_m, rtol=0, atol=1e-6)
        np.testing.assert_allclose(plan.horizon.uav_xy_m[:, uavs], ref.horizon.uav_xy_m, atol=1e-6)
        np.testing.assert_allclose(
            plan.bandwidth_share[uavs], 0.5 * ref.bandwidth_share, rtol=0, atol=1e-9
        )
        np.testing.assert_allclose(
            plan.horizon.bandwidth_share[:, uavs], 0.5 * ref.horizon.bandwidth_share, atol=1e-9
        )
        np.testing.assert_array_equal(plan.bs_of_uav[uavs], ref.bs_of_uav)
        if vehicle_model:
            assert plan.uav_velocity_mps is not None and ref.uav_velocity_mps is not None
            np.testing.assert_allclose(
                plan.uav_velocity_mps[uavs], ref.uav_velocity_mps, rtol=0, atol=1e-6
            )
        else:
            assert plan.uav_velocity_mps is None
    assert float(plan.bandwidth_share.sum()) == pytest.approx(1.0, abs=1e-12)
    serving = s.bs_xy[plan.bs_of_uav]
    distance = np.linalg.norm(plan.uav_xy_m - serving, axis=1)
    assert np.all(rate(plan.bandwidth_share, distance, s.dH, s.rho0, s.B) >= s.r_th)


@pytest.mark.parametrize(("separation_m", "atol_m"), [(2500.0, 1e-2), (10000.0, 1e-4)])
def test_the_decomposed_plan_is_the_whole_fleets_where_the_budgets_are_its_split(
    monkeypatch: pytest.MonkeyPatch, separation_m: float, atol_m: float
) -> None:
    """The whole fleet planned centrally (decompose none) against the decomposition given the
    centralized plan's split of the band, 1/2 per group at every horizon slot (checked: the
    geometry is mirror-symmetric), both solved to a tight barrier (mu_target 1e-11: at the
    default 3e-5 the two plans differ by about 2.5 cm because the full problem's
    non-binding cross-group rows still add their barrier terms). What is left is the
    information each UAV gathers on the far target, which the decomposition drops: a (200 m /
    separation)^4 fraction of the near one's range information, so the waypoints agree to
    3.6 mm at 2.5 km and 12 um at 10 km (measured), falling with the separation's fourth
    power, and the horizon objectives to 1e-5."""
    monkeypatch.setitem(horizon_nlp.IPOPT_OPTIONS, "mu_target", 1e-11)
    monkeypatch.setitem(horizon_nlp.IPOPT_OPTIONS, "tol", 1e-10)
    s = _scenario(separation_m, horizon={"max_iterations": 300})
    central = _scenario(separation_m, "none", horizon={"max_iterations": 300})
    inp = _input(s, separation_m)
    reference = plan_slot(inp, SolverKit(central), "horizon")
    assert reference.report.fallback == "" and reference.horizon is not None
    split = reference.horizon.bandwidth_share[:, :2].sum(axis=1)
    np.testing.assert_allclose(split, 0.5, atol=1e-5)
    plan = plan_slot(inp, SolverKit(s), "horizon")
    assert plan.report.fallback == "" and plan.horizon is not None
    np.testing.assert_allclose(plan.horizon.uav_xy_m, reference.horizon.uav_xy_m, atol=atol_m)
    np.testing.assert_allclose(
        plan.horizon.bandwidth_share, reference.horizon.bandwidth_share, atol=1e-5
    )
    weights = np.array([1.0, 1.0, 6.0])  # horizon_weights(3, 1, 6)
    assert weights @ plan.horizon.pcrb_trace == pytest.approx(
        weights @ reference.horizon.pcrb_trace, rel=1e-5
    )


def _crossing_input(s: Scenario) -> SlotInput:
    """UAV 0 with its target 290 m east, UAV 2 36 m from it (north-east, just outside the 32 m
    the UAVs keep) with its target 250 m west of UAV 0: planned apart, each group moves its UAV
    across the other's path (found by trying UAV 2 around UAV 0)."""
    J = np.asarray(np.linalg.inv(s.P0), dtype=np.float64)
    targets = tuple(
        TargetBelief(np.array([x, 900.0, 0.0, 0.0]), J, s.motion, track_id=i + 1)
        for i, x in enumerate((1290.0, 750.0))
    )
    return SlotInput(
        prev_xy_m=np.array([[1000.0, 900.0], [1500.0, 900.0], [1031.0, 918.0], [500.0, 900.0]]),
        prev_bandwidth_share=np.full(4, 0.25),
        prev_bs_of_uav=None,
        targets=targets,
    )


def test_a_recombined_plan_that_fails_the_exact_check_flies_the_per_slot_plan(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Two UAVs 36 m apart, each of another target: the grouping merges them (within reach),
    so the one group is the centralized horizon. Forced into two groups (slot_groups
    replaced), each group plans without the other's UAV and the recombined plan breaks 14i:
    the slot flies the centralized per-slot plan (feasible here), its reason naming 14i."""
    s = _scenario()
    inp = _crossing_input(s)
    kit = SolverKit(s)
    assert slot_groups(s, inp, np.zeros((4, 2))) == (Group((0, 1, 2, 3), (0, 1)),)
    forced = (Group((0, 1), (0,)), Group((2, 3), (1,)))
    monkeypatch.setattr(decomposed, "slot_groups", lambda *_: forced)
    plan = plan_slot(inp, kit, "horizon")
    assert plan.report.fallback == "horizon: decomposed answer infeasible"
    assert plan.report.reason.startswith("horizon: decomposed answer violates 14i")
    per_slot = proposed_plan(inp, kit)
    np.testing.assert_array_equal(plan.uav_xy_m, per_slot.uav_xy_m)
    np.testing.assert_array_equal(plan.bandwidth_share, per_slot.bandwidth_share)
    assert plan.horizon is None and plan.report.status == "ok"


def test_one_group_is_the_centralized_horizon_exactly() -> None:
    """Where the grouping merges every UAV into one group, the plan is the plain horizon's,
    to the bit (the existing code, called unchanged)."""
    inp = _crossing_input(_scenario())
    plans = [
        plan_slot(inp, SolverKit(_scenario(decompose=d)), "horizon") for d in ("targets", "none")
    ]
    np.testing.assert_array_equal(plans[0].uav_xy_m, plans[1].uav_xy_m)
    np.testing.assert_array_equal(plans[0].bandwidth_share, plans[1].bandwidth_share)
    assert plans[0].report.polish == plans[1].report.polish


def test_the_next_slot_starts_from_the_recombined_horizon_with_the_sub_kits_kept() -> None:
    """Two slots: the second plans each group from last slot's horizon shifted (restricted to
    its UAVs, its shares renormalised), and both groups (same size, same budget) use one
    sub-kit, built once."""
    s = _scenario()
    kit = SolverKit(s)
    inp = _input(s)
    first = plan_slot(inp, kit, "horizon")
    assert first.report.fallback == ""
    targets = tuple(
        TargetBelief(
            b.state_pred + np.array([0.0, 10.0, 0.0, 0.0]) * s.dt,
            b.prior_information,
            b.motion,
            track_id=b.track_id,
        )
        for b in inp.targets
    )
    second_inp = SlotInput(
        prev_xy_m=first.uav_xy_m,
        prev_bandwidth_share=first.bandwidth_share,
        prev_bs_of_uav=first.bs_of_uav,
        targets=targets,
        prev_plan=first,
    )
    second = plan_slot(second_inp, kit, "horizon")
    assert second.report.fallback == ""
    assert second.report.polish.count("from the shifted horizon alone") == 2
    planner = kit.built(DECOMPOSED_KEY, DecomposedHorizon)
    assert planner.kit_count == 1


def test_the_key_parses_defaults_to_none_and_is_left_out_of_the_dumped_config() -> None:
    assert HorizonConfig().decompose == "none"
    default = parse_scenario({}, "default")
    assert default.planner.horizon.decompose == "none"
    assert "decompose" not in default.trace_config()["planner"]["horizon"]
    s = parse_scenario({"planner": {"horizon": {"decompose": "targets"}}}, "set")
    assert s.planner.horizon.decompose == "targets"
    assert s.trace_config()["planner"]["horizon"]["decompose"] == "targets"
    with pytest.raises(ConfigError, match=r"planner\.horizon\.decompose: Input should be 'none'"):
        parse_scenario({"planner": {"horizon": {"decompose": "clusters"}}}, "bad")


def test_a_renewed_kit_with_another_rate_plans_its_groups_at_that_rate() -> None:
    """An operator's new R_th (the fleet kit renewed, sharing its built problems and so this
    planner): the groups' sub-kit is renewed with it, not rebuilt, and every UAV's rate on the
    recombined plan meets the new R_th."""
    s = _scenario()
    kit = SolverKit(s)
    inp = _input(s)
    plan_slot(inp, kit, "horizon")
    planner = kit.built(DECOMPOSED_KEY, DecomposedHorizon)
    faster = s.with_changes(r_th=3 * s.r_th)
    plan = plan_slot(inp, kit.renewed(faster), "horizon")
    assert plan.report.fallback == "" and planner.kit_count == 1
    distance = np.linalg.norm(plan.uav_xy_m - s.bs_xy[plan.bs_of_uav], axis=1)
    assert np.all(rate(plan.bandwidth_share, distance, s.dH, s.rho0, s.B) >= faster.r_th)
