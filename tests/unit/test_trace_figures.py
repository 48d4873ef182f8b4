"""Figures from traces (experiment/trace_figures.py) equal the Monte Carlo's own per-run figures
(experiment/comparison.py) on the runs those traces record."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from isac_mission.config import Scenario
from isac_mission.experiment.comparison import FIGURES, run_figures
from isac_mission.experiment.montecarlo import run_monte_carlo, trace_path
from isac_mission.experiment.trace_figures import trace_figures
from isac_mission.records import read_trace


def test_trace_figures_match_the_runs_they_record(paper: Scenario, tmp_path: Path) -> None:
    s = dataclasses.replace(paper, N=14)  # slots 11..N exist
    results = run_monte_carlo(s, ["sd"], 2, seed=3, trace_dir=tmp_path)["sd"]
    traces = [read_trace(trace_path(tmp_path, "sd", r)) for r in range(2)]
    got, want = trace_figures(traces), run_figures(results)
    for key in FIGURES:
        np.testing.assert_allclose(got[key], want[key], rtol=1e-9, err_msg=key)
    np.testing.assert_array_equal(got["truth_missing"], [0.0, 0.0])


def test_slots_without_truth_are_left_out_of_the_errors(paper: Scenario, tmp_path: Path) -> None:
    s = dataclasses.replace(paper, N=6)
    run_monte_carlo(s, ["sd"], 1, seed=1, trace_dir=tmp_path)
    trace = read_trace(trace_path(tmp_path, "sd", 0))
    full = trace_figures([trace])
    cut = dataclasses.replace(
        trace,
        slots=[dataclasses.replace(r, target_true=None) if r.slot == 4 else r for r in trace.slots],
    )
    part = trace_figures([cut])
    assert part["truth_missing"][0] == 1.0
    kept = [r for r in trace.slots[1:] if r.slot != 4]
    loc = np.mean([np.sum((r.target_est[:2] - r.target_true[:2]) ** 2) for r in kept])
    np.testing.assert_allclose(part["loc_mse"], [loc])
    np.testing.assert_allclose(part["pcrb"], full["pcrb"])  # the bound needs no truth
