"""Sweep grids: parsing, the cartesian product over dotted paths, overrides, errors, aggregation."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from isac_mission.errors import ConfigError
from isac_mission.experiment.sweep.grid import (
    expand_grid,
    load_grid,
    parse_grid,
    ring_start_points,
)
from isac_mission.experiment.sweep.runs import (
    TaskRow,
    limit_blas_threads,
    make_tasks,
    plan_sweep,
)
from isac_mission.experiment.sweep.summary import aggregate, t_interval, write_csv

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def base() -> dict[str, Any]:
    data = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    assert isinstance(data, dict)
    return data


def test_cartesian_product_over_dotted_paths(base: dict[str, Any]) -> None:
    grid = parse_grid(
        {
            "uavs.max_speed_mps": [15, 25],
            "radio.rate_min_bps": [1e7, 2e7, 3e7],
            "planner.max_ao_iterations": [4],
        }
    )
    assert grid.paths == ("uavs.max_speed_mps", "radio.rate_min_bps", "planner.max_ao_iterations")
    points = expand_grid(base, grid)
    assert len(points) == 6
    got = [
        (p.scenario.v_max, p.scenario.r_th, p.scenario.planner.max_ao_iterations) for p in points
    ]
    assert got == [(v, r, 4) for v in (15.0, 25.0) for r in (1e7, 2e7, 3e7)]
    assert [p.index for p in points] == list(range(6))
    assert len({p.key for p in points}) == 6
    # The base mapping is left untouched.
    assert base["uavs"]["max_speed_mps"] == 25


def test_yaml11_number_strings_become_numbers() -> None:
    grid = parse_grid(yaml.safe_load("radio.rate_min_bps: [1.0e7, 3e+7, 2]\nplanner.solver: [SCS]"))
    assert grid.axes[0][1] == (1.0e7, 3.0e7, 2)
    assert isinstance(grid.axes[0][1][0], float) and isinstance(grid.axes[0][1][2], int)
    assert grid.axes[1][1] == ("SCS",)


def test_defaults_and_reserved_keys() -> None:
    g = parse_grid({"uavs.max_speed_mps": [20]})
    assert (g.methods, g.runs, g.seed, g.slots) == (("proposed",), 4, None, None)
    g = parse_grid(
        {"uavs.max_speed_mps": [20], "methods": ["sd", "proposed"], "runs": 2, "seed": 7}
    )
    assert (g.methods, g.runs, g.seed) == (("sd", "proposed"), 2, 7)


def test_slots_override_sets_the_duration(base: dict[str, Any]) -> None:
    (p,) = expand_grid(base, parse_grid({"uavs.max_speed_mps": [25], "slots": 8}))
    assert p.scenario.N == 8
    (p,) = expand_grid(base, parse_grid({"timing.slot_s": [0.5], "slots": 8}))
    assert (p.scenario.N, p.scenario.dt) == (8, 0.5)
    (p,) = expand_grid(base, parse_grid({"uavs.max_speed_mps": [25]}))
    assert p.scenario.N == 60


@pytest.mark.parametrize(
    ("grid", "needle"),
    [
        ({"uavs.max_speed": [1]}, "uavs.max_speed: unknown key 'max_speed' under uavs"),
        ({"uav.max_speed_mps": [1]}, "unknown key 'uav' under the top level"),
        ({"radio": [1]}, "radio: is a section"),
        ({"uavs.max_speed_mps.x": [1]}, "uavs.max_speed_mps is not a section"),
        ({"uavs.max_speed_mps": 25}, "uavs.max_speed_mps: must be a non-empty list"),
        ({"uavs.max_speed_mps": []}, "uavs.max_speed_mps: must be a non-empty list"),
        ({"uavs.max_speed_mps": [25], "methods": ["best"]}, "methods: must be a non-empty list"),
        ({"uavs.max_speed_mps": [25], "runs": 0}, "runs: must be an integer >= 1"),
        ({"uavs.max_speed_mps": [25], "slots": 2.5}, "slots: must be an integer >= 1"),
        ({"uavs.count": [3, 0]}, "uavs.count: values must be integers >= 1"),
        ({"uavs.count": [3], "uavs.start_xy_m": [[[0, 0]]]}, "cannot both be swept"),
        ([1, 2], "non-empty mapping"),
    ],
)
def test_bad_grids_are_rejected_with_the_key(grid: Any, needle: str) -> None:
    with pytest.raises(ConfigError, match=r"grid\.yaml") as err:
        parse_grid(grid, "grid.yaml")
    assert needle in str(err.value)


def test_bad_value_names_the_point_path_and_value(base: dict[str, Any]) -> None:
    grid = parse_grid({"uavs.max_speed_mps": [25, -3], "radio.rate_min_bps": [1e7]})
    with pytest.raises(ConfigError) as err:
        expand_grid(base, grid, "paper.yaml")
    msg = str(err.value)
    assert "grid point 1 (uavs.max_speed_mps=-3, radio.rate_min_bps=10000000.0)" in msg
    assert "uavs.max_speed_mps" in msg and "greater than 0" in msg
    assert "grid point 0" not in msg


def test_wrong_type_value_is_rejected(base: dict[str, Any]) -> None:
    with pytest.raises(ConfigError, match=r"planner\.association=\"sometimes\""):
        expand_grid(base, parse_grid({"planner.association": ["keep", "sometimes"]}))


def test_uav_count_places_a_ring(base: dict[str, Any]) -> None:
    points = expand_grid(base, parse_grid({"uavs.count": [3, 6], "slots": 4}))
    assert [p.scenario.M for p in points] == [3, 6]
    six = points[1].scenario.uav_start_xy
    centre = np.mean(np.asarray(base["uavs"]["start_xy_m"], dtype=float), axis=0)
    radii = np.linalg.norm(six - centre, axis=1)
    np.testing.assert_allclose(radii, radii[0], rtol=1e-9)
    first = np.asarray(base["uavs"]["start_xy_m"][0], dtype=float) - centre
    bearing = (six[0] - centre) / radii[0]
    np.testing.assert_allclose(bearing, first / np.linalg.norm(first), atol=1e-9)
    gaps = np.linalg.norm(np.diff(np.vstack([six, six[:1]]), axis=0), axis=1)
    np.testing.assert_allclose(gaps, gaps[0], rtol=1e-9)


def test_uav_count_beyond_capacity_is_rejected(base: dict[str, Any]) -> None:
    with pytest.raises(ConfigError, match=r"grid point 0 \(uavs\.count=16\).*M > K \* N_a"):
        expand_grid(base, parse_grid({"uavs.count": [16]}))


def test_single_uav_ring_uses_a_quarter_of_the_area() -> None:
    pts = ring_start_points([[1000.0, 1000.0]], [3000.0, 2000.0], 4)
    np.testing.assert_allclose(np.linalg.norm(np.asarray(pts) - 1000.0, axis=1), 500.0)


def test_tasks_share_seeds_across_methods_and_points(base: dict[str, Any]) -> None:
    grid = parse_grid({"uavs.max_speed_mps": [15, 25], "methods": ["proposed", "sd"], "runs": 3})
    tasks = make_tasks(expand_grid(base, grid), grid, seed=10)
    assert len(tasks) == 2 * 2 * 3
    assert {(t.point, t.method, t.run) for t in tasks} == {
        (p, m, r) for p in (0, 1) for m in ("proposed", "sd") for r in range(3)
    }
    assert all(t.seed == 10 + t.run for t in tasks)


def test_plan_sweep_reads_both_files(tmp_path: Path) -> None:
    g = tmp_path / "grid.yaml"
    g.write_text("uavs.max_speed_mps: [15, 25]\nruns: 2\nslots: 5\nseed: 3\n")
    plan = plan_sweep(ROOT / "config" / "paper.yaml", g)
    assert (len(plan.points), len(plan.tasks), plan.seed, plan.mission_id) == (2, 4, 3, "paper")
    assert plan_sweep(ROOT / "config" / "paper.yaml", g, seed=9).seed == 9
    example = load_grid(ROOT / "config" / "grids" / "example.yaml")
    assert len(example.combinations()) == 4
    (tmp_path / "bad.yaml").write_text("uavs: [oops\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_grid(tmp_path / "bad.yaml")


def test_t_interval_matches_the_textbook_value() -> None:
    mean, lo, hi = t_interval([1.0, 2.0, 3.0])
    half = 4.302652729911275 / math.sqrt(3)  # t_{0.975, 2} * s / sqrt(n), s = 1
    assert (mean, lo, hi) == pytest.approx((2.0, 2.0 - half, 2.0 + half), rel=1e-9)
    mean, lo, hi = t_interval([5.0])
    assert mean == 5.0 and math.isnan(lo) and math.isnan(hi)


def _row(point: int, method: str, run: int, loc: float) -> TaskRow:
    return TaskRow(point, method, run, run, loc, loc / 100, 1.0 + run, 0.1, 5.0 + run, run % 2, 8)


def test_aggregate_and_csv(base: dict[str, Any], tmp_path: Path) -> None:
    grid = parse_grid({"uavs.max_speed_mps": [15, 25], "methods": ["proposed", "sd"], "runs": 3})
    points = expand_grid(base, grid)
    rows = [
        _row(p, m, r, loc=(r + 1) * (2.0 if m == "sd" else 1.0) + p)
        for r in (2, 0, 1)
        for p in (1, 0)
        for m in ("sd", "proposed")
    ]
    out = aggregate(rows, points)
    assert [(s.point, s.method) for s in out] == [
        (0, "proposed"),
        (0, "sd"),
        (1, "proposed"),
        (1, "sd"),
    ]
    s = out[0]
    _, lo, hi = t_interval([1.0, 2.0, 3.0])
    assert s.loc_rmse == pytest.approx(math.sqrt(2.0), rel=1e-12)
    assert (s.loc_rmse_lo, s.loc_rmse_hi) == pytest.approx((0.0, math.sqrt(hi)), rel=1e-12)
    assert lo < 0  # clipped at 0 before the square root
    assert s.vel_rmse == pytest.approx(math.sqrt(0.02), rel=1e-12)
    assert (s.pcrb_pos, s.solve_median_ms, s.infeasible_slots, s.slots) == (2.0, 6.0, 1, 24)
    assert s.values == (("uavs.max_speed_mps", 15),)
    path = write_csv(out, grid.paths, tmp_path / "sweep.csv")
    with path.open() as f:
        table = list(csv.DictReader(f))
    assert len(table) == 4
    assert table[3]["uavs.max_speed_mps"] == "25" and table[3]["method"] == "sd"
    assert float(table[0]["loc_rmse"]) == s.loc_rmse


def test_limit_blas_threads_sets_numpys_openblas_to_one_thread() -> None:
    import ctypes

    paths = limit_blas_threads(1)
    numpy_blas = [p for p in paths if "numpy" in p]
    if not numpy_blas:
        pytest.skip("numpy is not linked against a loadable OpenBLAS here")
    lib = ctypes.CDLL(numpy_blas[0])
    getter = next(
        getattr(lib, n)
        for n in ("scipy_openblas_get_num_threads64_", "openblas_get_num_threads")
        if hasattr(lib, n)
    )
    assert getter() == 1
