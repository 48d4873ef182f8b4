"""One scenario schema (docs/decisions/0001-one-scenario-schema.md): the targets under `targets:`,
their motion under `target_motion:`, one `tracker:` section with `kind` and `multi:`. The old
sections (`target:`, `multi_target:`) still load, each with a DeprecationWarning, to the very
Scenario the new form gives; no shipped config warns; bad input is one line naming the field."""

from __future__ import annotations

import copy
import dataclasses
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

import isac_mission
from isac_mission.cli import app
from isac_mission.config import (
    SCHEMA_REMOVAL_VERSION,
    Scenario,
    ScenarioFile,
    TargetConfig,
    load_scenario,
    multi_target_reasons,
    parse_scenario,
    single_target_problem,
)
from isac_mission.errors import ConfigError
from isac_mission.experiment.sweep.grid import expand_grid, load_grid, parse_grid

ROOT = Path(__file__).resolve().parents[2]
OLD = Path(__file__).resolve().parent / "data" / "scenarios-0.1"
OLD_FILES = sorted(OLD.glob("*.yaml"))
SHIPPED = sorted((ROOT / "config").glob("*.yaml"))
SINCE_THE_NEW_FORM = {"manoeuvring.yaml", "city-48.yaml", "city-96.yaml"}
"""Scenarios first shipped after the old form was deprecated, with what it never had (a target's
legs, the tracker's IMM, explicit BS positions): they have no old form."""
FILTER = re.compile(r".* is deprecated. use ")
"""pyproject.toml's filterwarnings pattern: a warning it matches is an error outside
pytest.warns, so a test or shipped config that used an old section unnoticed fails."""


def _read(path: Path) -> dict[str, Any]:
    data = yaml.safe_load(path.read_text())
    assert isinstance(data, dict)
    return data


def _same(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))
    return a == b


def assert_same_scenario(old: Scenario, new: Scenario) -> None:
    """Every dataclass field, the trace config and the path taken are equal."""
    differ = [
        f.name
        for f in dataclasses.fields(Scenario)
        if not _same(getattr(old, f.name), getattr(new, f.name))
    ]
    assert differ == []
    assert old.trace_config() == new.trace_config()
    assert old.multi_target == new.multi_target
    assert old.motion == new.motion


def load_quietly(path: Path | str) -> Scenario:
    """Load with every warning an error: the new form must not warn."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return load_scenario(path)


def test_every_shipped_scenario_has_its_old_form_here() -> None:
    older = [p.name for p in SHIPPED if p.name not in SINCE_THE_NEW_FORM]
    assert [p.name for p in OLD_FILES] == older


@pytest.mark.parametrize("old", OLD_FILES, ids=[p.stem for p in OLD_FILES])
def test_the_old_form_and_the_new_resolve_to_the_same_scenario(old: Path) -> None:
    sections = [k for k in ("target", "multi_target") if k in _read(old)]
    assert sections  # the fixture is the old form
    with pytest.warns(DeprecationWarning, match=FILTER) as caught:
        before = load_scenario(old)
    said = [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)]
    assert [m.split(": ")[1] for m in said] == sections  # one warning per old section
    for message in said:
        assert message.startswith(f"{old}: ")
        assert FILTER.match(message)
        assert f"removed in {SCHEMA_REMOVAL_VERSION}" in message
    after = load_quietly(ROOT / "config" / old.name)
    assert_same_scenario(before, after)


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_no_shipped_config_uses_an_old_section(path: Path) -> None:
    data = _read(path)
    assert "target" not in data and "multi_target" not in data
    assert "targets" in data and "target_motion" in data and "kind" in data["tracker"]
    assert ScenarioFile.model_validate(data).deprecations() == []
    load_quietly(path)
    load_quietly(path.stem)


def test_a_grid_over_the_old_form_gives_the_new_forms_points() -> None:
    grid = load_grid(ROOT / "config" / "grids" / "example.yaml")
    with pytest.warns(DeprecationWarning, match="target: is deprecated"):
        before = expand_grid(_read(OLD / "paper.yaml"), grid)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        after = expand_grid(_read(ROOT / "config" / "paper.yaml"), grid)
    assert [p.values for p in before] == [p.values for p in after]
    for b, a in zip(before, after, strict=True):
        assert_same_scenario(b.scenario, a.scenario)


def test_a_grid_sweeps_the_new_keys_and_still_the_old_ones_on_an_old_file() -> None:
    grid = parse_grid(
        {
            "target_motion.process_noise_intensity": [0.5, 1.0],
            "tracker.multi.gate_prob": [0.9],
            "slots": 4,
        }
    )
    points = expand_grid(_read(ROOT / "config" / "paper.yaml"), grid)
    assert [p.scenario.kappa for p in points] == [0.5, 1.0]
    assert points[0].scenario.multi_tracker.gate_prob == 0.9
    old = parse_grid({"target.process_noise_intensity": [1.0], "multi_target.gate_prob": [0.9]})
    with pytest.warns(DeprecationWarning, match=FILTER):
        (point,) = expand_grid(_read(OLD / "paper.yaml"), old)
    assert (point.scenario.kappa, point.scenario.multi_tracker.gate_prob) == (1.0, 0.9)
    # On a new-form file the old key is a setting given twice, refused by name.
    with pytest.raises(ConfigError, match=r"target\.process_noise_intensity: give it under"):
        expand_grid(_read(ROOT / "config" / "paper.yaml"), old)


def test_the_defaults_are_the_old_target_sections() -> None:
    # A mapping without targets (most tests' configs) means what it meant with target:'s defaults.
    with pytest.warns(DeprecationWarning, match="target: is deprecated: use targets: "):
        old = parse_scenario({"target": TargetConfig().model_dump()}, "old")
    with pytest.warns(DeprecationWarning, match="target: is deprecated: use targets: "):
        empty = parse_scenario({"target": {}}, "empty")
    new = parse_scenario({}, "new")
    assert_same_scenario(old, new)
    assert_same_scenario(empty, new)
    assert (new.kappa, new.a_target, new.tracker_kind) == (0.5, 2.0, "auto")


def test_the_deprecation_names_only_the_replacement_of_what_is_given() -> None:
    with pytest.warns(DeprecationWarning, match="target: is deprecated") as caught:
        parse_scenario({"target": {"max_accel_mps2": 3}}, "x.yaml")
    (message,) = [str(w.message) for w in caught]
    assert message.startswith("x.yaml: target: is deprecated: use target_motion: ")
    assert "targets:" not in message
    with pytest.warns(DeprecationWarning, match="multi_target: is deprecated") as caught:
        parse_scenario({"multi_target": {"association": "gnn"}}, "x.yaml")
    (message,) = [str(w.message) for w in caught]
    assert message.startswith("x.yaml: multi_target: is deprecated: use tracker.multi: ")


def test_the_removal_version_is_the_next_minor() -> None:
    major, minor, _ = (int(p) for p in isac_mission.__version__.split("."))
    assert SCHEMA_REMOVAL_VERSION == f"{major}.{minor + 1}.0"


def _multi() -> dict[str, Any]:
    return _read(ROOT / "config" / "multi-target.yaml")


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (
            lambda d: d.update(target={"rcs_dbsm": -5}),
            "x.yaml: target.rcs_dbsm: give the targets under targets: only",
        ),
        (
            lambda d: d.update(target={"process_noise_intensity": 1}),
            "x.yaml: target.process_noise_intensity: give it under target_motion: only",
        ),
        (
            lambda d: d.update(multi_target={"gate_prob": 0.9}),
            "x.yaml: multi_target: give the multi-target tracker under tracker.multi: only",
        ),
        (
            lambda d: d["target_motion"].update(process_noise_intensity=-1),
            "x.yaml: target_motion.process_noise_intensity: Input should be greater than or "
            "equal to 0 (got -1)",
        ),
        (
            lambda d: d["target_motion"].update(max_accel=2),
            "x.yaml: target_motion.max_accel: unknown key",
        ),
        (
            lambda d: d["tracker"].update(kind="jpda"),
            "x.yaml: tracker.kind: Input should be 'auto', 'labelled' or 'multi' (got 'jpda')",
        ),
        (
            lambda d: d["tracker"]["multi"].update(gate_prob=2),
            "x.yaml: tracker.multi.gate_prob: Input should be less than 1 (got 2)",
        ),
        (
            lambda d: d["tracker"]["multi"].update(confirm_hits=9),
            "x.yaml: tracker.multi: confirm_hits 9 cannot happen within confirm_window 4 slots",
        ),
        (
            # the old sections are still checked under their own names
            lambda d: d.update(multi_target={"gate_prob": 2}) or d["tracker"].pop("multi"),
            "x.yaml: multi_target.gate_prob: Input should be less than 1 (got 2)",
        ),
        (lambda d: d.update(targets=None), "x.yaml: targets: Input should be a valid list"),
        (
            lambda d: d["tracker"].update(kind="labelled"),
            "x.yaml: tracker.kind: labelled tracks one known constant-velocity target in the "
            "scene throughout, with the fixed detection model and no false alarms; this "
            "scenario has 3 targets, false alarms: use kind auto or multi",
        ),
    ],
)
def test_bad_input_is_one_line_naming_the_field(change: Any, expected: str) -> None:
    data = _multi()
    change(data)
    with pytest.raises(ConfigError) as err:
        parse_scenario(data, "x.yaml")
    assert str(err.value).startswith(expected) and "\n" not in str(err.value)


def test_an_old_target_outside_the_area_is_named_as_written() -> None:
    with pytest.warns(DeprecationWarning, match="target: is"), pytest.raises(ConfigError) as err:
        parse_scenario({"target": {"initial_state": [-5, 0, 1, 1]}}, "x.yaml")
    assert (
        str(err.value) == "x.yaml: target.initial_state: position [-5.0, 0.0] is outside the area"
    )
    with pytest.raises(ConfigError) as err:
        parse_scenario({"targets": [{"initial_state": [-5, 0, 1, 1]}]}, "x.yaml")
    assert str(err.value).startswith("x.yaml: targets[0].initial_state: position [-5.0, 0.0] ")


def test_tracker_kind_auto_keeps_the_rule_labelled_checks_it_multi_forces_it() -> None:
    paper = _read(ROOT / "config" / "paper.yaml")
    auto = parse_scenario(paper)
    assert not auto.multi_target and multi_target_reasons(auto) == []
    labelled = copy.deepcopy(paper)
    labelled["tracker"]["kind"] = "labelled"
    assert_same_scenario(auto, parse_scenario(labelled).with_changes(tracker_kind="auto"))
    multi = copy.deepcopy(paper)
    multi["tracker"]["kind"] = "multi"
    forced = parse_scenario(multi)
    assert forced.multi_target and multi_target_reasons(forced) == []
    problem = single_target_problem(forced)
    assert problem is not None and problem.startswith("tracker.kind multi: ")
    assert "multi_target" in forced.trace_config()  # traced as any multi-target scenario
    many = parse_scenario(_multi())
    assert many.multi_target and multi_target_reasons(many) == ["3 targets", "false alarms"]


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"appears_s": 5}, "target target-0 appears at slot 5"),
        ({"leaves_s": 30}, "target target-0 leaves at slot 30"),
        ({"prior": "unknown"}, "target target-0 must be found (prior unknown)"),
        ({"motion": "coordinated_turn", "turn_rate_radps": 0.01}, "moves by coordinated_turn"),
    ],
)
def test_the_reasons_for_the_multi_target_path_are_the_auto_rule(
    change: dict[str, Any], reason: str
) -> None:
    data = _read(ROOT / "config" / "paper.yaml")
    data["targets"][0].update(change)
    s = parse_scenario(data)
    assert s.multi_target and any(reason in r for r in multi_target_reasons(s))
    data["tracker"]["kind"] = "labelled"
    with pytest.raises(ConfigError, match=r"tracker\.kind: labelled tracks one"):
        parse_scenario(data)


def test_the_scenario_json_schema_is_the_one_schema() -> None:
    schema = ScenarioFile.model_json_schema()
    props = schema["properties"]
    assert props["targets"]["type"] == "array" and props["targets"]["minItems"] == 1
    assert {"target_motion", "tracker"} <= set(props)
    tracker = schema["$defs"]["TrackerConfig"]["properties"]
    assert tracker["kind"]["enum"] == ["auto", "labelled", "multi"]
    assert "multi" in tracker
    for old in ("target", "multi_target"):
        assert props[old]["deprecated"] is True
        assert SCHEMA_REMOVAL_VERSION in props[old]["description"]


def _words(output: str) -> str:
    """The output's words, the table's borders and rich's wrapping gone."""
    return " ".join(re.sub(r"[│┃]", " ", output).split())


def test_check_config_says_which_tracker_and_flags_old_sections() -> None:
    runner = CliRunner()
    new = runner.invoke(app, ["check-config", str(ROOT / "config" / "multi-target.yaml")])
    assert new.exit_code == 0, new.output
    said = _words(new.output)
    assert "deprecated" not in said
    assert "multi-target JPDA (kind auto: 3 targets, false alarms)" in said
    paper = runner.invoke(app, ["check-config", str(ROOT / "config" / "paper.yaml")])
    assert "labelled EKF (kind auto)" in _words(paper.output)
    old = runner.invoke(app, ["check-config", str(OLD / "multi-target.yaml")])
    assert old.exit_code == 0, old.output
    said = _words(old.output)
    assert "deprecated: " in said and "multi_target: is deprecated: use tracker.multi:" in said
