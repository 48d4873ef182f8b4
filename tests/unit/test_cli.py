"""The `isac-mission` command line: the version, scenarios by name, the package entry points."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

import isac_mission
from isac_mission.cli import COMMAND_GROUPS, app

ROOT = Path(__file__).resolve().parents[2]


def test_version_prints_the_package_version() -> None:
    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0
    assert result.output.strip() == f"isac-mission {isac_mission.__version__}"


def test_the_console_script_is_the_cli_main() -> None:
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"isac-mission": "isac_mission.cli:main"}


def test_every_command_is_registered_in_help_order() -> None:
    names = [
        c.name or getattr(c.callback, "__name__", "").replace("_", "-")
        for c in app.registered_commands
    ]
    assert names[:10] == [
        "check-config",
        "simulate",
        "replay",
        "sweep",
        "sim",
        "run",
        "serve",
        "compile",
        "gen-certs",
        "gen-users",
    ]
    assert COMMAND_GROUPS[:5] == ("offline", "sweep", "embedded", "live", "security")


def test_check_config_takes_a_shipped_scenario_by_name() -> None:
    result = CliRunner().invoke(app, ["check-config", "paper"], env={"COLUMNS": "160"})
    assert result.exit_code == 0, result.output
    assert "paper (mission paper)" in result.output
    assert "3 / 5 / 60" in result.output


def test_an_unknown_scenario_name_exits_2_naming_the_choices() -> None:
    result = CliRunner().invoke(app, ["check-config", "nope"], env={"COLUMNS": "160"})
    assert result.exit_code == 2
    assert "no such file, nor a shipped scenario" in result.output
    assert "paper-literal" in result.output


def test_simulate_takes_a_shipped_scenario_by_name(tmp_path: Path) -> None:
    out = tmp_path / "out"
    argv = ["simulate", "paper", "--runs", "1", "--methods", "sd", "--workers", "1", "--no-plots"]
    result = CliRunner().invoke(app, [*argv, "--out", str(out)], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "paper: 1 runs" in result.output
    assert (out / "summary.json").is_file()
    assert len(list((out / "traces").glob("sd_run*.jsonl"))) == 1


def test_run_and_serve_fly_the_horizon_by_default_and_resume_what_was_flown(
    tmp_path: Path,
) -> None:
    from isac_mission.cli.live import resolved_method
    from isac_mission.config import load_scenario
    from isac_mission.errors import ConfigError
    from isac_mission.planning.multi_target import check_multi_target_method

    paper, multi = load_scenario("paper"), load_scenario("multi-target")
    assert not paper.multi_target and multi.multi_target
    assert resolved_method(None, paper, tmp_path, resume=False) == "horizon"
    # The horizon plans one target's bound: a multi-target scenario defaults to a method that
    # its path accepts, and the single-target default is one it refuses.
    default_multi = resolved_method(None, multi, tmp_path, resume=False)
    check_multi_target_method(default_multi)
    with pytest.raises(ConfigError):
        check_multi_target_method(resolved_method(None, paper, tmp_path, resume=False))
    assert resolved_method("sd", paper, tmp_path, resume=True) == "sd"
    # `--resume` continues the method of the trace it finds, whatever today's default.
    (tmp_path / "trace_proposed.jsonl").write_text("{}\n")
    assert resolved_method(None, paper, tmp_path, resume=True) == "proposed"
    assert resolved_method(None, paper, tmp_path, resume=False) == "horizon"
    (tmp_path / "trace_sd.jsonl").write_text("{}\n")
    with pytest.raises(ValueError, match="proposed, sd; say which to resume"):
        resolved_method(None, paper, tmp_path, resume=True)
