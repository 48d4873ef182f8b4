"""The live settings (isac_mission.config.live_settings): one definition of what the live
service plans with, used by `run`/`serve` (LiveOptions) and `simulate --live-settings`."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from isac_mission.cli import app
from isac_mission.config import Scenario
from isac_mission.config.live_settings import LIVE_SETTINGS, LiveSettings
from isac_mission.records import read_trace
from isac_mission.service.assembly import LiveOptions, planning_scenario


def test_live_settings_plan_with_the_live_margins(paper: Scenario) -> None:
    live = LIVE_SETTINGS.apply(paper)
    assert live.v_max == pytest.approx(paper.v_max * LIVE_SETTINGS.speed_fraction)
    assert live.r_th == pytest.approx(paper.r_th * LIVE_SETTINGS.rate_factor)
    assert live.d_safe == pytest.approx(paper.d_safe + LIVE_SETTINGS.safety_margin_m)
    assert live.planner.accel_limit_mps2 == pytest.approx(
        paper.a_max * LIVE_SETTINGS.accel_fraction
    )
    assert live.planner.vehicle_model == (
        paper.planner.vehicle_model or LIVE_SETTINGS.vehicle_model
    )
    # Nothing else moves: the truth the vehicles fly in is the scenario's.
    assert live.planner.safety_margin == paper.planner.safety_margin
    assert (live.bs_xy == paper.bs_xy).all() and live.N == paper.N and live.M == paper.M


def test_the_live_service_plans_on_the_live_settings(paper: Scenario) -> None:
    """`run`/`serve` (LiveOptions' defaults) and `simulate --live-settings` share one definition."""
    assert LiveOptions().live_settings == LIVE_SETTINGS
    ours = planning_scenario(paper, LiveOptions()).trace_config()
    assert ours == LIVE_SETTINGS.apply(paper).trace_config()
    custom = LiveOptions(plan_speed_fraction=0.5, plan_safety_margin_m=0.0, plan_accel_fraction=0)
    s = planning_scenario(paper, custom)
    assert s.v_max == pytest.approx(0.5 * paper.v_max) and s.d_safe == paper.d_safe
    assert s.planner.accel_limit_mps2 == paper.planner.accel_limit_mps2


def test_vehicle_model_of_the_scenario_is_kept(paper: Scenario) -> None:
    on = paper.with_changes(planner=paper.planner.model_copy(update={"vehicle_model": True}))
    assert LiveSettings(vehicle_model=False).apply(on).planner.vehicle_model
    assert LiveSettings(vehicle_model=True).apply(paper).planner.vehicle_model


def test_the_vehicle_model_plans_with_the_acceleration_fraction(paper: Scenario) -> None:
    """The simulated vehicle flies plans at 0.8 a_max within the tracking margin, not turns held
    at a_max (tests/numerics/test_tracking_error.py); without the vehicle model a_max is kept."""
    live = LiveSettings(vehicle_model=True).apply(paper)
    assert live.a_max == pytest.approx(0.8 * paper.a_max)
    assert LiveSettings(vehicle_model=True, accel_fraction=0).apply(paper).a_max == paper.a_max
    assert LiveSettings(vehicle_model=False).apply(paper).a_max == paper.a_max


@pytest.mark.parametrize(
    "bad",
    [
        {"speed_fraction": 0.0},
        {"speed_fraction": 1.5},
        {"rate_factor": 0.0},
        {"safety_margin_m": -1.0},
        {"accel_fraction": -0.1},
    ],
)
def test_invalid_live_settings_name_the_bad_value(bad: dict[str, float]) -> None:
    name, value = next(iter(bad.items()))
    with pytest.raises(ValueError, match=name) as err:
        LiveSettings(**bad)  # type: ignore[arg-type]
    assert f"got {value}" in str(err.value)


def test_changes_list_every_changed_setting(paper: Scenario) -> None:
    rows = {q: (a, b) for q, a, b in LIVE_SETTINGS.changes(paper)}
    assert rows["V_max"] == (f"{paper.v_max:g} m/s", f"{0.9 * paper.v_max:g} m/s")
    assert rows["D_s"][1] == f"{paper.d_safe + LIVE_SETTINGS.safety_margin_m:g} m"
    assert rows["planner.accel_limit_mps2"] == (
        "null",
        f"{LIVE_SETTINGS.accel_fraction * paper.a_max:g}",
    )
    assert rows["planner.vehicle_model"] == ("false", "true")


def test_the_live_defaults_are_the_vehicle_model_and_the_safety_rule(paper: Scenario) -> None:
    """Chosen by live missions (docs/decisions/0010-live-settings.md): the scenario's safety
    rule, no fixed margin on D_s, and the vehicle model."""
    live = LIVE_SETTINGS.apply(paper)
    assert live.planner.vehicle_model and live.planner.safety_margin == "covariance"
    assert live.d_safe == paper.d_safe


def test_simulate_live_settings_plans_as_the_live_service(paper: Scenario, tmp_path: Path) -> None:
    out = tmp_path / "out"
    argv = ["simulate", "paper", "--runs", "1", "--methods", "sd", "--workers", "1", "--no-plots"]
    result = CliRunner().invoke(
        app, [*argv, "--live-settings", "--out", str(out)], env={"COLUMNS": "200"}
    )
    assert result.exit_code == 0, result.output
    assert "live settings" in result.output
    trace = read_trace(next((out / "traces").glob("sd_run*.jsonl")))
    want = planning_scenario(paper, LiveOptions()).trace_config()
    for key in ("v_max", "r_th", "d_safe", "planner"):
        assert trace.config[key] == want[key], key


def test_sweep_live_settings_plans_every_point_as_the_live_service(tmp_path: Path) -> None:
    from isac_mission.experiment.sweep.runs import plan_sweep

    root = Path(__file__).resolve().parents[2]
    g = tmp_path / "grid.yaml"
    g.write_text("uavs.max_speed_mps: [15, 25]\nruns: 1\nslots: 5\n")
    plain = plan_sweep(root / "config" / "paper.yaml", g)
    live = plan_sweep(root / "config" / "paper.yaml", g, live=LIVE_SETTINGS)
    for p, q in zip(plain.points, live.points, strict=True):
        assert q.scenario.trace_config() == LIVE_SETTINGS.apply(p.scenario).trace_config()
        assert q.key != p.key  # a worker's kit cache never mixes the two
    assert all(t.scenario is live.points[t.point].scenario for t in live.tasks)
