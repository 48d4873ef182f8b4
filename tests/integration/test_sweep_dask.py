"""Sweep on a local Dask cluster of 2 worker processes: the same numbers as the serial run, and
every socket of the cluster on 127.0.0.1."""

from __future__ import annotations

import urllib.error
import urllib.request
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import psutil
import pytest
import yaml

from isac_mission.experiment.sweep.cluster import cluster_addresses, dask_client, run_dask
from isac_mission.experiment.sweep.grid import expand_grid, parse_grid
from isac_mission.experiment.sweep.runs import TaskRow, make_tasks, run_serial
from isac_mission.experiment.sweep.summary import aggregate
from tests.support.ports import listening_hosts

ROOT = Path(__file__).resolve().parents[2]
# Wall-clock solve times differ between runs; everything else must be identical.
TIMING_FIELDS = {"solve_median_ms"}


def _numbers(row: Any) -> dict[str, Any]:
    """Every field but the timings and a multi-target run's figures (compared on their own)."""
    return {k: v for k, v in asdict(row).items() if k not in TIMING_FIELDS | {"figures"}}


def _http_status(url: str) -> int:
    try:
        with urllib.request.urlopen(url, timeout=10) as resp:
            return int(resp.status)
    except urllib.error.HTTPError as err:
        return int(err.code)


@pytest.mark.timeout(300)
def test_dask_sweep_equals_serial_and_binds_loopback() -> None:
    base = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    grid = parse_grid(
        {
            "uavs.max_speed_mps": [15, 25],
            "methods": ["proposed", "sd"],
            "runs": 2,
            "slots": 8,
        }
    )
    points = expand_grid(base, grid)
    tasks = make_tasks(points, grid, seed=3)
    assert len(tasks) == 8

    serial = run_serial(tasks)
    done: list[TaskRow] = []
    with dask_client(None, workers=2) as client:
        info = client.scheduler_info()
        assert len(info["workers"]) == 2
        assert all(w["nthreads"] == 1 for w in info["workers"].values())
        addresses = cluster_addresses(client)
        hosts = listening_hosts()
        status_code = _http_status(f"http://127.0.0.1:{info['services']['dashboard']}/status")
        distributed_rows = run_dask(client, tasks, done.append)
        # The work really ran in the worker processes (their pids are not ours).
        worker_pids = set(client.run(lambda: __import__("os").getpid()).values())
    assert len(worker_pids) == 2 and psutil.Process().pid not in worker_pids

    assert len(addresses) == 3
    assert all(a.startswith("tcp://127.0.0.1:") for a in addresses), addresses
    assert hosts == {"127.0.0.1"}, hosts
    assert status_code == 404  # no Bokeh dashboard behind the scheduler's loopback HTTP port

    assert len(done) == len(tasks)
    assert [(r.point, r.method, r.run) for r in distributed_rows] == [
        (t.point, t.method, t.run) for t in tasks
    ]
    for a, b in zip(serial, distributed_rows, strict=True):
        assert _numbers(a) == _numbers(b)
    # Aggregates are then equal too, and the sweep actually distinguishes its points and methods.
    agg_serial = [_numbers(s) for s in aggregate(serial, points)]
    agg_dask = [_numbers(s) for s in aggregate(distributed_rows, points)]
    assert agg_serial == agg_dask
    assert len({s["loc_rmse"] for s in agg_serial}) > 1
    assert {r.seed for r in serial} == {3, 4}


def _same_figures(a: TaskRow, b: TaskRow) -> bool:
    """The runs' multi-target figures are equal, array by array (NaN equal to NaN)."""
    assert a.figures is not None and b.figures is not None
    fa, fb = a.figures, b.figures
    arrays = [(fa.gospa_m, fb.gospa_m), (fa.localisation_m2, fb.localisation_m2)]
    arrays += [(fa.missed_m2, fb.missed_m2), (fa.false_m2, fb.false_m2)]
    for ta, tb in zip(fa.targets, fb.targets, strict=True):
        if (ta.seen_slot, ta.confirmed_slot, ta.id_switches) != (
            tb.seen_slot,
            tb.confirmed_slot,
            tb.id_switches,
        ):
            return False
        arrays += [(ta.squared_error_m2, tb.squared_error_m2), (ta.bound_m2, tb.bound_m2)]
    return fa.false_track_runs == fb.false_track_runs and all(
        np.array_equal(x, y, equal_nan=True) for x, y in arrays
    )


@pytest.mark.timeout(300)
def test_dask_sweep_of_several_targets_equals_serial() -> None:
    base = yaml.safe_load((ROOT / "config" / "multi-target.yaml").read_text())
    base["targets"][1]["appears_s"] = 2  # in the scene within the short mission
    grid = parse_grid(
        {
            "target_motion.process_noise_intensity": [0.25, 1.0],
            "methods": ["proposed", "sd"],
            "runs": 1,
            "slots": 5,
        }
    )
    points = expand_grid(base, grid)
    tasks = make_tasks(points, grid, seed=3)
    serial = run_serial(tasks)
    with dask_client(None, workers=2) as client:
        distributed_rows = run_dask(client, tasks)
    for a, b in zip(serial, distributed_rows, strict=True):
        assert repr(_numbers(a)) == repr(_numbers(b))  # the one target's columns: NaN
        assert _same_figures(a, b)
    agg_serial = [repr(_numbers(s)) for s in aggregate(serial, points)]
    assert agg_serial == [repr(_numbers(s)) for s in aggregate(distributed_rows, points)]
    assert all(s.tracking is not None for s in aggregate(serial, points))
    assert len({r.gospa_m for r in serial}) > 1


def test_cli_sweep_serial_writes_csv_and_plots(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from isac_mission.cli import app

    grid = tmp_path / "grid.yaml"
    grid.write_text("radio.rate_min_bps: [1.0e7, 2.0e7]\nmethods: [sd]\nruns: 2\nslots: 3\n")
    out = tmp_path / "out"
    args = ["sweep", str(ROOT / "config" / "paper.yaml"), "--grid", str(grid), "--out", str(out)]
    result = CliRunner().invoke(app, [*args, "--serial"])
    assert result.exit_code == 0, result.output
    assert "2 grid points x 1 methods x 2 runs = 4 missions" in result.output
    lines = (out / "sweep.csv").read_text().splitlines()
    assert lines[0].startswith("radio.rate_min_bps,point,method,runs,loc_rmse,loc_rmse_lo")
    assert len(lines) == 3
    assert len((out / "runs.csv").read_text().splitlines()) == 5
    assert (out / "rmse_vs_radio_rate_min_bps.png").stat().st_size > 0


def test_cli_sweep_rejects_a_bad_point_before_any_work(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from isac_mission.cli import app

    grid = tmp_path / "grid.yaml"
    grid.write_text("uavs.max_speed_mps: [25, 0]\nslots: 3\n")
    out = tmp_path / "out"
    result = CliRunner().invoke(
        app,
        ["sweep", str(ROOT / "config" / "paper.yaml"), "--grid", str(grid), "--out", str(out)],
    )
    assert result.exit_code == 2
    assert "grid point 1 (uavs.max_speed_mps=0)" in result.output
    assert not out.exists()


def test_cli_sweep_without_dask_names_the_extra_and_serial_still_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import sys

    from typer.testing import CliRunner

    from isac_mission.cli import app

    for name in ("dask", "distributed"):
        monkeypatch.setitem(sys.modules, name, None)  # as if the extra were not installed
    grid = tmp_path / "grid.yaml"
    grid.write_text("uavs.max_speed_mps: [20, 25]\nmethods: [sd]\nruns: 1\nslots: 2\n")
    out = tmp_path / "out"
    args = ["sweep", str(ROOT / "config" / "paper.yaml"), "--grid", str(grid), "--out", str(out)]
    result = CliRunner().invoke(app, [*args, "--workers", "2", "--no-plots"])
    assert result.exit_code == 2, result.output
    assert "isac-mission[sweep]" in result.output
    assert not out.exists()
    result = CliRunner().invoke(app, [*args, "--serial", "--no-plots"])
    assert result.exit_code == 0, result.output
    assert len((out / "sweep.csv").read_text().splitlines()) == 3
