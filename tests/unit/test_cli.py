"""The `isac-mission` command line: the version, scenarios by name, the package entry points;
bad input (one line, exit 2), `--help` at 80 columns, `--port-offset`, `serve --resume` on a
finished trace."""

from __future__ import annotations

import re
import tomllib
import typing
from pathlib import Path
from typing import Any

import pytest
import typer
from typer.testing import CliRunner

import isac_mission
from isac_mission.cli import COMMAND_GROUPS, app
from tests.support.trace_files import write_multi_target_trace, write_single_target_trace

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
    assert "paper: 1 run" in result.output
    assert (out / "summary.json").is_file()
    assert len(list((out / "traces").glob("sd_run*.jsonl"))) == 1


def test_run_and_serve_fly_the_horizon_by_default_and_resume_what_was_flown(
    tmp_path: Path, horizon_plans_one_target: None
) -> None:
    from isac_mission.cli.live import resolved_method
    from isac_mission.config import load_scenario
    from isac_mission.errors import ConfigError
    from isac_mission.planning.tracks import check_multi_target_method

    paper, multi = load_scenario("paper"), load_scenario("multi-target")
    assert not paper.multi_target and multi.multi_target
    assert resolved_method(None, paper, tmp_path, resume=False) == "horizon"
    # Were the single-target default a one-target method (the fixture), a multi-target
    # scenario would still default to a method that its path accepts.
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


# --------------------------------------------------------------------------- bad input, help


def _commands() -> dict[str, Any]:
    """The click command of every `isac-mission` subcommand, by name."""
    group = typer.main.get_command(app)
    return dict(group.commands)  # type: ignore[attr-defined]


def _numeric_type(command: Any, param: Any) -> type | None:
    """int or float when `param` of `command` is a numeric option (its annotation, Optional or
    not), else None: read from the command's own signature, so a new option is seen."""
    if not str(getattr(param, "opts", [""])[0]).startswith("--") or param.is_flag:
        return None
    hint = typing.get_type_hints(command.callback, include_extras=True)[param.name]
    if typing.get_origin(hint) is typing.Annotated:
        hint = typing.get_args(hint)[0]
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    if args:
        hint = args[0] if len(args) == 1 else hint
    return hint if hint in (int, float) else None


def _bad_values(option: str, kind: type) -> list[str]:
    """Values every numeric option must refuse: -1 (no count, seed, port, time or speed of the
    CLI is negative), NaN for a float, 65536 for a port."""
    values = ["-1"]
    if kind is float:
        values.append("nan")
    if "port" in option:
        values.append("65536")
    return values


NUMERIC_CASES = [
    pytest.param(name, opt, value, id=f"{name}{opt}={value}")
    for name, command in _commands().items()
    for param in command.params
    if (kind := _numeric_type(command, param)) is not None
    for opt in param.opts
    if opt.startswith("--")
    for value in _bad_values(opt, kind)
]
"""(command, option, bad value) for every numeric option of every command, from the click
command tree: an option added without validation joins the list and fails the test below."""


def test_the_numeric_options_are_all_found() -> None:
    found = {(name, opt) for name, opt, _ in (p.values for p in NUMERIC_CASES)}
    assert {
        ("run", "--speed"),
        ("run", "--port-offset"),
        ("serve", "--port-offset"),
        ("sim", "--port-offset"),
        ("sim", "--lockstep-timeout"),
        ("simulate", "--runs"),
        ("sweep", "--workers"),
        ("replay", "--from-slot"),
        ("gen-certs", "--days"),
    } <= found


def _argv(name: str, command: Any, tail: list[str], missing: Path) -> list[str]:
    """`name`, a (missing) path for every required argument and option, then `tail`."""
    argv = [name]
    for param in command.params:
        if param.required and str(param.opts[0]).startswith("--"):
            argv += [param.opts[0], str(missing)]
        elif param.required:
            argv.append(str(missing))
    return argv + tail


@pytest.mark.parametrize(("name", "option", "value"), NUMERIC_CASES)
def test_every_numeric_option_refuses_a_bad_value_in_one_line(
    name: str, option: str, value: str, tmp_path: Path
) -> None:
    argv = _argv(name, _commands()[name], [option, value], tmp_path / "missing")
    result = CliRunner().invoke(app, argv, env={"COLUMNS": "80"})
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1, result.stderr
    assert option in lines[0] and value in lines[0], lines[0]
    assert "Traceback" not in result.output


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["run", "paper", "--bogus"], "No such option: --bogus"),
        (["run"], "Missing argument"),
        (["simulate", "paper", "--runs", "many"], "--runs: input should be a valid integer"),
        (["sweep", "paper"], "Missing option '--grid'"),
        (["run", "paper", "--zenoh-listen", "nonsense"], "--zenoh-listen: zenoh endpoint"),
        (["serve", "paper", "--zenoh-listen", "tcp/10.0.0.1:7447"], "is not loopback"),
    ],
)
def test_a_usage_error_is_one_line_naming_the_problem(argv: list[str], expected: str) -> None:
    result = CliRunner().invoke(app, argv, env={"COLUMNS": "80"})
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2
    assert len(lines) == 1 and expected in lines[0], result.stderr


def test_without_arguments_the_help_is_shown() -> None:
    result = CliRunner().invoke(app, [], env={"COLUMNS": "80"})
    assert "Commands:" in result.output and "simulate" in result.output


@pytest.mark.parametrize("name", [None, *_commands()], ids=lambda n: n or "isac-mission")
def test_help_fits_80_columns_with_every_option_name_whole(name: str | None) -> None:
    argv = [name, "--help"] if name else ["--help"]
    result = CliRunner().invoke(app, argv, env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    too_long = [line for line in result.output.splitlines() if len(line) > 80]
    assert too_long == []
    command = _commands()[name] if name else typer.main.get_command(app)
    names = ["--help"] + [
        o for p in command.params for o in (*p.opts, *p.secondary_opts) if o.startswith("-")
    ]
    missing = [
        o for o in names if not re.search(rf"(?<![\w-]){re.escape(o)}(?![\w-])", result.output)
    ]
    assert missing == []


# --------------------------------------------------------------------------- --port-offset


def test_a_port_offset_moves_every_port_of_the_mission() -> None:
    from isac_mission.cli.ports import mission_ports
    from isac_mission.config import load_scenario

    s = load_scenario("paper")
    assert mission_ports(s, 100).table(s.M) == {
        "zenoh (TCP)": (7547,),
        "console (TCP)": (8180,),
        "offboard (UDP)": (14640, 14641, 14642),
        "offboard local (UDP)": (14680, 14681, 14682),
        "ground station (UDP)": (14650,),
        "ground-station local (UDP)": (18670, 18671, 18672),
    }
    ports = mission_ports(s, 100)
    assert ports.zenoh == "tcp/127.0.0.1:7547" and ports.console == "127.0.0.1:8180"


@pytest.mark.parametrize("scenario", ["paper", "multi-target"])
def test_two_missions_100_ports_apart_share_no_port(scenario: str) -> None:
    from isac_mission.cli.ports import mission_ports
    from isac_mission.config import load_scenario

    s = load_scenario(scenario)
    first, second = (
        [p for ports in mission_ports(s, offset).table(s.M).values() for p in ports]
        for offset in (0, 100)
    )
    assert len(set(first)) == len(first) and len(set(second)) == len(second)
    assert set(first).isdisjoint(second)


def test_an_explicit_port_option_wins_over_the_offset() -> None:
    from isac_mission.cli.ports import mission_ports
    from isac_mission.config import load_scenario, parse_scenario

    s = load_scenario("paper")
    ports = mission_ports(
        s, 100, zenoh="tcp/127.0.0.1:20001", console="127.0.0.1:20002", gcs_port=20003
    )
    assert ports.zenoh == "tcp/127.0.0.1:20001" and ports.console == "127.0.0.1:20002"
    assert ports.mavlink["gcs_port"] == 20003
    assert ports.mavlink["mavlink_base_port"] == 14640  # the others still move
    # The scenario's `links` are the defaults the offset moves; an ephemeral local base stays.
    ephemeral = parse_scenario({"links": {"offboard_local_base_port": 0, "gcs_port": 24550}})
    moved = mission_ports(ephemeral, 7).mavlink
    assert moved["mavlink_local_base_port"] == 0 and moved["gcs_port"] == 24557


@pytest.mark.parametrize("command", ["run", "serve", "sim"])
def test_an_offset_that_moves_a_port_past_65535_is_one_line(command: str) -> None:
    result = CliRunner().invoke(app, [command, "paper", "--port-offset", "50000"])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and lines[0].startswith("--port-offset 50000: "), result.stderr
    assert "ground-station local base port would be 68570" in lines[0]


def test_the_console_s_default_is_the_console_s_own() -> None:
    from isac_mission.cli.ports import DEFAULT_CONSOLE
    from isac_mission.console import DEFAULT_ADDRESS

    assert DEFAULT_CONSOLE == DEFAULT_ADDRESS


# --------------------------------------------------------------------------- serve --resume


@pytest.mark.parametrize("killed", [False, True], ids=["ended", "killed-after-slot-N"])
@pytest.mark.parametrize(
    ("scenario", "write"),
    [("paper", write_single_target_trace), ("multi-target", write_multi_target_trace)],
    ids=["single-target", "multi-target"],
)
def test_resume_refuses_a_complete_trace_in_one_line_and_leaves_it_as_it_was(
    tmp_path: Path, scenario: str, write: typing.Callable[..., None], killed: bool
) -> None:
    # With the console on by default: the refusal comes before any socket (the fast tier's
    # guard fails the test on one) and before the vehicles.
    trace = tmp_path / "trace_proposed.jsonl"
    write(trace, scenario, 60, killed=killed)
    before = trace.read_bytes()
    result = CliRunner().invoke(app, ["serve", scenario, "--resume", "--out", str(tmp_path)])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1, result.stderr
    assert "the trace is complete: 60/60" in lines[0] and str(trace) in lines[0]
    assert trace.read_bytes() == before


def test_resume_of_a_multi_target_mission_is_refused_before_anything_opens(
    tmp_path: Path,
) -> None:
    trace = tmp_path / "trace_proposed.jsonl"
    write_multi_target_trace(trace, "multi-target", 12)
    before = trace.read_bytes()
    result = CliRunner().invoke(app, ["serve", "multi-target", "--resume", "--out", str(tmp_path)])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2, result.output
    # A trace written before multi-target traces carried what a restart needs.
    assert len(lines) == 1 and "has no `plan_eta` or `tracker`" in lines[0], result.stderr
    assert trace.read_bytes() == before


def test_resume_refuses_a_corrupt_trace_in_one_line(tmp_path: Path) -> None:
    trace = tmp_path / "trace_proposed.jsonl"
    write_single_target_trace(trace, "paper", 5, killed=True)
    trace.write_bytes(trace.read_bytes() + b"not json\n")
    result = CliRunner().invoke(
        app, ["serve", "paper", "--resume", "--out", str(tmp_path), "--no-console"]
    )
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and "line 7" in lines[0] and str(trace) in lines[0], result.stderr
