"""The public API of `import isac_mission as im`: every name resolves, the version is the
package's, and the notebook helpers compose the library's own pieces without changing them."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

import isac_mission as im
from isac_mission import api
from isac_mission.config import load_scenario
from isac_mission.experiment.montecarlo import run_monte_carlo, trace_path
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import plan_slot
from isac_mission.records import read_trace

ROOT = Path(__file__).resolve().parents[2]


def test_every_public_name_resolves_and_is_listed() -> None:
    assert set(im.__all__) == {"__version__", *im._EXPORTS}
    for name in im.__all__:
        assert getattr(im, name) is not None
    assert set(im.__all__) <= set(dir(im))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        _ = im.nope  # type: ignore[attr-defined]


def test_the_version_has_one_source() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "version" not in project
    assert "version" in project["dynamic"]
    assert im.__version__.count(".") == 2


def test_first_slot_input_starts_at_the_start_points() -> None:
    s = load_scenario("paper")
    inp = api.first_slot_input(s)
    assert np.array_equal(inp.prev_xy_m, s.uav_start_xy)
    assert inp.prev_bandwidth_share.shape == (
        s.M,
    ) and inp.prev_bandwidth_share.sum() == pytest.approx(1.0)
    assert inp.prev_bs_of_uav is None
    assert inp.lead.state_pred.shape == (4,) and inp.lead.prior_information.shape == (4, 4)
    # One slot of the constant-velocity model from x0.
    assert np.allclose(inp.lead.state_pred[:2], s.x0[:2] + s.dt * s.x0[2:])


def test_plan_slot_is_the_planner_on_the_first_slot_input() -> None:
    s = load_scenario("paper")
    kit = SolverKit(s)
    mine = im.plan_slot(s, kit=kit)
    direct = plan_slot(api.first_slot_input(s), kit, "proposed")
    assert mine.report.status == direct.report.status == "ok"
    assert np.array_equal(mine.uav_xy_m, direct.uav_xy_m)
    assert np.array_equal(mine.bandwidth_share, direct.bandwidth_share)
    assert mine.pcrb_trace == direct.pcrb_trace


def test_run_closed_loop_traces_what_simulate_writes(tmp_path: Path) -> None:
    s = load_scenario("paper").with_changes(N=3)
    kit = SolverKit(s)
    run = im.run_closed_loop(s, seed=7, kit=kit)
    run_monte_carlo(s, ["proposed"], runs=1, seed=7, trace_dir=tmp_path)
    on_disk = read_trace(trace_path(tmp_path, "proposed", 0))
    assert run.trace.config == on_disk.config
    assert len(run.trace) == len(on_disk) == 3
    timing = {"solve_ms"}
    for mine, theirs in zip(run.trace, on_disk, strict=True):
        a, b = mine.to_dict(), theirs.to_dict()
        assert {k: v for k, v in a.items() if k not in timing} == {
            k: v for k, v in b.items() if k not in timing
        }
    assert run.result.est.shape == (3, 4)
    assert run.trace.method == "proposed"
