"""`sweep` on a scenario of several targets: a serial sweep of a shortened config/multi-target.yaml
writes the multi-target columns, each equal to an independent recomputation of `simulate`'s run
(experiment/runs.py `fly_run`) with the same seed; a method that plans one target
is refused before any work; the CSV's columns and the plots on hand-made rows (a single-target
sweep's columns as before, GOSPA added)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, cast

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from isac_mission.cli import app
from isac_mission.config import Scenario, parse_scenario
from isac_mission.experiment.runs import fly_run
from isac_mission.experiment.sweep.grid import GridPoint, Value, parse_grid
from isac_mission.experiment.sweep.plots import gospa_plot_name, rmse_plot_name, sweep_figures
from isac_mission.experiment.sweep.runs import TaskRow
from isac_mission.experiment.sweep.summary import (
    MULTI_TARGET_COLUMNS,
    SUMMARY_COLUMNS,
    aggregate,
    sweep_table,
    write_csv,
)
from isac_mission.experiment.track_metrics import RunFigures, TargetFigures, summarize_tracking

ROOT = Path(__file__).resolve().parents[2]
SLOTS = 6
KAPPAS = [0.25, 1.0]
SEED = 5
# The columns of a single-target sweep before GOSPA was added, in their order.
SINGLE_TARGET_COLUMNS = [
    "point",
    "method",
    "runs",
    "loc_rmse",
    "loc_rmse_lo",
    "loc_rmse_hi",
    "vel_rmse",
    "vel_rmse_lo",
    "vel_rmse_hi",
    "pcrb_pos",
    "pcrb_vel",
    "solve_median_ms",
    "infeasible_slots",
    "slots",
]


def _short_multi_target() -> dict[str, Any]:
    """config/multi-target.yaml over SLOTS slots, its entering target in from slot 2."""
    data = yaml.safe_load((ROOT / "config" / "multi-target.yaml").read_text())
    data["timing"]["duration_s"] = SLOTS * data["timing"]["slot_s"]
    data["targets"][1]["appears_s"] = 2
    return dict(data)


def _same(got: str, want: float) -> bool:
    value = float(got)
    return (math.isnan(value) and math.isnan(want)) or value == want  # exactly: the same run


def test_a_serial_sweep_of_several_targets_writes_simulates_figures(tmp_path: Path) -> None:
    config = tmp_path / "short.yaml"
    config.write_text(yaml.safe_dump(_short_multi_target()))
    grid = tmp_path / "grid.yaml"
    grid.write_text(
        f"target_motion.process_noise_intensity: {KAPPAS}\n"
        f"methods: [proposed, sd]\nruns: 1\nseed: {SEED}\n"
    )
    out = tmp_path / "out"
    result = CliRunner().invoke(
        app, ["sweep", str(config), "--grid", str(grid), "--out", str(out), "--serial"]
    )
    assert result.exit_code == 0, result.output
    assert "2 grid points x 2 methods x 1 runs = 4 missions" in result.output
    with (out / "sweep.csv").open() as f:
        reader = csv.DictReader(f)
        header = list(reader.fieldnames or [])
        table = list(reader)
    targets = ["target0_rmse_m", "target0_bound_m2", "target1_rmse_m", "target1_bound_m2"]
    targets += ["target2_rmse_m", "target2_bound_m2"]
    assert header == [
        "target_motion.process_noise_intensity",
        *SINGLE_TARGET_COLUMNS,
        "gospa_m",
        "gospa_m_lo",
        "gospa_m_hi",
        *MULTI_TARGET_COLUMNS,
        *targets,
    ]
    assert [(r["target_motion.process_noise_intensity"], r["method"]) for r in table] == [
        (str(k), m) for k in KAPPAS for m in ("proposed", "sd")
    ]
    assert (out / gospa_plot_name("target_motion.process_noise_intensity")).stat().st_size > 0
    assert not (out / rmse_plot_name("target_motion.process_noise_intensity")).exists()
    runs_header = (out / "runs.csv").read_text().splitlines()[0].split(",")
    assert runs_header[-1] == "gospa_m" and "figures" not in runs_header

    # The same missions, flown as `simulate` flies them: the scenario built from the file
    # without the grid code, the run's noise and a kit of its own.
    for row in table:
        data = _short_multi_target()
        data["target_motion"]["process_noise_intensity"] = float(
            row["target_motion.process_noise_intensity"]
        )
        s = parse_scenario(data, "recomputed")
        method = row["method"]
        run = fly_run(s, method, 0, SEED, None)
        x = summarize_tracking([run.tracking])
        delays = x.confirmation_delays
        want: dict[str, float] = {
            "gospa_m": x.gospa_m,
            "gospa_localisation_m2": x.localisation_m2,
            "gospa_missed_m2": x.missed_m2,
            "gospa_false_m2": x.false_m2,
            "id_switches": x.id_switches,
            "runs_with_false_tracks": x.runs_with_false_tracks,
            "longest_false_run": x.longest_false_run,
            "confirmation_delay_median": float(np.median(delays)) if delays else math.nan,
            "confirmation_delay_max": max(delays) if delays else math.nan,
            "never_confirmed": x.never_confirmed,
        }
        for t in range(3):
            want[f"target{t}_rmse_m"] = x.rmse_m[t]
            want[f"target{t}_bound_m2"] = x.bound_m2[t]
        for column, value in want.items():
            assert _same(row[column], value), (method, column, row[column], value)
        assert math.isfinite(float(row["gospa_m"])) and float(row["gospa_m"]) > 0
        assert math.isfinite(float(row["target0_rmse_m"]))  # the known target is followed
        assert math.isnan(float(row["gospa_m_lo"]))  # one run: no interval
        for column in ("loc_rmse", "vel_rmse", "pcrb_pos", "pcrb_vel"):
            assert math.isnan(float(row[column])), column  # no one labelled target
        assert int(row["slots"]) == SLOTS and int(row["runs"]) == 1


def test_a_method_that_plans_one_target_is_refused_before_any_work(
    tmp_path: Path, horizon_plans_one_target: None
) -> None:
    grid = tmp_path / "grid.yaml"
    grid.write_text("target_motion.process_noise_intensity: [0.5]\nmethods: [sd, horizon]\n")
    out = tmp_path / "out"
    result = CliRunner().invoke(
        app,
        [
            "sweep",
            str(ROOT / "config" / "multi-target.yaml"),
            "--grid",
            str(grid),
            "--out",
            str(out),
            "--serial",
        ],
    )
    assert result.exit_code == 2
    said = " ".join(result.output.split())  # rich wraps the message
    assert "invalid sweep:" in said
    assert "grid point 0: method 'horizon' plans for one target" in said
    assert "missions" not in said and not out.exists()


def _figures(gospa: float, error: float, false_runs: tuple[int, ...]) -> RunFigures:
    """A hand-made run of 4 slots and 2 targets (the second never followed)."""
    followed = TargetFigures(1, 2, 0, np.array([error, error]), np.array([1.0, 3.0]))
    missed = TargetFigures(0, 0, 0, np.zeros(0), np.zeros(0))
    parts = np.full(4, gospa)
    return RunFigures(parts, parts**2, parts, parts, (followed, missed), false_runs)


def _row(point: int, method: str, run: int, figures: RunFigures | None) -> TaskRow:
    nan = math.nan
    if figures is None:
        return TaskRow(point, method, run, run, 1.0 + run, 0.01, 2.0, 0.02, 5.0, 0, 4, 0.5 + run)
    gospa = float(figures.gospa_m.mean())
    return TaskRow(point, method, run, run, nan, nan, nan, nan, 5.0, 0, 4, gospa, figures)


def _points(path: str, values: list[Value]) -> list[GridPoint]:
    return [
        GridPoint(index=i, values=((path, v),), scenario=cast(Scenario, None), key=str(i))
        for i, v in enumerate(values)
    ]


def test_the_columns_of_one_target_stay_and_several_targets_add_theirs(tmp_path: Path) -> None:
    grid = parse_grid({"tracker.kind": ["auto", "multi"], "methods": ["sd"], "runs": 2})
    points = _points("tracker.kind", ["auto", "multi"])
    one = [_row(0, "sd", r, None) for r in range(2)]
    several = [_row(1, "sd", r, _figures(2.0 + r, 4.0, (3,) if r else ())) for r in range(2)]

    (single,) = aggregate(one, points[:1])
    assert single.tracking is None
    assert single.gospa_m == pytest.approx(1.0) and single.gospa_m_lo < 1.0 < single.gospa_m_hi
    path = write_csv([single], grid.paths, tmp_path / "one.csv")
    assert path.read_text().splitlines()[0].split(",") == [
        "tracker.kind",
        *SINGLE_TARGET_COLUMNS,
        "gospa_m",
        "gospa_m_lo",
        "gospa_m_hi",
    ]
    assert SUMMARY_COLUMNS == [*SINGLE_TARGET_COLUMNS, "gospa_m", "gospa_m_lo", "gospa_m_hi"]

    summaries = aggregate([*one, *several], points)
    multi = summaries[1]
    want = summarize_tracking([r.figures for r in several if r.figures is not None])
    assert repr(multi.tracking) == repr(want)  # NaN != NaN: compare the texts
    assert multi.gospa_m == pytest.approx(2.5)
    with write_csv(summaries, grid.paths, tmp_path / "both.csv").open() as f:
        table = list(csv.DictReader(f))
    assert table[0]["target1_rmse_m"] == "" and table[0]["id_switches"] == ""
    assert float(table[0]["loc_rmse"]) == single.loc_rmse
    row = table[1]
    assert float(row["target0_rmse_m"]) == pytest.approx(2.0)  # sqrt of the pooled 4 m^2
    assert float(row["target0_bound_m2"]) == pytest.approx(2.0)
    assert math.isnan(float(row["target1_rmse_m"]))  # never followed
    assert (row["runs_with_false_tracks"], row["longest_false_run"]) == ("0.5", "3")
    assert (row["confirmation_delay_median"], row["confirmation_delay_max"]) == ("1.0", "1")
    assert row["never_confirmed"] == "0" and math.isnan(float(row["loc_rmse"]))

    figures = sweep_figures(summaries, grid)
    assert list(figures) == [rmse_plot_name("tracker.kind"), gospa_plot_name("tracker.kind")]
    (ax,) = figures[gospa_plot_name("tracker.kind")].axes
    assert ax.get_ylabel() == "mission-mean GOSPA [m]" and len(ax.containers) == 1
    assert len(sweep_table(summaries, grid.paths, "t").columns) == 1 + 1 + 4 + 1 + 2 + 2 + 2


def test_a_sweep_of_several_targets_plots_gospa_only() -> None:
    path = "target_motion.process_noise_intensity"
    grid = parse_grid({path: [0.5, 1.0], "methods": ["proposed", "sd"], "runs": 2})
    points = _points(path, [0.5, 1.0])
    rows = [
        _row(p, m, r, _figures(1.0 + p + r, 1.0, ()))
        for p in range(2)
        for m in ("proposed", "sd")
        for r in range(2)
    ]
    figures = sweep_figures(aggregate(rows, points), grid)
    assert list(figures) == [gospa_plot_name(path)]
    (ax,) = figures[gospa_plot_name(path)].axes
    assert ax.get_xlabel() == path
    assert len(ax.containers) == 2  # one line per method
