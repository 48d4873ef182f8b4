"""The multi-target scenario (config/targets.py): `targets:` and `detection:` load, resolve and are
refused with a clear message where wrong; every single-target scenario means what it meant."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml
from typer.testing import CliRunner

from isac_mission.cli import app
from isac_mission.config import load_scenario, parse_scenario, single_target_problem
from isac_mission.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]


def multi() -> dict[str, Any]:
    data = yaml.safe_load((ROOT / "config" / "multi-target.yaml").read_text())
    assert isinstance(data, dict)
    return data


def test_the_shipped_multi_target_scenario_is_the_issues() -> None:
    s = load_scenario("multi-target")
    assert s.M == 6 and len(s.targets) == 3
    known, entering, turning = s.targets
    assert known.prior_known and known.first_slot == 0
    assert not entering.prior_known and entering.first_slot == 20
    assert turning.motion == "coordinated_turn" and turning.turn_rate_radps == 0.05
    assert s.detection is not None
    assert s.detection.detection_prob == pytest.approx(0.9)
    assert s.detection.false_alarms_per_slot == 2
    assert s.multi_target
    assert single_target_problem(s) is not None


@pytest.mark.parametrize("name", ["paper", "paper-literal", "constrained"])
def test_single_target_scenarios_are_as_before(name: str) -> None:
    s = load_scenario(name)
    assert not s.multi_target and single_target_problem(s) is None
    (t,) = s.targets
    assert t.x0 == tuple(s.x0.tolist()) and t.rcs_m2 == s.rcs_m2
    assert (t.first_slot, t.last_slot, t.prior_known) == (0, s.N, True)
    config = s.trace_config()
    assert "targets" not in config and "detection" not in config


def test_a_multi_target_trace_config_names_the_targets() -> None:
    config = load_scenario("multi-target").trace_config()
    assert [t["name"] for t in config["targets"]] == ["known", "entering", "turning"]
    assert config["detection"]["false_alarms_per_slot"] == 2


def test_one_known_plain_target_under_targets_is_the_single_target_path() -> None:
    data = multi()
    data["targets"] = [data["targets"][0]]
    data["sensing"]["missed_detection_prob"] = 0.0
    data["detection"] = {"model": "fixed", "false_alarms_per_slot": 0}
    assert not parse_scenario(data, "one").multi_target
    late = copy.deepcopy(data)
    late["targets"][0]["appears_s"] = 5
    assert parse_scenario(late, "late").multi_target
    unknown = copy.deepcopy(data)
    unknown["targets"][0]["prior"] = "unknown"
    assert parse_scenario(unknown, "unknown").multi_target


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda d: d.update(target={"initial_state": [1, 2, 3, 4]}), "under targets: only"),
        (lambda d: d["targets"][2].pop("turn_rate_radps"), "needs turn_rate_radps"),
        (lambda d: d["targets"][0].update(turn_rate_radps=0.1), "is for motion coordinated_turn"),
        (lambda d: d["targets"][0].update(motion="waypoints"), "needs waypoints_xy_m"),
        (lambda d: d["targets"][1].update(leaves_s=10), "must be after appears_s"),
        (lambda d: d["targets"][1].update(appears_s=500), "after the mission's end"),
        (lambda d: d["targets"][1].update(initial_state=[-5, 600, 1, 1]), "outside the area"),
        (lambda d: d["targets"][0].update(initial_state=[1500, 2310, 1, 1]), "closer than"),
        (lambda d: d["targets"][0].update(colour="red"), "colour"),
        (lambda d: d["detection"].update(model="snr"), "needs snr_threshold_db"),
        (lambda d: d["detection"].update(snr_threshold_db=13), "is for model snr"),
        (lambda d: d["detection"].update(false_alarms_per_slot=-1), "false_alarms_per_slot"),
        (lambda d: d["detection"].update(doppler_window_mps=[5, -5]), "low < high"),
        (lambda d: d.update(targets=[]), "targets"),
    ],
)
def test_bad_multi_target_input_is_named(change: Any, message: str) -> None:
    data = multi()
    change(data)
    with pytest.raises((ConfigError, ValueError), match=message):
        parse_scenario(data, "bad")


def test_replay_takes_a_multi_target_scenario_and_reads_its_trace(tmp_path: Path) -> None:
    # The scenario is taken (tests/numerics/test_replay_tracks.py replays such a trace); here
    # the trace does not exist, so the command stops at reading it.
    result = CliRunner().invoke(
        app, ["replay", str(ROOT / "config" / "multi-target.yaml"), str(tmp_path / "t.jsonl")]
    )
    assert result.exit_code == 1
    said = " ".join(result.output.split())  # rich wraps the message at the path's length
    assert "cannot read the trace" in said and "multi-target path" not in said


@pytest.mark.parametrize("command", ["run", "serve"])
def test_the_live_service_refuses_a_one_target_planner_on_the_multi_target_path_by_name(
    command: str, horizon_plans_one_target: None
) -> None:
    result = CliRunner().invoke(
        app, [command, str(ROOT / "config" / "multi-target.yaml"), "--method", "horizon"]
    )
    assert result.exit_code == 2
    assert "'horizon' plans for one target" in " ".join(result.output.split())


def test_simulate_refuses_a_one_target_planner_on_the_multi_target_path_by_name(
    horizon_plans_one_target: None,
) -> None:
    result = CliRunner().invoke(
        app,
        ["simulate", str(ROOT / "config" / "multi-target.yaml"), "--methods", "sd,horizon"],
    )
    assert result.exit_code == 2
    assert "'horizon' plans for one target" in " ".join(result.output.split())


def test_check_config_accepts_and_describes_a_multi_target_scenario() -> None:
    result = CliRunner().invoke(app, ["check-config", str(ROOT / "config" / "multi-target.yaml")])
    assert result.exit_code == 0, result.output
    assert "target turning" in result.output and "coordinated_turn" in result.output


def test_a_longer_or_shorter_paper_mission_keeps_its_one_plain_target() -> None:
    # with_changes(N=...) keeps a target that is in the scene to the end in it to the new end:
    # a 120-slot paper.yaml is still single-target (it took the multi-target path, and the live
    # service its multi-target ground loop, when the target "left" at the old slot 60).
    s = load_scenario(ROOT / "config" / "paper.yaml")
    for n in (30, 120):
        longer = s.with_changes(N=n)
        assert not longer.multi_target
        assert longer.targets[0].last_slot == n
    late = load_scenario(ROOT / "config" / "multi-target.yaml").with_changes(N=90)
    assert [t.last_slot for t in late.targets] == [90, 90, 90]
