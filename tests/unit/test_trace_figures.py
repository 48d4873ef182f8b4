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


def test_steps_and_the_tracking_phase_from_the_positions(paper: Scenario, tmp_path: Path) -> None:
    """The mean step per UAV per slot and the figures over slots 11..N, recomputed by hand; a
    UAV without a known position (a `held` slot's null) is left out of the steps it ends."""
    s = dataclasses.replace(paper, N=14)
    run_monte_carlo(s, ["proposed"], 1, seed=2, trace_dir=tmp_path)
    trace = read_trace(trace_path(tmp_path, "proposed", 0))
    got = trace_figures([trace])
    xy = trace.stack("uav_xy")
    steps = np.linalg.norm(np.diff(xy, axis=0), axis=2)  # [N - 1, M], step n ends in slot n + 2
    np.testing.assert_allclose(got["step_m"], [steps.mean()])
    np.testing.assert_allclose(got["step_from11_m"], [steps[9:].mean()])
    assert got["step_m"][0] > 1.0  # proposed moves
    err = trace.stack("target_est") - trace.stack("target_true")
    loc = np.sum(err[:, :2] ** 2, axis=1)
    np.testing.assert_allclose(got["loc_mse_from11"], [loc[10:].mean()])
    np.testing.assert_allclose(got["loc_mse"], [loc[1:].mean()])
    unknown = xy.copy()
    unknown[5, 1] = np.nan  # UAV 1 unknown in slot 6: its steps into and out of slot 6 go
    slots = [
        dataclasses.replace(r, uav_xy_m=unknown[i]) if i == 5 else r
        for i, r in enumerate(trace.slots)
    ]
    part = trace_figures([dataclasses.replace(trace, slots=slots)])
    kept = np.ones_like(steps, dtype=bool)
    kept[4, 1] = kept[5, 1] = False
    np.testing.assert_allclose(part["step_m"], [steps[kept].mean()])
