"""bench/live_compare.py cannot rot: its seeds, its default methods, and its report on traces
(here `simulate`'s traces stand in for both sides, so simulate is exactly "within 10 %")."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.experiment.montecarlo import run_monte_carlo, trace_path
from isac_mission.planning.slot import METHODS

BENCH = Path(__file__).resolve().parents[2] / "bench" / "live_compare.py"


@pytest.fixture(scope="module")
def lc() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_live_compare", BENCH)
    assert spec is not None and spec.loader is not None
    module = sys.modules.setdefault("bench_live_compare", importlib.util.module_from_spec(spec))
    spec.loader.exec_module(module)
    return module


def test_seeds_and_default_methods(lc: ModuleType) -> None:
    assert lc.parse_seeds("1..10") == list(range(1, 11))
    assert lc.parse_seeds("1,2,5") == [1, 2, 5]
    methods = lc.default_methods()
    assert methods[:3] == ["proposed", "sd", "aba"]
    assert ("horizon" in methods) == ("horizon" in METHODS)


def sd_and_comm_traces(
    paper: Scenario, seeds: list[int], tmp_path: Path
) -> dict[str, dict[int, Path]]:
    """One `simulate` trace per seed of sd and comm, 13 slots (so that slots 11..N exist)."""
    s = dataclasses.replace(paper, N=13)
    paths: dict[str, dict[int, Path]] = {"sd": {}, "comm": {}}
    for seed in seeds:
        where = tmp_path / f"seed{seed}"
        run_monte_carlo(s, ["sd", "comm"], 1, seed=seed, trace_dir=where)
        for m in paths:
            paths[m][seed] = trace_path(where, m, 0)
    return paths


def test_report_compares_both_sides_and_reduces_against_sd(
    lc: ModuleType, paper: Scenario, tmp_path: Path
) -> None:
    seeds = [4, 5, 6]
    paths = sd_and_comm_traces(paper, seeds, tmp_path)
    lc.report(["sd", "comm"], seeds, {"live": paths, "simulate": paths}, tmp_path, 1.0, "x", [0])
    out = json.loads((tmp_path / "live_compare.json").read_text())
    assert out["seeds"] == seeds
    assert out["live_exit_codes"] == {"0": 1}
    for m in ("sd", "comm"):
        assert out["figures"][m]["within"] == {"pcrb_from11": True, "step_from11_m": True}
        assert out["figures"][m]["live_vs_simulate_pct"]["pcrb_from11"] == pytest.approx(0.0)
    # comm's tr(PCRB) reduction against sd, recomputed from the per-seed figures.
    for key in ("pcrb", "pcrb_from11"):
        sd = np.array(out["figures"]["sd"]["per_seed"]["live"][key])
        comm = np.array(out["figures"]["comm"]["per_seed"]["live"][key])
        est, low, high = out["reductions"]["live"]["comm"]["sd"][key]
        assert est == pytest.approx(100 * (1 - comm.mean() / sd.mean()))
        assert low <= est <= high


def test_report_flags_a_live_side_off_its_twin(
    lc: ModuleType, paper: Scenario, tmp_path: Path
) -> None:
    """`comm` flown "live" against `sd` offline: the deviation is recomputed from the per-seed
    figures, and the targets are judged on it (sd's parked UAVs take no step at all)."""
    seeds = [4, 5]
    paths = sd_and_comm_traces(paper, seeds, tmp_path)
    traces = {"live": {"sd": paths["comm"]}, "simulate": {"sd": paths["sd"]}}
    lc.report(["sd"], seeds, traces, tmp_path, 1.0, "x", [0, 0])
    row = json.loads((tmp_path / "live_compare.json").read_text())["figures"]["sd"]
    live = np.mean(row["per_seed"]["live"]["pcrb_from11"])
    sim = np.mean(row["per_seed"]["simulate"]["pcrb_from11"])
    dev = row["live_vs_simulate_pct"]["pcrb_from11"]
    assert dev == pytest.approx(100 * (live / sim - 1))
    assert row["within"]["pcrb_from11"] == (abs(dev) <= 20)
    assert row["simulate"]["step_from11_m"] == 0.0  # sd never moves
    assert row["live"]["step_from11_m"] > 0.0
    assert row["within"]["step_from11_m"] is False
