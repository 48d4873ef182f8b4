"""Scenario files: derived constants, and bad input rejected with the field, value and reason."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
import yaml

from isac_mission.config import (
    SCENARIOS_DIR,
    load_scenario,
    parse_scenario,
    scenario_names,
    scenario_path,
)
from isac_mission.config.loading import load_yaml
from isac_mission.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]


def test_paper_constants_match_independent_arithmetic() -> None:
    s = load_scenario(ROOT / "config" / "paper-literal.yaml")
    lam = 299_792_458.0 / 28e9
    beta0 = (lam / (4 * math.pi)) ** 2
    assert s.beta0 == pytest.approx(beta0, rel=1e-12)
    assert 10 * math.log10(s.beta0) == pytest.approx(-61.4, abs=0.05)
    assert s.rho0 == pytest.approx(0.1 * beta0 / 1e-16, rel=1e-9)
    assert s.d_th == pytest.approx(math.sqrt(1.0 * beta0 / (1e-16 * 10**1.1) - 85.0**2), rel=1e-9)
    assert s.gamma_th == pytest.approx(12.589, rel=1e-4)
    assert (s.M, s.K, s.N, s.n_a) == (3, 5, 60, 3)
    assert (s.alpha_d, s.alpha_v) == (3.6e-8, 1.4e-9)
    assert s.bs_xy.shape == (5, 2)
    assert (s.bs_xy >= 0).all() and (s.bs_xy <= 3000).all()


def test_calibrated_alphas_follow_the_crb_formula() -> None:
    s = load_scenario(ROOT / "config" / "paper.yaml")
    c, lam = 299_792_458.0, 299_792_458.0 / 28e9
    assert s.alpha_d == pytest.approx(3 * c**2 / (8 * math.pi**2 * 20e6 * 0.01), rel=1e-12)
    assert s.alpha_v == pytest.approx(3 * lam**2 / (8 * math.pi**2 * 20e6 * 0.01), rel=1e-12)


def test_bs_layout_is_fixed_by_its_seed() -> None:
    a = parse_scenario({"base_stations": {"placement_seed": 3}})
    b = parse_scenario({"base_stations": {"placement_seed": 3}})
    c = parse_scenario({"base_stations": {"placement_seed": 4}})
    assert (a.bs_xy == b.bs_xy).all()
    assert not (a.bs_xy == c.bs_xy).all()


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        ({"radio": {"bandwith_hz": 1e6}}, "radio.bandwith_hz: unknown key"),
        (
            {"radio": {"bandwidth_hz": -1}},
            "radio.bandwidth_hz: Input should be greater than 0 (got -1)",
        ),
        ({"uavs": {"max_speed_mps": 0}}, "uavs.max_speed_mps"),
        (
            {"uavs": {"start_xy_m": [[100, 100], [110, 100]]}},
            "uavs.start_xy_m[0], [1]: 10.0 m apart, closer than safe_distance_m = 30.0 m",
        ),
        ({"radio": {"control_snr_min_db": 70}}, "control link never closes"),
        (
            {"radio": {"control_snr_min_db": 40}, "uavs": {"start_xy_m": [[0, 0], [3000, 3000]]}},
            "beyond the control range",
        ),
        (
            {"base_stations": {"count": 1}, "radio": {"bs_capacity": 2}},
            "3 UAVs cannot be served by 1 BSs of capacity 2",
        ),
        ({"sensing": {"model": "literal"}}, "model literal needs both alpha_d and alpha_v"),
        ({"sensing": {"alpha_d": 1.0}}, "derived by model radar_crb"),
        ({"timing": {"duration_s": 10, "slot_s": 3}}, "whole number of slots"),
        ({"uavs": {"start_xy_m": [[-5, 0]]}}, "outside the area"),
        ({"base_stations": {"count": 2, "xy_m": [[0, 0]]}}, "has 1 positions but count is 2"),
    ],
)
def test_bad_config_names_field_value_and_reason(data: dict[str, Any], expected: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_scenario(data, "x.yaml")
    assert expected in str(err.value)
    assert str(err.value).startswith("x.yaml: ")


def test_bad_files_give_errors_not_tracebacks(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_scenario(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("radio: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_scenario(bad)
    bad.write_text(yaml.safe_dump([1, 2]))
    with pytest.raises(ConfigError, match="must hold a mapping"):
        load_scenario(bad)


def test_every_shipped_config_loads() -> None:
    for path in sorted((ROOT / "config").glob("*.yaml")):
        assert load_scenario(path).N > 0


def test_shipped_scenarios_load_by_name_as_by_path() -> None:
    names = scenario_names()
    assert {"paper", "paper-literal", "constrained"} <= set(names)
    assert names == sorted(p.stem for p in (ROOT / "config").glob("*.yaml"))
    for name in names:
        by_name, by_path = load_scenario(name), load_scenario(ROOT / "config" / f"{name}.yaml")
        assert by_name.trace_config() == by_path.trace_config()
        assert scenario_path(name).resolve() == (ROOT / "config" / f"{name}.yaml").resolve()


def test_the_repository_config_folder_is_the_package_data() -> None:
    assert (ROOT / "config").resolve() == SCENARIOS_DIR.resolve()
    assert (SCENARIOS_DIR / "grids" / "example.yaml").is_file()


def test_an_unknown_name_lists_the_shipped_scenarios(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"^nope: no such file, nor a shipped scenario") as err:
        load_scenario("nope")
    assert "paper-literal" in str(err.value)
    # A path (a folder or a .yaml suffix) is never taken for a name.
    with pytest.raises(ConfigError, match="cannot read"):
        load_scenario("paper.yaml")
    with pytest.raises(ConfigError, match="cannot read"):
        load_scenario(tmp_path / "paper")


def test_an_existing_file_wins_over_a_shipped_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "paper").write_text(yaml.safe_dump({"mission_id": "local"}))
    monkeypatch.chdir(tmp_path)
    assert load_scenario("paper").mission_id == "local"


def test_a_sweep_reads_a_shipped_scenario_by_name() -> None:
    from isac_mission.experiment.sweep.grid import load_config_mapping

    expected = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    assert load_config_mapping("paper") == expected


def test_a_key_given_twice_with_two_values_is_refused_naming_it_and_both_lines(
    tmp_path: Path,
) -> None:
    f = tmp_path / "twice.yaml"
    f.write_text("planner:\n  polish: false\n  safety_margin: none\n  safety_margin: covariance\n")
    with pytest.raises(
        ConfigError,
        match=r"found key 'safety_margin' twice with two values \('none' on line 3, 'covariance'",
    ):
        load_scenario(f)
    with pytest.raises(ConfigError, match="line 4"):
        load_scenario(f)
    f.write_text("planner:\n  polish: false\n  safety_margin: none\n  safety_margin: none\n")
    once = tmp_path / "once.yaml"
    once.write_text("planner:\n  polish: false\n  safety_margin: none\n")
    assert load_scenario(f).trace_config() == load_scenario(once).trace_config()


def test_merged_defaults_may_be_overridden_and_every_shipped_scenario_has_unique_keys(
    tmp_path: Path,
) -> None:
    f = tmp_path / "merged.yaml"
    f.write_text(
        "defaults: &d {polish: false, max_ao_iterations: 8}\nplanner:\n  <<: *d\n  polish: true\n"
    )
    assert load_yaml(f.read_text())["planner"] == {"polish": True, "max_ao_iterations": 8}
    for name in scenario_names():
        assert isinstance(load_yaml((SCENARIOS_DIR / f"{name}.yaml").read_text()), dict), name
