"""Live missions against a target that manoeuvres at the scenario's bound: no telemetry sample
closer than D_s to the true target (docs/model.md, "Safety").

Pursuit: the target starts 900 m from UAV 0, flying at 30 m/s (faster than the UAVs) straight at
it, and turns toward where the UAV would be (on the offline plan of the same mission) at up to
a_T = `target_motion.max_accel_mps2` all the way (tests/support/soak.py, `pursuit_path`); the
world flies that path. The offline twin of this mission is asserted too, along the flown legs.

Racetrack: config/manoeuvring.yaml (six UAVs, the interacting multiple model) with its target
flying laps that turn at a_T = 4 m/s^2 and change speed between 10 and 30 m/s (`racetrack_legs`),
for --soak-slots slots (240 by default, 3.4 laps; 3600 at full size), the live default method.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from isac_mission.config import Scenario, load_scenario
from isac_mission.config.live_settings import LiveSettings
from isac_mission.experiment.closed_loop import SlotOutcome, draw_run_noise, run_closed_loop
from isac_mission.model.vehicle import hermite_position
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method
from tests.support.soak import pursuit_path, racetrack_lap_s, run_soak, soak_scenario

ROOT = Path(__file__).resolve().parents[2]
TARGET_SPEED_MPS = 30.0


def pursuit_scenario(tmp_path: Path) -> tuple[Scenario, np.ndarray]:
    """(the scenario, 40 slots, the target's start toward UAV 0 from the west; its path [41, 2])."""
    cfg = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    cfg["uavs"]["altitude_m"] = 50  # take-off and landing in seconds; the planar problem is alike
    config = tmp_path / "pursuit.yaml"
    config.write_text(yaml.safe_dump(cfg))
    base = load_scenario(config).with_changes(N=40)
    toward = np.array([1.0, 0.0])
    x0 = np.r_[base.uav_start_xy[0] - 900 * toward, TARGET_SPEED_MPS * toward]
    s = base.with_changes(x0=x0)
    planned = LiveSettings().apply(s)
    straight = run_closed_loop(planned, "proposed", draw_run_noise(planned, 1), SolverKit(planned))
    aims = np.vstack([s.uav_start_xy[0][None], straight.uav_xy[:, 0]])
    return s, pursuit_path(x0, aims, s.a_target, s.dt)


def nearest_along_legs(s: Scenario, outcomes: list[SlotOutcome], path: np.ndarray) -> float:
    """The smallest UAV-to-target distance along the flown Hermite legs (41 instants a slot),
    the target on the chord between its path's slot positions."""
    nearest = math.inf
    for n, o in enumerate(outcomes):
        inp, plan = o.slot_input, o.plan
        assert inp.prev_velocity_mps is not None and plan.uav_velocity_mps is not None
        for f in np.linspace(0.0, 1.0, 41):
            uav = hermite_position(
                inp.prev_xy_m, inp.prev_velocity_mps, plan.uav_xy_m, plan.uav_velocity_mps, s.dt, f
            )
            target = path[n] + f * (path[n + 1] - path[n])
            nearest = min(nearest, float(np.min(np.linalg.norm(uav - target, axis=1))))
    return nearest


@pytest.mark.parametrize("method", ["horizon", "proposed"])
async def test_a_target_manoeuvring_at_the_bound_toward_a_uav_stays_d_safe_away(
    tmp_path: Path, method: Method
) -> None:
    """Offline and live, with the live default (`horizon`) and the paper's method."""
    s, path = pursuit_scenario(tmp_path)
    assert s.a_target > 0
    truth = np.hstack([path, np.zeros_like(path)])
    truth[:-1, 2:] = np.diff(path, axis=0) / s.dt
    truth[-1, 2:] = truth[-2, 2:]
    planned = LiveSettings().apply(s)
    outcomes: list[SlotOutcome] = []
    run_closed_loop(
        planned,
        method,
        draw_run_noise(planned, 1),
        SolverKit(planned),
        outcomes.append,
        truth=truth,
    )
    offline = nearest_along_legs(planned, outcomes, path)
    assert offline >= s.d_safe, offline
    assert offline < 3 * s.d_safe, offline  # the target did come at the UAVs

    waypoints = tuple((float(x), float(y)) for x, y in path)
    result = await run_soak(
        s,
        tmp_path / "out",
        speed=10.0,
        lockstep=True,
        path=(waypoints, TARGET_SPEED_MPS),
        method=method,
    )
    counts = result.proximity
    assert counts.samples >= s.M * s.N
    assert counts.target_under_d_safe == 0, counts.render(s.d_safe)
    assert counts.nearest_target_m < 3 * s.d_safe, counts.render(s.d_safe)


async def test_a_target_on_racetrack_laps_at_the_bound_stays_d_safe_away(
    soak_slots: int, tmp_path: Path
) -> None:
    cfg = yaml.safe_load((ROOT / "config" / "manoeuvring.yaml").read_text())
    cfg["uavs"]["altitude_m"] = 50  # take-off and landing in seconds; the planar problem is alike
    config = tmp_path / "racetrack.yaml"
    config.write_text(yaml.safe_dump(cfg))
    s = soak_scenario(load_scenario(config), soak_slots, "racetrack")
    assert s.a_target == 4.0 and s.tracker_motion == "imm"
    assert soak_slots * s.dt > 2 * racetrack_lap_s(s.a_target)  # every leg flown at least twice
    result = await run_soak(s, tmp_path / "out", speed=5.0, lockstep=True)
    counts = result.proximity
    print(f"\nracetrack: {soak_slots} slots; {counts.render(s.d_safe)}")
    assert result.live.report.counters["slots"] == soak_slots
    assert [p.slot for p in result.samples] == list(range(1, soak_slots + 1))
    assert counts.samples >= s.M * s.N
    assert counts.target_under_d_safe == 0, counts.render(s.d_safe)
    assert counts.uav_under_d_safe == 0, counts.render(s.d_safe)
    assert counts.nearest_target_m < 3 * s.d_safe, counts.render(s.d_safe)  # the UAVs were close
