"""Pydantic's validation errors in the project's words, and the base of the runtime settings.

`validation_lines` turns a `ValidationError` into one `source: field.path: reason (got value)`
line per problem (`source: reason` for a model's own check, whose reason names its fields;
security values and whole sections never echoed). `Settings` is the base of the settings
classes the bridge, the ground loop and the simulated autopilot take: frozen, no unknown keys,
and every problem raised as one `ConfigError` (never pydantic's own error).
"""

from __future__ import annotations

from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, ValidationError, model_validator

from isac_mission.errors import ConfigError


def validation_lines(err: ValidationError, source: str) -> str:
    """One `source: field.path: reason (got value)` line per error in `err`."""
    lines = []
    for e in err.errors():
        where = ".".join(str(p) for p in e["loc"])
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
        elif msg.startswith("Value error, "):
            msg = msg[len("Value error, ") :]
        got = e.get("input")
        secret = e["loc"][:1] == ("security",)  # never echo what might be a key or password
        got_txt = "" if isinstance(got, dict) or secret else f" (got {got!r})"
        # A model's own check (no location) names its fields in its message.
        lines.append(f"{source}: {where}: {msg}{got_txt}" if where else f"{source}: {msg}{got_txt}")
    return "\n".join(lines)


class Settings(BaseModel):
    """Frozen settings with no unknown keys; a bad field raises `ConfigError` whose lines start
    with `settings_name` (subclasses set it, e.g. "BridgeSettings")."""

    model_config = ConfigDict(frozen=True, extra="forbid")
    settings_name: ClassVar[str] = "settings"

    @model_validator(mode="wrap")
    @classmethod
    def _raise_config_error(cls, data: Any, handler: Any) -> Any:
        """A type error (pydantic's) becomes a ConfigError naming the field."""
        try:
            return handler(data)
        except ValidationError as err:
            raise ConfigError(validation_lines(err, cls.settings_name)) from None
