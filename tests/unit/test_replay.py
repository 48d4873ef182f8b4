"""`isac-mission replay` (experiment/replay.py): an offline trace replays to itself, and a trace
whose planner started elsewhere, or was planned on other settings, says so."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from isac_mission.cli import app
from isac_mission.config import Scenario
from isac_mission.config.live_settings import LIVE_SETTINGS
from isac_mission.experiment.montecarlo import run_monte_carlo, trace_path
from isac_mission.experiment.replay import config_differences, replay_trace, summarize_replay
from isac_mission.records import Trace, read_trace

N_SLOTS = 12


@pytest.fixture(scope="module")
def live_like(paper: Scenario) -> Scenario:
    """paper.yaml planned as the live service plans it (vehicle model: plan_velocity traced)."""
    return LIVE_SETTINGS.apply(dataclasses.replace(paper, N=N_SLOTS))


@pytest.fixture(scope="module")
def offline_trace(live_like: Scenario, tmp_path_factory: pytest.TempPathFactory) -> Trace:
    where = tmp_path_factory.mktemp("replay")
    run_monte_carlo(live_like, ["proposed"], 1, seed=3, trace_dir=where)
    return read_trace(trace_path(where, "proposed", 0))


def test_an_offline_trace_replays_to_itself(live_like: Scenario, offline_trace: Trace) -> None:
    rows = replay_trace(offline_trace, live_like)
    assert [r.slot for r in rows] == list(range(1, N_SLOTS + 1))
    for r in rows:
        np.testing.assert_array_equal(r.start_gap_m, 0.0)  # offline starts on its last plan
        np.testing.assert_array_equal(r.start_velocity_gap_mps, 0.0)
        assert r.prediction_gap < 1e-9
        np.testing.assert_allclose(r.replay_gap_m, 0.0, atol=1e-6)  # the same planner
        np.testing.assert_allclose(r.offline_step_m, r.planned_step_m, atol=1e-6)
    summary = summarize_replay(rows, first_slot=11)
    assert summary.slots == N_SLOTS - 10
    assert summary.start_gap_max_m == 0.0
    # The step is each waypoint's distance from the previous one, recomputed here.
    xy = offline_trace.stack("plan_xy")
    steps = np.linalg.norm(xy[10:] - xy[9:-1], axis=2)
    assert summary.planned_step_m == pytest.approx(float(steps.mean()))


def test_a_planner_that_started_elsewhere_shows_its_gap(
    live_like: Scenario, offline_trace: Trace
) -> None:
    slots = list(offline_trace.slots)
    start = slots[4].plan_start_xy
    assert start is not None
    moved = start.copy()
    moved[0] += [1.2, -1.6]  # UAV 0 of slot 5 planned from 2 m away from its last waypoint
    slots[4] = dataclasses.replace(slots[4], plan_start_xy=moved)
    rows = replay_trace(dataclasses.replace(offline_trace, slots=slots), live_like, slots=[4, 5])
    assert [r.slot for r in rows] == [4, 5]
    np.testing.assert_allclose(rows[1].start_gap_m, [2.0, 0.0, 0.0], atol=1e-12)
    # From the recorded (moved) start the planner plans another waypoint than the one traced.
    assert rows[1].replay_gap_m[0] > 1e-3
    np.testing.assert_allclose(rows[0].replay_gap_m, 0.0, atol=1e-6)


def test_another_scenario_is_refused_naming_what_differs(
    paper: Scenario, offline_trace: Trace
) -> None:
    other = dataclasses.replace(paper, N=N_SLOTS)  # without the live settings
    diff = config_differences(offline_trace.config, other)
    assert any(d.startswith("v_max:") for d in diff)
    with pytest.raises(ValueError, match="v_max"):
        replay_trace(offline_trace, other)


def test_the_command_finds_the_planning_scenario_and_writes_json(
    offline_trace: Trace, tmp_path: Path
) -> None:
    assert offline_trace.path is not None
    paper_yaml = Path(__file__).resolve().parents[2] / "config" / "paper.yaml"
    # paper.yaml has N = 60: the trace's N differs, so the command must refuse it ...
    res = CliRunner().invoke(app, ["replay", str(paper_yaml), str(offline_trace.path)])
    assert res.exit_code == 1
    assert "N: trace 12, here 60" in " ".join(res.output.split())
    # ... and take a config with the trace's N, finding the live settings itself.
    cfg = tmp_path / "short.yaml"
    text = paper_yaml.read_text()
    assert "duration_s: 60 " in text
    cfg.write_text(text.replace("duration_s: 60 ", f"duration_s: {N_SLOTS} "))
    out = tmp_path / "replay.json"
    res = CliRunner().invoke(app, ["replay", str(cfg), str(offline_trace.path), "--out", str(out)])
    assert res.exit_code == 0, res.output
    data = json.loads(out.read_text())
    assert len(data["slots"]) == N_SLOTS
    assert data["summaries"]["slots 11.."]["slots"] == N_SLOTS - 10
    assert data["summaries"]["slots 1.."]["start_gap_max_m"] == 0.0


def test_an_unreadable_trace_is_a_clear_error(tmp_path: Path) -> None:
    paper_yaml = Path(__file__).resolve().parents[2] / "config" / "paper.yaml"
    bad = tmp_path / "bad.jsonl"
    bad.write_text("not json\n")
    res = CliRunner().invoke(app, ["replay", str(paper_yaml), str(bad)])
    assert res.exit_code == 1
    assert "cannot read the trace" in res.output
