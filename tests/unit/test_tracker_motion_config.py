"""The tracker's motion model in the scenario (`tracker.motion`, `tracker.imm:`;
config/sections.py, config/resolve.py): an IMM section resolves to `ImmSpec`, each refusal names
its field, and every scenario without the keys is what it was (cv, no IMM, the same trace
config)."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml

from isac_mission.config import ScenarioFile, load_scenario, parse_scenario
from isac_mission.config.sections import ImmModeSpec, ImmSpec, TrackerConfig
from isac_mission.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted((ROOT / "config").glob("*.yaml"))

IMM: dict[str, Any] = {
    "modes": [
        {"model": "cv", "process_noise_intensity": 0.05},
        {"model": "ct", "process_noise_intensity": 0.5, "turn_rate_noise": 0.001},
    ],
    "switching": [[0.95, 0.05], [0.10, 0.90]],
    "initial_probabilities": [0.9, 0.1],
    "initial_turn_rate_std_radps": 0.2,
}


def _with_tracker(**tracker: Any) -> dict[str, Any]:
    return {"tracker": {"kind": "auto", **tracker}}


def _refusal(data: dict[str, Any]) -> str:
    with pytest.raises(ConfigError) as err:
        parse_scenario(data, "x.yaml")
    return str(err.value)


def _imm(**changes: Any) -> dict[str, Any]:
    imm = copy.deepcopy(IMM)
    imm.update(changes)
    return imm


def test_an_imm_section_resolves_to_its_spec() -> None:
    s = parse_scenario(_with_tracker(motion="imm", imm=IMM), "x.yaml")
    assert s.tracker_motion == "imm"
    assert s.imm == ImmSpec(
        modes=(ImmModeSpec("cv", 0.05, 0.0), ImmModeSpec("ct", 0.5, 0.001)),
        switching=((0.95, 0.05), (0.10, 0.90)),
        initial_probabilities=(0.9, 0.1),
        initial_turn_rate_std_radps=0.2,
    )
    config = s.trace_config()
    assert config["tracker_motion"] == "imm"
    assert config["imm"]["modes"][1] == {
        "model": "ct",
        "kappa_m2ps3": 0.5,
        "turn_noise_rad2ps3": 0.001,
    }
    default_std = _imm()
    del default_std["initial_turn_rate_std_radps"]
    imm = parse_scenario(_with_tracker(motion="imm", imm=default_std), "x.yaml").imm
    assert imm is not None and imm.initial_turn_rate_std_radps == 0.1


def test_four_modes_resolve_in_order() -> None:
    modes = [
        {"model": "cv", "process_noise_intensity": 0.01},
        {"model": "cv", "process_noise_intensity": 1.0},
        {"model": "ct", "process_noise_intensity": 0.5, "turn_rate_noise": 1e-4},
        {"model": "ct", "process_noise_intensity": 0.5, "turn_rate_noise": 1e-2},
    ]
    switching = [[0.7, 0.1, 0.1, 0.1]] * 4
    imm = _imm(modes=modes, switching=switching, initial_probabilities=[0.25] * 4)
    spec = parse_scenario(_with_tracker(motion="imm", imm=imm), "x.yaml").imm
    assert spec is not None
    assert [m.turn_noise_rad2ps3 for m in spec.modes] == [0.0, 0.0, 1e-4, 1e-2]
    assert spec.switching == ((0.7, 0.1, 0.1, 0.1),) * 4


@pytest.mark.parametrize(
    ("tracker", "line"),
    [
        (
            {"motion": "imm", "imm": _imm(switching=[[0.95, 0.05], [0.1, 0.8]])},
            "x.yaml: tracker.imm.switching: row 1 sums to 0.9, not 1",
        ),
        (
            {"motion": "imm", "imm": _imm(switching=[[0.5, 0.5], [0.5, 0.5], [0.5, 0.5]])},
            "x.yaml: tracker.imm.switching: 3 rows for 2 modes: it must be 2 x 2",
        ),
        (
            {"motion": "imm", "imm": _imm(switching=[[0.5, 0.5, 0.0], [0.5, 0.5, 0.0]])},
            "x.yaml: tracker.imm.switching: row 0 has 3 entries, not 2: it must be square",
        ),
        (
            {"motion": "imm", "imm": _imm(switching=[[1.5, -0.5], [0.1, 0.9]])},
            "x.yaml: tracker.imm.switching: row 0: 1.5 is not a probability in [0, 1]",
        ),
        (
            {"motion": "imm", "imm": _imm(initial_probabilities=[0.9, 0.2])},
            "x.yaml: tracker.imm.initial_probabilities: they sum to 1.1, not 1",
        ),
        (
            {"motion": "imm", "imm": _imm(initial_probabilities=[1.0])},
            "x.yaml: tracker.imm.initial_probabilities: 1 probabilities for 2 modes",
        ),
        (
            {"imm": IMM},
            "x.yaml: tracker: imm is for motion imm, not cv",
        ),
        (
            {"motion": "cv", "imm": IMM},
            "x.yaml: tracker: imm is for motion imm, not cv",
        ),
        (
            {"motion": "imm"},
            "x.yaml: tracker: motion imm needs imm (its modes, switching and "
            "initial_probabilities)",
        ),
        (
            {
                "motion": "imm",
                "imm": _imm(
                    modes=[
                        {"model": "cv", "process_noise_intensity": 0.05, "turn_rate_noise": 0.01},
                        {"model": "ct", "process_noise_intensity": 0.5},
                    ]
                ),
            },
            "x.yaml: tracker.imm.modes.0: turn_rate_noise is for model ct: a cv mode has no "
            "turn rate (got 0.01)",
        ),
        (
            {
                "motion": "imm",
                "imm": _imm(
                    modes=[{"model": "cv", "process_noise_intensity": 0.05}],
                    switching=[[1.0]],
                    initial_probabilities=[1.0],
                ),
            },
            "x.yaml: tracker.imm.modes: List should have at least 2 items",
        ),
        (
            {"motion": "imm", "imm": _imm(initial_turn_rate_std_radps=0)},
            "x.yaml: tracker.imm.initial_turn_rate_std_radps: Input should be greater than 0",
        ),
        (
            {"motion": "kalman"},
            "x.yaml: tracker.motion: Input should be 'cv' or 'imm'",
        ),
    ],
)
def test_each_refusal_names_its_field(tracker: dict[str, Any], line: str) -> None:
    assert _refusal(_with_tracker(**tracker)).startswith(line)


def test_a_switching_row_within_1e_9_of_one_is_accepted() -> None:
    near = _imm(switching=[[0.95, 0.05 + 5e-10], [0.1, 0.9]])
    assert parse_scenario(_with_tracker(motion="imm", imm=near), "x.yaml").imm is not None
    far = _imm(switching=[[0.95, 0.05 + 5e-9], [0.1, 0.9]])
    assert "row 0 sums to" in _refusal(_with_tracker(motion="imm", imm=far))


def test_the_default_scenario_tracks_with_constant_velocity() -> None:
    s = parse_scenario({}, "x.yaml")
    assert s.tracker_motion == "cv" and s.imm is None
    assert ScenarioFile().tracker.motion == "cv" and ScenarioFile().tracker.imm is None


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_a_scenario_without_the_keys_dumps_and_traces_as_before(path: Path) -> None:
    data = yaml.safe_load(path.read_text())
    tracker = data.get("tracker", {})
    if "motion" in tracker or "imm" in tracker:
        pytest.skip(f"{path.stem} sets the tracker's motion model")
    s = load_scenario(path)
    assert s.tracker_motion == "cv" and s.imm is None
    config = s.trace_config()
    assert "tracker_motion" not in config and "imm" not in config
    for target in config.get("targets", []):
        assert "legs" not in target
    dumped = ScenarioFile.model_validate(data).model_dump()
    assert "motion" not in dumped["tracker"] and "imm" not in dumped["tracker"]
    assert set(TrackerConfig(**tracker).model_dump()) == set(TrackerConfig.model_fields) - {
        "motion",
        "imm",
    }


def test_an_imm_tracker_section_dumps_its_keys_and_reloads_the_same() -> None:
    cfg = TrackerConfig(motion="imm", imm=IMM)
    dumped = cfg.model_dump()
    assert dumped["motion"] == "imm" and dumped["imm"]["switching"] == IMM["switching"]
    assert TrackerConfig.model_validate(dumped) == cfg
    assert TrackerConfig.model_validate(TrackerConfig().model_dump()) == TrackerConfig()


def test_the_manoeuvring_scenario_tracks_with_the_imm() -> None:
    s = load_scenario("manoeuvring")
    assert s.tracker_motion == "imm" and s.imm is not None
    assert [m.model for m in s.imm.modes] == ["cv", "ct", "cv"]
    # The manoeuvre mode's kappa is a_T^2 / 2 (docs/model.md, "The interacting multiple model").
    assert s.imm.modes[2].kappa_m2ps3 == s.a_target**2 / 2
    assert s.multi_target and s.trace_config()["tracker_motion"] == "imm"


def test_the_imm_takes_the_multi_target_tracker_for_one_plain_target() -> None:
    # One known constant-velocity target with the paper's detections: the labelled EKF's
    # scenario, but the IMM runs on the multi-target tracker's tracks (n = 1).
    plain = parse_scenario(_with_tracker(), "x.yaml")
    assert not plain.multi_target
    s = parse_scenario(_with_tracker(motion="imm", imm=IMM), "x.yaml")
    assert s.multi_target
    assert _refusal(_with_tracker(kind="labelled", motion="imm", imm=IMM)).endswith(
        "tracker.motion imm (the IMM runs on the multi-target tracker's tracks): use kind auto "
        "or multi"
    )


def test_the_planners_motion_mixes_the_modes_by_their_long_run_shares() -> None:
    s = parse_scenario(_with_tracker(motion="imm", imm=IMM), "x.yaml")
    # pi = (2/3, 1/3) for ((0.95, 0.05), (0.10, 0.90)): kappa = 2/3 0.05 + 1/3 0.5 = 0.2.
    assert s.motion.process_noise(1.0)[2, 2] == pytest.approx(0.2, rel=1e-9)
    assert s.truth_motion.process_noise(1.0)[2, 2] == pytest.approx(s.kappa, rel=1e-12)
    cv = parse_scenario(_with_tracker(), "x.yaml")
    assert cv.motion == cv.truth_motion
