"""The planner cluster's options on `simulate`, `run` and `serve` (cli/planner_options.py, one
definition for the three): a refusal is one line naming the option, exit status 2, before any
cluster or mission starts (the fast tier's guard fails a test that opens a socket or starts a
process); accepted, they resolve into the service's `LiveOptions.planner_cluster` with the live
deadline (half the slot's planning budget); and a sub-fleet's kit solves its groups where the
full fleet's kit does (planning/fleet.KitCache), through an operator's new R_th too. The live
missions on a real cluster: tests/integration/test_planner_cluster_live.py."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from isac_mission.cli import app
from isac_mission.planner_cluster import (
    DEFAULT_DEADLINE_S,
    LIVE_DEADLINE_FRACTION,
    PlannerCluster,
    live_deadline_s,
)
from isac_mission.planning.decomposed import (
    DECOMPOSED_KEY,
    DecomposedHorizon,
    GroupJob,
    use_group_executor,
)
from isac_mission.planning.fleet import KitCache
from isac_mission.planning.kit import SolverKit
from isac_mission.types import SlotPlan
from tests.support import two_clusters as scene

TWO_TARGETS = scene.two_targets_config(10)


@pytest.fixture
def nothing_starts(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """No cluster and no mission may start: each attempt is recorded (and the fast tier's
    guard would fail a socket or a process anyway)."""
    started: list[str] = []

    def refuse(what: str) -> Any:
        def call(*_args: Any, **_kwargs: Any) -> None:
            started.append(what)
            raise AssertionError(f"{what} started")

        return call

    monkeypatch.setattr("isac_mission.planner_cluster.planner_client", refuse("a cluster"))
    monkeypatch.setattr("isac_mission.planner_cluster.group_executor", refuse("a cluster"))
    monkeypatch.setattr("isac_mission.cli.mission.fly", refuse("the mission"))
    monkeypatch.setattr("isac_mission.experiment.report.simulate_report", refuse("simulate"))
    return started


def _config(tmp_path: Path, decompose: str = "targets") -> Path:
    """TWO_TARGETS (its horizon decomposed or not) as a scenario file under tmp_path."""
    cfg = dict(TWO_TARGETS, planner={"horizon": {"length": 3, "decompose": decompose}})
    path = tmp_path / f"two-{decompose}.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def _one_line(argv: Sequence[str]) -> str:
    """The one stderr line of a refused command (exit status 2)."""
    result = CliRunner().invoke(app, list(argv), env={"COLUMNS": "80"})
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1, result.stderr
    return lines[0]


@pytest.mark.parametrize("command", ["run", "serve"])
def test_run_and_serve_refuse_a_cluster_for_another_method(
    command: str, tmp_path: Path, nothing_starts: list[str]
) -> None:
    line = _one_line([command, str(_config(tmp_path)), "--method", "proposed",
                      "--planner-workers", "2"])  # fmt: skip
    assert line.startswith("--planner-workers: only the method `horizon` solves groups"), line
    assert "this mission flies `proposed` (--method horizon)" in line
    assert nothing_starts == []


@pytest.mark.parametrize("command", ["run", "serve"])
def test_run_and_serve_refuse_a_cluster_for_a_horizon_not_decomposed(
    command: str, tmp_path: Path, nothing_starts: list[str]
) -> None:
    line = _one_line([command, str(_config(tmp_path, "none")), "--method", "horizon",
                      "--planner-scheduler", "tcp://127.0.0.1:8786"])  # fmt: skip
    assert line.startswith("--planner-scheduler: only the decomposed horizon"), line
    assert "planner.horizon.decompose: none (set it to targets)" in line
    # The paper's scenario (one target, the horizon by default): refused the same way.
    line = _one_line([command, "paper", "--planner-workers", "2", "--planner-deadline", "0.3"])
    assert line.startswith("--planner-workers/--planner-deadline: only the decomposed"), line
    assert nothing_starts == []


@pytest.mark.parametrize("command", ["run", "serve", "simulate"])
def test_a_deadline_without_a_cluster_is_refused(
    command: str, tmp_path: Path, nothing_starts: list[str]
) -> None:
    argv = [command, str(_config(tmp_path)), "--planner-deadline", "0.5"]
    line = _one_line([*argv, *(["--methods", "horizon"] if command == "simulate" else [])])
    assert line.startswith("--planner-deadline: no cluster to wait for"), line
    assert nothing_starts == []


def test_simulate_refuses_as_run_and_serve_do(tmp_path: Path, nothing_starts: list[str]) -> None:
    line = _one_line(["simulate", str(_config(tmp_path)), "--methods", "proposed",
                      "--planner-workers", "2"])  # fmt: skip
    assert line == (
        "--planner-workers: only the method `horizon` solves groups on a cluster; add it to "
        "--methods"
    )
    line = _one_line(["simulate", str(_config(tmp_path, "none")), "--methods", "horizon",
                      "--planner-workers", "2"])  # fmt: skip
    assert "planner.horizon.decompose: none" in line
    assert nothing_starts == []


@pytest.mark.parametrize("command", ["run", "serve"])
@pytest.mark.parametrize(
    ("options", "expected"),
    [
        ((), None),
        (("--planner-workers", "2"), PlannerCluster(workers=2)),
        (
            ("--planner-scheduler", "tcp://10.1.2.3:8786", "--planner-deadline", "0.25"),
            PlannerCluster(workers=0, scheduler="tcp://10.1.2.3:8786", deadline_s=0.25),
        ),
    ],
    ids=["none", "workers", "scheduler-and-deadline"],
)
def test_the_options_reach_the_service_as_its_planner_cluster(
    command: str,
    options: tuple[str, ...],
    expected: PlannerCluster | None,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Accepted, the options become `LiveOptions.planner_cluster` (the mission itself, which
    starts the cluster, is not flown here); its deadline without --planner-deadline is half
    the slot's planning budget."""
    flown: list[Any] = []
    monkeypatch.setattr("isac_mission.bus.session.check_listen_endpoints", lambda _e: None)
    monkeypatch.setattr("isac_mission.cli.mission.fly", lambda s, opts, **kw: flown.append(opts))
    argv = [command, str(_config(tmp_path)), "--method", "horizon", "--no-console",
            "--plan-budget", "0.8", "--out", str(tmp_path / "out"), *options]  # fmt: skip
    result = CliRunner().invoke(app, argv, env={"COLUMNS": "160"})
    assert result.exit_code == 0, result.output
    (opts,) = flown
    assert opts.planner_cluster == expected
    if expected is not None:
        deadline = opts.planner_cluster.deadline_for(opts.plan_budget_s)
        assert deadline == (expected.deadline_s or 0.4)


def test_the_live_deadline_is_half_the_planning_budget() -> None:
    assert LIVE_DEADLINE_FRACTION == 0.5
    assert live_deadline_s(1.0) == 0.5 and live_deadline_s(None) == DEFAULT_DEADLINE_S
    assert PlannerCluster(2).deadline_for() == DEFAULT_DEADLINE_S  # simulate's
    assert PlannerCluster(2).deadline_for(1.0) == 0.5  # run's and serve's
    assert PlannerCluster(2, deadline_s=3.0).deadline_for(1.0) == 3.0
    local = PlannerCluster(2)
    assert local.where == "a local cluster of 2 workers on 127.0.0.1"
    assert not local.leaves_the_machine
    assert not PlannerCluster(0, "tcp://127.0.0.1:8786").leaves_the_machine
    remote = PlannerCluster(0, "tcp://10.1.2.3:8786")
    assert remote.leaves_the_machine and "not loopback" in remote.where
    with pytest.raises(ValueError, match="workers must be >= 1"):
        PlannerCluster(0)
    with pytest.raises(ValueError, match="deadline must be > 0"):
        PlannerCluster(2, deadline_s=0.0)


class _Executor:
    """A GroupExecutor that records nothing and plans nothing (only its identity matters)."""

    def map(self, jobs: Sequence[GroupJob]) -> list[SlotPlan]:
        raise AssertionError("not planned here")


def _executor_of(kit: SolverKit) -> object:
    return kit.built(DECOMPOSED_KEY, DecomposedHorizon).executor


def test_a_sub_fleet_kit_solves_its_groups_where_the_full_kit_does() -> None:
    """KitCache passes the full kit's executor to every sub-fleet kit it hands out (a vehicle
    lost: a kit of three, of two), to kits made by a KitCache of a renewed full kit (an
    operator's new R_th, as MissionState.set_scenario renews them), and takes it off with
    the full kit's."""
    s = scene.scenario()
    full = SolverKit(s)
    executor = _Executor()
    use_group_executor(full, executor)
    kits = KitCache(full, "sd")
    three, two = kits.for_active((0, 1, 3)), kits.for_active((0, 2))
    assert three.scenario.M == 3 and two.scenario.M == 2
    assert _executor_of(three) is executor and _executor_of(two) is executor

    renewed = full.renewed(s.with_changes(r_th=2 * s.r_th))
    assert _executor_of(renewed) is executor
    again = KitCache(renewed, "sd")
    other = again.for_active((1, 2, 3))
    assert other.scenario.r_th == 2 * s.r_th
    assert _executor_of(other) is executor and _executor_of(again.for_active((1,))) is executor

    use_group_executor(renewed, None)
    assert _executor_of(again.for_active((1, 2, 3))) is None
    assert _executor_of(kits.for_active((0, 1, 3))) is None
    np.testing.assert_array_equal(three.scenario.uav_start_xy, s.uav_start_xy[[0, 1, 3]])


def test_a_kit_cache_of_a_horizon_not_decomposed_sets_no_executor() -> None:
    s = scene.scenario(decompose="none")
    kits = KitCache(SolverKit(s), "sd")
    sub = kits.for_active((0, 1))
    assert DECOMPOSED_KEY not in sub._built


def test_a_scheduler_off_this_machine_is_a_warning_before_anything_connects(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """`serve --planner-scheduler tcp://10.1.2.3:8786`: the service logs that the groups'
    inputs and plans leave this machine before it connects (here the connection is refused
    in-process, so nothing leaves, and the mission does not start)."""
    import asyncio

    from isac_mission.config import load_scenario
    from isac_mission.service.assembly import LiveOptions, Progress, Stopping, run_mission

    def refused(*_args: Any, **_kwargs: Any) -> Any:
        raise RuntimeError("no connection in this test")

    monkeypatch.setattr("isac_mission.planner_cluster.group_executor", refused)
    s = load_scenario(_config(tmp_path))
    cluster = PlannerCluster(workers=0, scheduler="tcp://10.1.2.3:8786")
    opts = LiveOptions(method="horizon", out_dir=tmp_path, planner_cluster=cluster)
    statuses: list[str] = []
    progress = Progress(statuses.append)
    with pytest.raises(RuntimeError, match="no connection in this test"):
        asyncio.run(run_mission(s, opts, Stopping(), progress))
    (warning,) = [r for r in caplog.records if r.levelname == "WARNING"]
    assert "tcp://10.1.2.3:8786 is not on this machine's loopback" in warning.getMessage()
    assert "leave this machine, unencrypted" in warning.getMessage()
    assert statuses == [
        "starting the planner cluster: the scheduler tcp://10.1.2.3:8786 (not loopback: the "
        "groups' inputs and plans leave this machine, unencrypted)"
    ]
    assert not (tmp_path / "trace_horizon.jsonl").exists()
