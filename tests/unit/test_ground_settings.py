"""service/ground/settings.py: GroundSettings validates with pydantic and raises ConfigError."""

from __future__ import annotations

from pathlib import Path

import pydantic
import pytest

from isac_mission.errors import ConfigError
from isac_mission.planning.slot import plan_slot
from isac_mission.service.ground.settings import GroundSettings


def test_defaults_are_the_documented_ones() -> None:
    g = GroundSettings()
    assert (g.method, g.trace_path, g.resume) == ("proposed", None, False)
    assert (g.detection_wait_s, g.detection_wall_wait_s, g.telemetry_max_age_s) == (0.5, 2.0, 1.0)
    assert (g.plan_budget_s, g.vehicle_lost_after_s, g.vehicle_lost_wall_s) == (1.0, 1.5, 1.0)
    assert g.plan_rate_factor == 1.0 and g.planner is plan_slot and g.trace_config == {}


def test_values_pass_through() -> None:
    g = GroundSettings(trace_path=Path("t.jsonl"), plan_budget_s=None, method="sd")
    assert g.trace_path == Path("t.jsonl") and g.plan_budget_s is None and g.method == "sd"


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("plan_budget_s", -1.0),
        ("detection_wall_wait_s", 0.0),
        ("detection_wait_s", -0.5),
        ("vehicle_lost_after_s", float("nan")),
        ("plan_rate_factor", 0.0),
        ("method", "fastest"),
    ],
)
def test_an_invalid_value_raises_config_error_naming_the_field(field: str, value: object) -> None:
    with pytest.raises(ConfigError, match=f"^ground settings: {field}"):
        GroundSettings(**{field: value})  # type: ignore[arg-type]


def test_an_unknown_key_is_refused_and_settings_are_frozen() -> None:
    with pytest.raises(ConfigError, match="plan_budget: unknown key"):
        GroundSettings(plan_budget=1.0)  # type: ignore[call-arg]
    g = GroundSettings()
    with pytest.raises(pydantic.ValidationError):
        g.resume = True  # type: ignore[misc]
