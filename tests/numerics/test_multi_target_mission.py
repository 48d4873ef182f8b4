"""The live ground loop's mission state (service/ground/mission.py) on several targets, fed the simulated
world's reports (sim/multi_target_scene.py) with no network between, is `simulate`'s run: the
same targets, the same reports, the same plans and tracks, slot by slot. What the live service
adds (waiting, vehicles that trail their plans) is then all that can make live differ."""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.errors import ConfigError
from isac_mission.experiment.runs import fly_outcomes, tracks_slot
from isac_mission.model.run_noise import draw_multi_target_noise
from isac_mission.planning.tracks import (
    KEEP_OUT_CAPACITY,
    multi_target_kit,
    plan_tracks,
)
from isac_mission.records.tracks import TracksSlot, slot_line
from isac_mission.service.ground.mission import MissionState
from isac_mission.wire import DetectionSetMsg, TruthSetMsg
from sim.multi_target_scene import MultiTargetScene
from tests.support.ground_steps import plan_slot_of, processed
from tests.support.live_cli import ROOT

SLOTS = 8
SEED = 3


@pytest.fixture(scope="module")
def scenario() -> Scenario:
    s = load_scenario(ROOT / "config" / "multi-target.yaml")
    return s.with_changes(N=SLOTS)


def _without_times(line: str) -> str:
    import json

    d = json.loads(line)
    d.pop("solve_ms")
    return json.dumps(d, sort_keys=True)


def _fly_the_mission_state(s: Scenario) -> list[TracksSlot]:
    """The live state's recursion, the world's reports taken at the plans' waypoints (where the
    offline loop's UAVs are) with the plans' shares."""
    scene = MultiTargetScene(s, SEED)
    errors = draw_multi_target_noise(s, SEED).initial_errors
    mission = MissionState(s, multi_target_kit(s), "proposed", errors)
    uav_xy, velocity = s.uav_start_xy.copy(), np.zeros((s.M, 2))
    out = []
    for n in range(1, s.N + 1):
        _, plan = plan_slot_of(mission, uav_xy, velocity)
        velocity = (
            plan.uav_velocity_mps
            if plan.uav_velocity_mps is not None
            else (plan.uav_xy_m - uav_xy) / s.dt
        )
        uav_xy = plan.uav_xy_m
        reports = scene.reports(n, uav_xy, plan.bandwidth_share)
        msgs = {
            m: DetectionSetMsg(n, 0.0, m, r.measurements, uav_xy[m], plan.bandwidth_share[m])
            for m, r in enumerate(reports)
        }
        origins = tuple(tuple(int(o) for o in r.origin) for r in reports)
        truth = TruthSetMsg(n, 0.0, scene.truth(n), origins)
        out.append(processed(mission, n, msgs, truth, uav_xy))
    assert mission.done
    return out


def test_the_live_mission_state_fed_the_worlds_reports_is_simulates_run(
    scenario: Scenario,
) -> None:
    s = scenario
    offline = [tracks_slot(o) for o in fly_outcomes(s, "proposed", SEED, multi_target_kit(s))]
    live = _fly_the_mission_state(s)
    assert len(live) == len(offline) == SLOTS
    for a, b in zip(live, offline, strict=True):
        assert _without_times(slot_line(a)) == _without_times(slot_line(b)), f"slot {a.slot}"
    # Not vacuous: tracks were confirmed, the fleet moved and some report held a false alarm.
    assert any(t.confirmed for t in live[-1].tracks)
    assert not np.allclose(live[-1].uav_xy_m, s.uav_start_xy)
    assert any(np.any(r.origin == -1) for o in live for r in o.reports)


def test_a_missing_report_contributes_nothing_and_its_origins_are_unknown(
    scenario: Scenario,
) -> None:
    s = scenario
    scene = MultiTargetScene(s, SEED)
    mission = MissionState(s, multi_target_kit(s), "sd")
    _, plan = plan_slot_of(mission, s.uav_start_xy)
    reports = scene.reports(1, plan.uav_xy_m, plan.bandwidth_share)
    msgs = {
        m: DetectionSetMsg(1, 0.0, m, r.measurements, plan.uav_xy_m[m], plan.bandwidth_share[m])
        for m, r in enumerate(reports)
        if m != 2
    }
    slot = processed(mission, 1, msgs, None, plan.uav_xy_m)
    assert slot.bandwidth_share[2] == 0.0  # UAV 2 sensed nothing as far as the tracker knows
    assert len(slot.reports[2].measurements) == 0
    assert all(np.all(r.origin == -2) for r in slot.reports)  # no truth: origins unknown
    assert np.isnan(slot.truth).all()


def test_an_excluded_vehicle_holds_and_the_others_plan_around_it(scenario: Scenario) -> None:
    s = scenario
    mission = MissionState(s, multi_target_kit(s), "proposed")
    predictions = mission.predict()
    xy = s.uav_start_xy.copy()
    xy[4] = xy[1] + np.array([40.0, 0.0])  # vehicle 4 lost 40 m from vehicle 1
    planned_for, plan = plan_slot_of(mission, xy, None, (4,), commit=False)
    assert planned_for == 1
    assert plan.report.status == "ok" and "vehicles [4] excluded" in plan.report.reason
    np.testing.assert_array_equal(plan.uav_xy_m[4], xy[4])  # it holds where it was seen
    assert plan.bandwidth_share[4] == 0.0 and plan.bs_of_uav[4] == -1
    assert plan.bandwidth_share.sum() == pytest.approx(1.0)
    # Every other vehicle keeps D_s from it (a keep-out point beside the tracks').
    others = np.delete(plan.uav_xy_m, 4, axis=0)
    assert np.linalg.norm(others - xy[4], axis=1).min() >= s.d_safe - 1e-6
    # The others' plan is the five-vehicle planner's, with vehicle 4 as one more keep-out point.
    idx = [0, 1, 2, 3, 5]
    five = mission.kits.for_active(tuple(idx))
    assert five.n_keep_out == KEEP_OUT_CAPACITY + 1
    eta = mission.eta[idx] / mission.eta[idx].sum()
    alone = plan_tracks(
        five.scenario, "proposed", five, predictions, xy[idx], eta, None, None, None, xy[[4]]
    ).plan
    np.testing.assert_allclose(plan.uav_xy_m[idx], alone.uav_xy_m, atol=1e-6)
    np.testing.assert_allclose(plan.bandwidth_share[idx], alone.bandwidth_share, atol=1e-9)


def test_a_one_target_planner_is_refused_by_name(
    scenario: Scenario, horizon_plans_one_target: None
) -> None:
    with pytest.raises(ConfigError, match="'horizon' plans for one target"):
        MissionState(scenario, multi_target_kit(scenario), "horizon")
