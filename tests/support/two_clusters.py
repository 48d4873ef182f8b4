"""The two-clusters scene of tests/numerics/test_decomposed.py, flown over several slots, and a
group solve that kills its worker process (for the planner's Dask cluster,
isac_mission/planner_cluster.py).

Two targets SEPARATION_M apart flying north at 10 m/s, each with two UAVs 200 m off it and a BS
below it, mirror-symmetric: the decomposed horizon plans them as two groups of two UAVs.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from isac_mission.config import Scenario, load_scenario, parse_scenario
from isac_mission.planner_cluster import solve_on_worker
from isac_mission.planning.decomposed import GroupJob
from isac_mission.planning.problem import SlotInput
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.imm import ImmBelief, ImmPath, imm_model, imm_start
from isac_mission.types import FloatArray, Gaussian, SlotPlan

SEPARATION_M = 2500.0
TARGET_SPEED_MPS = 10.0


def scenario(
    separation_m: float = SEPARATION_M, decompose: str = "targets", **planner: Any
) -> Scenario:
    """The two-clusters scenario (as tests/numerics/test_decomposed.py `_scenario`)."""
    x1, x2 = 1000.0, 1000.0 + separation_m
    return parse_scenario(
        {
            "timing": {"duration_s": 5},
            "area": {"size_m": [separation_m + 2000.0, 2000.0]},
            "radio": {"bs_capacity": 3},
            "base_stations": {"count": 2, "xy_m": [[x1, 300.0], [x2, 300.0]]},
            "uavs": {
                "start_xy_m": [[x1 - 200, 900], [x1 + 200, 900], [x2 + 200, 900], [x2 - 200, 900]]
            },
            "targets": [{"initial_state": [x1, 1000.0, 0.0, TARGET_SPEED_MPS]}],
            "planner": {
                "horizon": {"length": 3, "decompose": decompose, **planner.pop("horizon", {})},
                **planner,
            },
        },
        f"two clusters {separation_m:g} m apart",
    )


def turning_path(state: FloatArray, cov: FloatArray, turn_rate_radps: float) -> ImmPath:
    """An IMM prediction (the `manoeuvring` scenario's modes) of a target at state [4] with
    covariance cov [4, 4] whose every mode believes it turns at turn_rate_radps (rad/s)."""
    s = load_scenario("manoeuvring")
    assert s.imm is not None
    model = imm_model(s.imm, s.dt)
    start = imm_start(model, Gaussian(x=np.asarray(state, dtype=float), P=cov))
    means = start.means.copy()
    means[:, 4] = turn_rate_radps
    return ImmPath(model, ImmBelief(means, start.covariances, start.probabilities))


def targets_at(
    s: Scenario, slot: int, separation_m: float = SEPARATION_M, manoeuvre: bool = False
) -> tuple[TargetBelief, ...]:
    """The two targets' beliefs predicted to the end of slot `slot` (1-based): their true
    states (north at TARGET_SPEED_MPS), the prior information P0^-1; with `manoeuvre`, each
    with an IMM path turning at 0.05 rad/s (`turning_path`: a `PathOffsets` to pickle)."""
    J = np.asarray(np.linalg.inv(s.P0), dtype=np.float64)
    y = 1000.0 + TARGET_SPEED_MPS * s.dt * (slot - 1)
    out = []
    for i, x in enumerate((1000.0, 1000.0 + separation_m)):
        state = np.array([x, y, 0.0, TARGET_SPEED_MPS])
        path = turning_path(state, s.P0, 0.2) if manoeuvre else None
        out.append(TargetBelief(state, J, s.motion, track_id=i + 1, manoeuvre=path))
    return tuple(out)


def first_input(
    s: Scenario, separation_m: float = SEPARATION_M, manoeuvre: bool = False
) -> SlotInput:
    """Slot 1's input: the UAVs at their start points, equal shares, no association yet
    (targets as `targets_at`)."""
    return SlotInput(
        prev_xy_m=s.uav_start_xy,
        prev_bandwidth_share=np.full(s.M, 1.0 / s.M),
        prev_bs_of_uav=None,
        targets=targets_at(s, 1, separation_m, manoeuvre),
    )


def next_input(
    s: Scenario,
    slot: int,
    plan: SlotPlan,
    separation_m: float = SEPARATION_M,
    manoeuvre: bool = False,
) -> SlotInput:
    """Slot `slot`'s input after `plan` (last slot's) was flown exactly (targets as
    `targets_at`)."""
    return SlotInput(
        prev_xy_m=plan.uav_xy_m,
        prev_bandwidth_share=plan.bandwidth_share,
        prev_bs_of_uav=plan.bs_of_uav,
        targets=targets_at(s, slot, separation_m, manoeuvre),
        prev_velocity_mps=plan.uav_velocity_mps,
        prev_plan=plan,
    )


def die_if_flagged(flag: str, index: int, job: GroupJob) -> SlotPlan:
    """A worker's group solve that kills its own process (exit status 1, no cleanup: a crash)
    when the job is group `index` of its slot and the file `flag` exists; else the real one
    (`planner_cluster.solve_on_worker`)."""
    if job.index == index and Path(flag).exists():
        os._exit(1)
    return solve_on_worker(job)


def two_targets_config(duration_s: float) -> dict[str, Any]:
    """The two clusters as a scenario mapping with both targets in the scene (tracked, not given:
    `simulate`, `run` and `serve` plan them as two groups), `duration_s` seconds long."""
    return {
        "mission_id": "two-clusters",
        "timing": {"duration_s": duration_s},
        "area": {"size_m": [4500, 2000]},
        "radio": {"bs_capacity": 3},
        "base_stations": {"count": 2, "xy_m": [[1000, 300], [3500, 300]]},
        "uavs": {"start_xy_m": [[800, 900], [1200, 900], [3700, 900], [3300, 900]]},
        "targets": [
            {"name": "west", "initial_state": [1000, 1000, 0, 10]},
            {"name": "east", "initial_state": [3500, 1000, 0, 10]},
        ],
        "planner": {"horizon": {"length": 3, "decompose": "targets"}},
    }


def assert_same_plan(a: SlotPlan, b: SlotPlan) -> None:
    """Positions, shares, BSs, end velocities, the bound and the horizon: exactly equal, and the
    same fallback."""
    np.testing.assert_array_equal(a.uav_xy_m, b.uav_xy_m)
    np.testing.assert_array_equal(a.bandwidth_share, b.bandwidth_share)
    np.testing.assert_array_equal(a.bs_of_uav, b.bs_of_uav)
    assert a.pcrb_trace == b.pcrb_trace
    assert (a.uav_velocity_mps is None) == (b.uav_velocity_mps is None)
    if a.uav_velocity_mps is not None and b.uav_velocity_mps is not None:
        np.testing.assert_array_equal(a.uav_velocity_mps, b.uav_velocity_mps)
    assert a.horizon is not None and b.horizon is not None
    np.testing.assert_array_equal(a.horizon.uav_xy_m, b.horizon.uav_xy_m)
    np.testing.assert_array_equal(a.horizon.bandwidth_share, b.horizon.bandwidth_share)
    np.testing.assert_array_equal(a.horizon.pcrb_trace, b.horizon.pcrb_trace)
    assert a.report.fallback == b.report.fallback
