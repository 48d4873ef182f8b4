"""Sweep grids: parsing, the cartesian product over dotted paths, overrides, errors, aggregation."""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from isac_mission.errors import ConfigError
from isac_mission.experiment.sweep.grid import (
    apply_overrides,
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


OLD_PAPER = Path(__file__).resolve().parent / "data" / "scenarios-0.1" / "paper.yaml"
"""0.1.0's paper.yaml: its one target under the deprecated `target:`."""


def _read(path: Path) -> dict[str, Any]:
    data = yaml.safe_load(path.read_text())
    assert isinstance(data, dict)
    return data


def test_an_index_sweeps_a_list_entry_as_the_old_target_key_did(base: dict[str, Any]) -> None:
    rcs = [-10, 0, 10]
    points = expand_grid(base, parse_grid({"targets.0.rcs_dbsm": rcs, "slots": 4}))
    assert [p.values for p in points] == [(("targets.0.rcs_dbsm", v),) for v in rcs]
    assert [p.scenario.rcs_m2 for p in points] == pytest.approx([0.1, 1.0, 10.0], rel=1e-12)
    assert [p.scenario.targets[0].rcs_m2 for p in points] == [p.scenario.rcs_m2 for p in points]
    assert len({p.key for p in points}) == 3
    assert base["targets"][0]["rcs_dbsm"] == -10  # the base mapping is left untouched
    # The old key on the old-form file gives the very same scenarios.
    with pytest.warns(DeprecationWarning, match="target: is deprecated"):
        old = expand_grid(_read(OLD_PAPER), parse_grid({"target.rcs_dbsm": rcs, "slots": 4}))
    for a, b in zip(old, points, strict=True):
        assert a.scenario.rcs_m2 == b.scenario.rcs_m2
        assert a.scenario.targets == b.scenario.targets
        assert a.scenario.trace_config() == b.scenario.trace_config()


def test_an_index_sweeps_a_whole_entry_value_and_indexes_nested_lists(
    base: dict[str, Any],
) -> None:
    states = [[600, 1600, 30, 0], [500, 1400, 20, 5]]
    points = expand_grid(base, parse_grid({"targets.0.initial_state": states, "slots": 4}))
    assert [p.scenario.x0.tolist() for p in points] == states
    with pytest.warns(DeprecationWarning, match="target: is deprecated"):
        old = expand_grid(
            _read(OLD_PAPER), parse_grid({"target.initial_state": states, "slots": 4})
        )
    assert [p.scenario.x0.tolist() for p in old] == states
    # An index into a list of a list entry: the target's vx; a UAV's start point.
    grid = parse_grid({"targets.0.initial_state.2": [20], "uavs.start_xy_m.1": [[900, 1000]]})
    (p,) = expand_grid(base, grid)
    assert p.scenario.x0.tolist() == [600, 1600, 20, 0]
    assert p.scenario.uav_start_xy.tolist() == [[1500, 2300], [900, 1000], [2193, 1100]]
    assert base["uavs"]["start_xy_m"][1] == [807, 1100]


def test_an_index_picks_its_entry_of_several() -> None:
    multi = _read(ROOT / "config" / "multi-target.yaml")
    points = expand_grid(multi, parse_grid({"targets.1.rcs_dbsm": [-10, 0]}))
    assert [p.scenario.targets[1].rcs_m2 for p in points] == pytest.approx([0.1, 1.0])
    for p in points:
        assert p.scenario.targets[0].rcs_m2 == pytest.approx(0.1)
        assert p.scenario.targets[2].rcs_m2 == pytest.approx(10 ** (-0.7))


@pytest.mark.parametrize(
    ("path", "needle"),
    [
        ("targets.x.rcs_dbsm", "targets is a list: index it by a non-negative integer (got 'x')"),
        ("targets.-1.rcs_dbsm", "targets is a list: index it by a non-negative integer"),
        ("targets.01.rcs_dbsm", "index it by a non-negative integer (got '01')"),
        ("targets.0", "targets.0: is a section, not a value"),
        ("targets.0.rcs", "unknown key 'rcs' under targets.0"),
        ("targets.0.rcs_dbsm.0", "targets.0.rcs_dbsm is not a section or a list"),
        ("targets.0.initial_state.4", "index 4 is out of range: targets.0.initial_state has 4"),
        ("uavs.0", "unknown key '0' under uavs"),
    ],
)
def test_bad_indexes_are_rejected_with_the_path(path: str, needle: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_grid({path: [1]}, "grid.yaml")
    assert str(err.value).startswith(f"grid.yaml: {path}: ")
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_paths_one_inside_the_other_are_rejected() -> None:
    with pytest.raises(
        ConfigError, match=r"uavs\.count and uavs\.start_xy_m\.1 cannot both be swept"
    ):
        parse_grid({"uavs.count": [3], "uavs.start_xy_m.1": [[0, 0]]}, "grid.yaml")
    with pytest.raises(
        ConfigError,
        match=r"^grid\.yaml: targets and targets\.0\.rcs_dbsm cannot both be swept \(one is",
    ):
        parse_grid({"targets.0.rcs_dbsm": [0], "targets": [[]]}, "grid.yaml")


def test_an_index_the_config_cannot_take_is_one_line_naming_the_path(
    base: dict[str, Any],
) -> None:
    grid = parse_grid({"targets.1.rcs_dbsm": [-10, 0, 10], "uavs.start_xy_m.3": [[1, 2]]})
    with pytest.raises(ConfigError) as err:
        expand_grid(base, grid, "paper.yaml")
    assert str(err.value).splitlines() == [
        "paper.yaml: targets.1.rcs_dbsm: index 1 is out of range: targets has 1 entry in the "
        "config",
        "paper.yaml: uavs.start_xy_m.3: index 3 is out of range: uavs.start_xy_m has 3 entries "
        "in the config",
    ]
    # A list the config leaves out has no entries to change (a grid never adds one).
    with pytest.raises(ConfigError) as err:
        expand_grid(base, parse_grid({"base_stations.xy_m.0": [[1, 2]]}), "paper.yaml")
    assert str(err.value) == (
        "paper.yaml: base_stations.xy_m.0: index 0 is out of range: the config gives no "
        "base_stations.xy_m"
    )
    with pytest.raises(ConfigError) as err:
        expand_grid(_read(OLD_PAPER), parse_grid({"targets.0.rcs_dbsm": [0]}), "old.yaml")
    assert str(err.value) == (
        "old.yaml: targets.0.rcs_dbsm: index 0 is out of range: the config gives no targets "
        "(it gives its target under the deprecated target:, e.g. target.rcs_dbsm)"
    )


@pytest.mark.parametrize(
    ("targets", "needle"),
    [
        (
            {"0": {"rcs_dbsm": -10}},
            "targets.0.rcs_dbsm: targets is not a list in the config (a mapping)",
        ),
        ("secret", "targets.0.rcs_dbsm: targets is not a list in the config (a string)"),
        ([5], "targets.0.rcs_dbsm: targets.0 is not a mapping in the config (a number)"),
        ([None], "targets.0.rcs_dbsm: targets.0 is not a mapping in the config (null)"),
    ],
)
def test_an_entry_of_the_wrong_kind_is_named_not_echoed(
    base: dict[str, Any], targets: Any, needle: str
) -> None:
    bad = {**base, "targets": targets}
    with pytest.raises(ConfigError) as err:
        expand_grid(bad, parse_grid({"targets.0.rcs_dbsm": [0]}), "bad.yaml")
    assert str(err.value) == f"bad.yaml: {needle}"
    with pytest.raises(ConfigError, match=re.escape(needle)):
        apply_overrides(bad, [("targets.0.rcs_dbsm", 0)], None)


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
