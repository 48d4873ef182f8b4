"""The settings base: pydantic's errors become one ConfigError, a line per field, named."""

from __future__ import annotations

from typing import ClassVar

import pytest
from pydantic import Field

from isac_mission.config.validation import Settings
from isac_mission.errors import ConfigError
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.ground.settings import GroundSettings
from sim.autopilot.settings import AutopilotSettings


class _Demo(Settings):
    settings_name: ClassVar[str] = "DemoSettings"
    rate_hz: float = Field(1.0, gt=0.0)
    count: int = 1


def test_every_bad_field_is_one_named_line_of_one_config_error() -> None:
    with pytest.raises(ConfigError) as err:
        _Demo.model_validate({"rate_hz": -1.0, "count": "many", "colour": "red"})
    lines = str(err.value).splitlines()
    assert len(lines) == 3
    assert lines[0] == "DemoSettings: rate_hz: Input should be greater than 0 (got -1.0)"
    assert lines[1].startswith("DemoSettings: count: ") and "(got 'many')" in lines[1]
    assert lines[2] == "DemoSettings: colour: unknown key (got 'red')"


def test_settings_are_frozen() -> None:
    demo = _Demo()
    with pytest.raises(Exception, match="frozen"):
        setattr(demo, "rate_hz", 2.0)  # noqa: B010 (a frozen model refuses assignment)


@pytest.mark.parametrize(
    ("cls", "prefix"),
    [
        (BridgeSettings, "BridgeSettings: "),
        (GroundSettings, "ground settings: "),
        (AutopilotSettings, "AutopilotSettings: "),
    ],
)
def test_the_runtime_settings_share_the_base(cls: type[Settings], prefix: str) -> None:
    assert issubclass(cls, Settings)
    with pytest.raises(ConfigError, match=f"^{prefix}no_such_setting: unknown key"):
        cls.model_validate({"no_such_setting": 1})
