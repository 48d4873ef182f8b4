"""The horizon on its reduced pair sets (planning/pairs.py): the same plans as on every pair, the
fleet's order undone, a slot whose close pairs fit no band counted as a fallback."""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario, parse_scenario
from isac_mission.experiment.closed_loop import draw_run_noise, record_slot_inputs
from isac_mission.planning.horizon import horizon_nlp, kit_pair_bands
from isac_mission.planning.horizon_problem import horizon_weights
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.pairs import band_pair_count
from isac_mission.planning.slot import SlotInput, plan_slot

CENTRES_XY_M = ((700.0, 700.0), (1500.0, 2300.0), (2300.0, 700.0))


def _clusters(per_cluster: int, pair_band: int) -> Scenario:
    """The default scenario with three clusters of per_cluster UAVs 80 m apart (far enough from
    each other that no pair of two clusters is within reach), the paper's bandwidth per UAV."""
    start = [[x + dx, y] for x, y in CENTRES_XY_M for dx in 80.0 * np.arange(per_cluster)]
    return parse_scenario(
        {
            "timing": {"duration_s": 12},
            "radio": {"bandwidth_hz": 20e6 * len(start) / 3, "bs_capacity": 3},
            "uavs": {"start_xy_m": start},
            "planner": {"horizon": {"pair_band": pair_band}},
        },
        f"clusters of {per_cluster}",
    )


def _input(s: Scenario, slot: int = 1) -> SlotInput:
    return record_slot_inputs(s, "proposed", draw_run_noise(s, 3), SolverKit(s))[1][slot]


def test_the_band_problem_has_the_rows_of_its_pairs_only() -> None:
    s = _clusters(3, pair_band=2)
    kit = SolverKit(s)
    assert kit_pair_bands(kit) == (2, 4)
    full, band = horizon_nlp(kit), horizon_nlp(kit, 2)
    rows_per_pair = s.planner.horizon.length * s.planner.horizon.leg_samples
    dropped = s.M * (s.M - 1) // 2 - band_pair_count(s.M, 2)
    assert len(full.lbg) - len(band.lbg) == dropped * rows_per_pair


def test_a_reduced_problem_plans_what_the_full_one_plans() -> None:
    """Three clusters of three: the pairs within reach fit band 2 in the banded order, and the
    band problem's plan is the full problem's (the dropped rows are implied by the others), with
    every UAV's waypoint its own (the order undone)."""
    reduced = _clusters(3, pair_band=2)
    full = _clusters(3, pair_band=8)
    inp = _input(reduced)
    plan_reduced = plan_slot(inp, SolverKit(reduced), "horizon")
    plan_full = plan_slot(inp, SolverKit(full), "horizon")
    assert plan_reduced.report.fallback == plan_full.report.fallback == ""
    h_reduced, h_full = plan_reduced.horizon, plan_full.horizon
    assert h_reduced is not None and h_full is not None
    cfg = reduced.planner.horizon
    weights = horizon_weights(cfg.length, cfg.discount, cfg.terminal_weight)
    # The same problem, but IPOPT stops at its barrier target (mu_target), where the full
    # problem's dropped rows still add their small barrier terms: the objectives agree to that
    # offset (the waypoints less: the objective is flat along some of them).
    value_reduced, value_full = weights @ h_reduced.pcrb_trace, weights @ h_full.pcrb_trace
    assert value_reduced == pytest.approx(value_full, rel=1e-3)
    step_m = np.linalg.norm(plan_reduced.uav_xy_m - inp.prev_xy_m, axis=1)
    assert np.all(step_m <= reduced.v_max * reduced.dt + 1e-6)


def test_close_pairs_that_fit_no_band_fly_the_per_slot_plan_counted() -> None:
    """Clusters of four: each a clique of pairs within reach, bandwidth 3, wider than the bands
    (1, 2) of pair_band 1."""
    s = _clusters(4, pair_band=1)
    kit = SolverKit(s)
    assert kit_pair_bands(kit) == (1, 2)
    plan = plan_slot(_input(s), kit, "horizon")
    assert plan.report.fallback == "horizon: pairs beyond the band"
    assert "need a band of 3" in plan.report.reason
