"""Every registered planning method through the one protocol (planning/registry.py).

Each method plans a slot, prepares its kit ahead, and in a short closed loop on paper.yaml flies
plans that the independent checker (tests/support/independent/constraints.py, written from the
paper's equations without the planner's code) finds within 14a-14j wherever the method's report
says "ok". The registry is what the CLI, the settings and the reports read.
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.errors import ConfigError
from isac_mission.experiment.montecarlo import run_monte_carlo, trace_path
from isac_mission.experiment.report import LABELS as REPORT_LABELS
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.problem import SlotInput, warm_up_input
from isac_mission.planning.registry import LABELS, METHODS, REGISTRY, check_method, planner
from isac_mission.planning.slot import plan_slot, warm_up
from isac_mission.records import SlotRecord, read_trace
from isac_mission.service.ground.settings import GroundSettings
from tests.support.independent.constraints import check_constraints

N_SLOTS = 4


@pytest.fixture(scope="module")
def traces(paper: Scenario, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 4-slot closed loop of every registered method (seed 3)."""
    out = tmp_path_factory.mktemp("protocol")
    run_monte_carlo(dataclasses.replace(paper, N=N_SLOTS), list(METHODS), 1, seed=3, trace_dir=out)
    return out


@pytest.mark.parametrize("method", METHODS)
def test_every_method_plans_a_slot_and_names_its_status(paper: Scenario, method: str) -> None:
    kit = SolverKit(paper)
    planner(method).prepare(kit)
    plan = plan_slot(warm_up_input(kit), kit, method)
    assert plan.report.status in ("ok", "infeasible")
    assert plan.uav_xy_m.shape == (paper.M, 2)
    assert plan.bandwidth_share.shape == (paper.M,)
    assert abs(float(plan.bandwidth_share.sum()) - 1.0) < 1e-9
    assert np.isfinite(plan.pcrb_trace) and plan.pcrb_trace > 0
    if plan.report.status != "ok":
        assert plan.report.reason and plan.report.fallback


@pytest.mark.parametrize("method", METHODS)
def test_every_methods_ok_plans_pass_the_independent_check(traces: Path, method: str) -> None:
    trace = read_trace(trace_path(traces, method, 0))
    assert len(trace.slots) == N_SLOTS
    ok = [r.slot for r in trace.slots if r.status == "ok"]
    assert ok, f"{method}: no slot planned"
    violations = [v for v in check_constraints(trace, tol_m=1e-6) if v.slot in ok]
    assert violations == []


def test_the_registry_is_what_names_methods() -> None:
    assert METHODS == tuple(r.name for r in REGISTRY)
    assert len(set(METHODS)) == len(METHODS)
    assert REPORT_LABELS == LABELS and set(LABELS) == set(METHODS)
    for name in METHODS:
        assert check_method(name) == name
        assert hasattr(planner(name), "plan") and hasattr(planner(name), "prepare")
    with pytest.raises(ValueError, match="unknown planning method 'nope'; choose from proposed"):
        check_method("nope")
    with pytest.raises(ValueError, match="choose from"):
        planner("nope")


def test_the_ground_settings_take_only_registered_methods() -> None:
    assert GroundSettings(method="horizon").method == "horizon"
    with pytest.raises(ConfigError, match=r"method.*unknown planning method 'greedy'"):
        GroundSettings(method="greedy")


def test_the_cli_help_lists_the_registry() -> None:
    from typer.testing import CliRunner

    from isac_mission.cli.app import app

    for command in ("simulate", "run", "serve"):
        result = CliRunner().invoke(app, [command, "--help"], env={"COLUMNS": "400"})
        assert result.exit_code == 0
        text = " ".join(result.output.split())
        assert ", ".join(METHODS) in text, command


def test_the_old_field_names_still_work_and_warn(paper: Scenario) -> None:
    kit = SolverKit(paper)
    new = warm_up_input(kit)
    with pytest.warns(DeprecationWarning, match="is deprecated") as caught:
        old = SlotInput(
            prev_xy=new.prev_xy_m,
            prev_eta=new.prev_bandwidth_share,
            prev_assoc=None,
            targets=new.targets,
        )
    assert "SlotInput.prev_xy is deprecated: use SlotInput.prev_xy_m" in {
        str(w.message) for w in caught
    }
    assert len(caught) == 3
    assert np.array_equal(old.prev_xy_m, new.prev_xy_m)
    with pytest.warns(DeprecationWarning, match=r"SlotInput.prev_eta is deprecated"):
        assert old.prev_eta is old.prev_bandwidth_share
    with pytest.warns(DeprecationWarning, match="SlotInput.keep_out_xy is deprecated"):
        moved = dataclasses.replace(new, keep_out_xy=np.zeros((1, 2)))
    assert moved.keep_out_xy_m is not None and moved.keep_out_xy_m.shape == (1, 2)
    assert plan_slot(old, kit, "sd").report.status == plan_slot(new, kit, "sd").report.status

    line = {
        "slot": 1,
        "method": "sd",
        "status": "ok",
        "uav_xy": [[0.0, 0.0]],
        "eta": [1.0],
        "assoc": [0],
        "target_true": None,
        "target_est": [0.0] * 4,
        "target_pred": [0.0] * 4,
        "r_diag": [1.0, 1.0],
        "pcrb_trace": 1.0,
        "solve_ms": 1.0,
        "P": np.eye(4).tolist(),
        "J": np.eye(4).tolist(),
    }
    rec = SlotRecord.from_dict(line)
    assert rec.to_dict()["uav_xy"] == [[0.0, 0.0]] and rec.to_dict()["eta"] == [1.0]
    with pytest.warns(DeprecationWarning, match=r"SlotRecord.eta is deprecated: use "):
        assert rec.eta is rec.bandwidth_share
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert rec.uav_xy_m.tolist() == [[0.0, 0.0]]


def _documented_blocks() -> list[str]:
    """The python blocks of docs/architecture.md's "Adding a planning method"."""
    text = (Path(__file__).parents[2] / "docs" / "architecture.md").read_text()
    section = text.split("### Adding a planning method", 1)[1].split("\n## ", 1)[0]
    return [block.split("```", 1)[0] for block in section.split("```python\n")[1:]]


def test_the_documented_example_method_plans(
    paper: Scenario, monkeypatch: pytest.MonkeyPatch
) -> None:
    import types

    from isac_mission.planning import registry

    module_code, registry_line = _documented_blocks()
    module = types.ModuleType("isac_mission.planning.chase")
    exec(compile(module_code, "docs/architecture.md", "exec"), module.__dict__)
    monkeypatch.setitem(__import__("sys").modules, "isac_mission.planning.chase", module)
    line = next(ln for ln in registry_line.splitlines() if ln.strip().startswith("Registered("))
    entry = eval(line.strip().rstrip(","), vars(registry))
    monkeypatch.setattr(registry, "REGISTRY", (*registry.REGISTRY, entry))
    monkeypatch.setattr(registry, "METHODS", (*registry.METHODS, entry.name))
    registry.planner.cache_clear()
    try:
        kit = SolverKit(paper)
        warm_up(kit, "chase")
        plan = plan_slot(warm_up_input(kit), kit, "chase")
    finally:
        registry.planner.cache_clear()
    assert plan.report.status in ("ok", "infeasible")
    step = np.linalg.norm(plan.uav_xy_m - paper.uav_start_xy, axis=1)
    assert np.all(step <= paper.v_max * paper.dt + 1e-9) and np.all(step > 0)
