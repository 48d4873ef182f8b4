"""The offline loop on several targets (experiment/runs.py), its planning objective and its
metrics (experiment/track_metrics.py), each against an independent computation:

- the summed objective against its parts and its gradients against finite differences, and a
  slot problem given other targets minimising the sum of every target's bound;
- a mission of config/multi-target.yaml: every target confirmed soon after three UAVs saw it,
  no ID switch, D_s kept from every true target at every slot end, the plan made around a
  confirmed track; the horizon refused by name;
- the metrics on a hand-made run: GOSPA against tracking/gospa.py, switches, false runs,
  confirmation delays, a far but honest track following its target;
- the report's tables and traces of several targets from `simulate`'s entry point.
"""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from isac_mission.config import Scenario, load_scenario
from isac_mission.errors import ConfigError
from isac_mission.experiment.montecarlo import run_monte_carlo
from isac_mission.experiment.report import simulate_report
from isac_mission.experiment.runs import fly_outcomes, tracks_slot
from isac_mission.experiment.track_metrics import follow, track_figures
from isac_mission.model.detections import CLUTTER, UavReport
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.model.radar import SensingParams
from isac_mission.planning.problem import SlotInput, build_slot_problem
from isac_mission.planning.tracks import multi_target_kit
from isac_mission.records.header import TRACE_FORMAT
from isac_mission.records.tracks import TracksSlot
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.gospa import UNASSIGNED, gospa
from isac_mission.tracking.pcrb import Bound, PlanningObjective, SumObjective, predict_information
from isac_mission.tracking.tracker import TrackEstimate
from isac_mission.types import Gaussian, SlotPlan, SolveReport


@pytest.fixture(scope="module")
def scenario() -> Scenario:
    return load_scenario("multi-target")


def test_the_summed_objective_is_its_parts_and_its_gradients_are_finite_differences(
    scenario: Scenario,
) -> None:
    rng = np.random.default_rng(5)
    sensing = SensingParams.from_scenario(scenario)
    F, W = transition_matrix(1.0), process_noise(1.0, 0.5)
    parts = tuple(
        PlanningObjective(
            predict_information(Bound.from_covariance(scenario.P0 * rng.uniform(0.1, 2)), F, W),
            np.array([*rng.uniform(500, 2500, 2), *rng.uniform(-20, 20, 2)]),
            sensing,
        )
        for _ in range(3)
    )
    total = SumObjective(parts)
    q = rng.uniform(300, 2700, (scenario.M, 2))
    eta = rng.dirichlet(np.ones(scenario.M))
    assert total.value(q, eta) == pytest.approx(sum(p.value(q, eta) for p in parts), rel=1e-14)
    batch = q[None] + rng.normal(0, 20, (4, scenario.M, 2))
    np.testing.assert_allclose(
        total.values(batch, eta), [total.value(b, eta) for b in batch], rtol=1e-10
    )
    moved = rng.uniform(300, 2700, (5, 2))
    want = [total.value(np.vstack([q[:2], c[None], q[3:]]), eta) for c in moved]
    np.testing.assert_allclose(total.values_moving_one(q, eta, 2, moved), want, rtol=1e-10)
    f, grad_q, grad_eta = total.value_and_gradients(q, eta)
    assert f == pytest.approx(total.value(q, eta), rel=1e-12)
    for m in range(scenario.M):
        for j in range(2):
            e = np.zeros_like(q)
            e[m, j] = 1e-2
            fd = (total.value(q + e, eta) - total.value(q - e, eta)) / 2e-2
            assert grad_q[m, j] == pytest.approx(fd, rel=1e-5, abs=1e-12)
        d = 1e-6 * np.eye(scenario.M)[m]
        fd_eta = (total.value(q, eta + d) - total.value(q, eta - d)) / 2e-6
        assert grad_eta[m] == pytest.approx(fd_eta, rel=1e-5)


def test_a_slot_problem_with_other_targets_minimises_their_sum(scenario: Scenario) -> None:
    kit = multi_target_kit(scenario)
    J = np.linalg.inv(scenario.P0)
    others = ((np.array([2000.0, 2000.0, 5.0, 0.0]), J), (np.array([800.0, 900.0, 0, 9.0]), J))
    inp = SlotInput(
        scenario.uav_start_xy,
        np.full(scenario.M, 1 / scenario.M),
        None,
        tuple(
            TargetBelief(x, Jx, scenario.motion)
            for x, Jx in ((np.array([600.0, 1600.0, 30.0, 0.0]), J), *others)
        ),
        keep_out_xy_m=np.full((kit.n_keep_out, 2), -1e6),
    )
    problem = build_slot_problem(inp, kit)
    assert isinstance(problem.objective, SumObjective)
    q, eta = scenario.uav_start_xy, np.full(scenario.M, 1 / scenario.M)
    single = PlanningObjective(J, inp.lead.state_pred, kit.sensing)
    want = single.value(q, eta) + sum(
        PlanningObjective(Jo, x, kit.sensing).value(q, eta) for x, Jo in others
    )
    assert problem.objective.value(q, eta) == pytest.approx(want, rel=1e-14)


@pytest.fixture(scope="module")
def mission(scenario: Scenario) -> tuple[TracksSlot, ...]:
    s = scenario.with_changes(N=36)
    return tuple(tracks_slot(o) for o in fly_outcomes(s, "proposed", 1, multi_target_kit(s)))


def test_a_mission_follows_every_target_and_keeps_its_distance(
    scenario: Scenario, mission: tuple[TracksSlot, ...]
) -> None:
    figures = track_figures(mission, scenario.multi_tracker.gospa_cutoff_m)
    for t, target in enumerate(figures.targets):
        assert target.seen_slot > 0, t
        assert target.confirmation_delay is not None and target.confirmation_delay <= 6, t
        assert target.id_switches == 0, t
    assert figures.targets[0].confirmed_slot == 1  # known from the start
    for slot in mission:
        truth = slot.truth[np.all(np.isfinite(slot.truth), axis=1)]
        distance = np.linalg.norm(slot.uav_xy_m[:, None] - truth[None, :, :2], axis=2)
        assert distance.min() >= scenario.d_safe, slot.slot
        confirmed = [t.track_id for t in slot.tracks if t.confirmed]
        assert slot.planned_for in confirmed or (slot.planned_for == 0 and not confirmed)


def test_a_single_target_planner_is_refused_by_name(
    scenario: Scenario, horizon_plans_one_target: None
) -> None:
    with pytest.raises(ConfigError, match=r"horizon.*plans for one target"):
        run_monte_carlo(scenario, ["horizon"], 1, 1)


def _track(track_id: int, xy: tuple[float, float], std_m: float = 1.0) -> TrackEstimate:
    P = np.diag([std_m**2, std_m**2, 1.0, 1.0])
    return TrackEstimate(
        track_id, True, Gaussian(np.array([*xy, 0.0, 0.0]), P), Bound.from_covariance(P), 5.0
    )


def _report(origins: list[int]) -> UavReport:
    return UavReport(np.zeros((len(origins), 2)), np.array(origins, dtype=np.int64))


def test_the_metrics_of_a_hand_made_run() -> None:
    truth = np.array([[0.0, 0.0, 1, 0], [500.0, 0.0, 0, 1]])
    # Target 0 followed by track 1, then track 2 (a switch); target 1 seen by three UAVs from
    # slot 2, followed from slot 4; track 9 false at slots 2 and 3.
    tracks = [
        [_track(1, (3.0, 4.0))],
        [_track(1, (1.0, 0.0)), _track(9, (2000.0, 0.0))],
        [_track(2, (0.0, 2.0)), _track(9, (2100.0, 0.0))],
        [_track(2, (0.0, 1.0)), _track(3, (503.0, 0.0))],
    ]
    seen = [[0], [0, 1], [0, 1], [1]]
    slots = []
    for n in range(4):
        reports = tuple(_report(seen[n] + [CLUTTER]) for _ in range(3))
        plan = SlotPlan(
            np.zeros((3, 2)), np.zeros(3, dtype=np.int64), np.ones(3) / 3, 0.0, SolveReport("ok")
        )
        slots.append(
            TracksSlot(
                n + 1,
                "sd",
                plan,
                np.zeros((3, 2)),
                np.ones(3) / 3,
                truth,
                reports,
                tuple(tracks[n]),
                0,
            )
        )
    f = track_figures(slots, 10.0)
    for n, slot in enumerate(slots):
        xy = np.array([t.belief.x[:2] for t in slot.tracks])
        assert f.gospa_m[n] == pytest.approx(gospa(truth[:, :2], xy, c=10.0).distance)
    target0, target1 = f.targets
    assert (target0.seen_slot, target0.confirmed_slot, target0.id_switches) == (1, 1, 1)
    assert (target1.seen_slot, target1.confirmed_slot, target1.id_switches) == (2, 4, 0)
    assert target1.confirmation_delay == 2
    np.testing.assert_allclose(target0.squared_error_m2, [25.0, 1.0, 4.0, 1.0])
    np.testing.assert_allclose(target1.squared_error_m2, [9.0])
    np.testing.assert_allclose(target0.bound_m2, [2.0] * 4)
    assert f.false_track_runs == (2,)
    assert f.id_switches == 1


def test_a_far_track_follows_its_target_when_its_gate_holds_it() -> None:
    truth = np.array([[0.0, 0.0]])
    honest, overconfident = _track(1, (150.0, 0.0), std_m=60.0), _track(1, (150.0, 0.0))
    assert follow(truth, [honest]).tolist() == [0]
    assert follow(truth, [overconfident]).tolist() == [UNASSIGNED]
    assert follow(truth, [_track(1, (90.0, 0.0))]).tolist() == [0]


def test_the_report_prints_its_tables_and_writes_traces(scenario: Scenario, tmp_path: Path) -> None:
    s = scenario.with_changes(N=8)
    printed = io.StringIO()
    summary = simulate_report(
        s,
        ["sd", "aba"],
        runs=2,
        seed=3,
        out_dir=tmp_path,
        workers=1,
        plots=True,
        console=Console(file=printed),
    )
    text = printed.getvalue()
    for label in ("GOSPA (m)", "ID switches / run", "known: RMSE", "GOSPA change", "ABA"):
        assert label in text
    assert set(summary["methods"]) == {"sd", "aba"}
    lines = (tmp_path / "traces" / "aba_run001.jsonl").read_text().splitlines()
    head = json.loads(lines[0])
    assert head["format"] == TRACE_FORMAT and head["config"]["seed"] == 4
    slots = [json.loads(line) for line in lines[1:]]
    assert [r["slot"] for r in slots] == list(range(1, 9))
    assert all(len(r["measurements"]) == s.M == len(r["origins"]) for r in slots)
    assert any(t["confirmed"] for t in slots[-1]["tracks"])
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert on_disk["methods"]["sd"]["gospa_m"] == pytest.approx(summary["methods"]["sd"]["gospa_m"])
    for method in ("sd", "aba"):  # the pictures: PNGs of the figure's size
        png = (tmp_path / f"tracks_{method}.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
        width, height = struct.unpack(">II", png[16:24])
        assert (width, height) == (8 * 120, 7 * 120)
