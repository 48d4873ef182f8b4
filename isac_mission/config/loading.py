"""Loading: a YAML file, a mapping, or a scenario shipped with the package (by name) to a
`Scenario`; a `ValidationError` becomes one line per field (`file: radio.bandwidth_hz: ...`), and
a deprecated section one DeprecationWarning (`file: target: is deprecated: use targets: ...`)."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from isac_mission.config.resolve import resolve
from isac_mission.config.scenario import Scenario, ScenarioFile
from isac_mission.config.validation import validation_lines
from isac_mission.errors import ConfigError


class _StrictLoader(yaml.SafeLoader):
    """YAML's safe loader that refuses a key given twice in one mapping with two values (PyYAML
    would keep the last silently); the same value twice is harmless and read as once."""


def _unique_mapping(loader: _StrictLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    first: dict[Any, tuple[int, Any]] = {}
    for key_node, value_node in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue  # `<<:` merges defaults that the mapping's own keys may override
        key = loader.construct_object(key_node, deep=True)
        value = loader.construct_object(value_node, deep=True)
        try:
            line, kept = first.setdefault(key, (key_node.start_mark.line, value))
        except TypeError:
            continue  # an unhashable key: the constructor below says what is wrong with it
        if kept != value:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping",
                node.start_mark,
                f"found key {key!r} twice with two values ({kept!r} on line {line + 1}, "
                f"{value!r} here)",
                key_node.start_mark,
            )
    return loader.construct_mapping(node, deep=True)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _unique_mapping)


def load_yaml(text: str) -> Any:
    """The content of a YAML document, each mapping's keys unique; yaml.YAMLError otherwise."""
    return yaml.load(text, Loader=_StrictLoader)  # a SafeLoader: constructs plain data only


def parse_scenario(data: Any, source: str = "<config>") -> Scenario:
    """Validate a mapping (as read from YAML) and resolve it. Raises ConfigError. Warns
    (DeprecationWarning, attributed to the first caller outside the package) once per deprecated
    section the mapping uses (`ScenarioFile.deprecations`)."""
    if not isinstance(data, dict):
        raise ConfigError(
            f"{source}: the file must hold a mapping of sections, got {type(data).__name__}"
        )
    try:
        spec = ScenarioFile.model_validate(data)
    except ValidationError as err:
        raise ConfigError(validation_lines(err, source)) from None
    for message in spec.deprecations():
        warnings.warn(f"{source}: {message}", DeprecationWarning, stacklevel=_outside_package())
    try:
        return resolve(spec)
    except ConfigError as err:
        raise ConfigError(
            "\n".join(f"{source}: {line}" for line in str(err).splitlines())
        ) from None


def _outside_package() -> int:
    """The stacklevel of `warnings.warn`, called from the function that calls this one, that
    names the first frame outside isac_mission (the user's script or the test that loaded the
    scenario: Python shows a DeprecationWarning by default only there)."""
    level, frame = 2, sys._getframe(2)
    while frame.f_back is not None and frame.f_globals.get("__name__", "").startswith(
        "isac_mission."
    ):
        frame, level = frame.f_back, level + 1
    return level


SCENARIOS_DIR = Path(__file__).resolve().parents[1] / "scenarios"
"""The scenarios shipped with the package (`isac_mission/scenarios/*.yaml`; `config/` in a
checkout points at it)."""


def scenario_names() -> list[str]:
    """Names of the shipped scenarios (`paper`, `paper-literal`, `constrained`, ...), sorted."""
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.yaml"))


def scenario_path(path_or_name: str | Path) -> Path:
    """The file of a scenario given by path, or by the name of a shipped scenario.

    An existing file wins; otherwise a bare name (no folder, no `.yaml`/`.yml` suffix) is looked
    up among `scenario_names()`. Raises ConfigError for an unknown name; a path that does not
    exist is returned as is (reading it then fails with "cannot read").
    """
    p = Path(path_or_name)
    if p.is_file() or len(p.parts) != 1 or p.suffix in {".yaml", ".yml"}:
        return p
    shipped = SCENARIOS_DIR / f"{p.name}.yaml"
    if shipped.is_file():
        return shipped
    raise ConfigError(
        f"{p}: no such file, nor a shipped scenario (choose from {', '.join(scenario_names())})"
    )


def read_scenario_data(path_or_name: str | Path) -> tuple[Any, str]:
    """The YAML content of a scenario file or shipped scenario, and its name for messages.

    Raises ConfigError (cannot read, not valid YAML, unknown name), never a traceback.
    """
    p = scenario_path(path_or_name)
    try:
        text = p.read_text()
    except OSError as err:
        raise ConfigError(f"{p}: cannot read: {err.strerror}") from None
    try:
        return load_yaml(text), str(p)
    except yaml.YAMLError as err:
        raise ConfigError(f"{p}: not valid YAML: {err}") from None


def load_scenario(path_or_name: str | Path) -> Scenario:
    """Read, validate and resolve a YAML scenario file, or a shipped scenario by name
    (`load_scenario("paper")`). Raises ConfigError, never a traceback."""
    data, source = read_scenario_data(path_or_name)
    return parse_scenario(data, source)
