"""Grid files of `isac-mission sweep`: parsing, validation, overrides and the grid points.

Grid file (YAML mapping):

* ``<dotted.path>: [v1, v2, ...]`` -- a scenario key (as in config/paper.yaml) and its values,
  e.g. ``uavs.max_speed_mps: [15, 25]``. The study is the cartesian product of all such lists.
  A non-negative integer in a path indexes a list, 0 the first entry: ``targets.0.rcs_dbsm``
  (the first target's RCS), ``targets.1.initial_state``, ``uavs.start_xy_m.2``,
  ``targets.0.initial_state.2`` (its vx). The entry must be in the config (a grid changes
  entries, it never adds one); two paths one inside the other cannot both be swept.
* ``uavs.count: [3, 6]`` (special) -- the number of UAVs M. M UAVs are placed evenly on a ring:
  centre = centroid of the config's ``uavs.start_xy_m``, radius = their mean distance to it
  (a quarter of the smaller area side if the config has a single UAV), the first UAV at the config's
  first start point's bearing. Cannot be combined with a ``uavs.start_xy_m`` axis.
* optional ``methods: [proposed, sd]`` (default: proposed), ``runs: 4`` (default 4),
  ``seed: 1`` (default: the config's seed), ``slots: 20`` (sets ``timing.duration_s`` to
  slots * slot_s for quick studies; default: the config's duration).

Every grid point is validated with `parse_scenario` before any work starts; an invalid point
raises ConfigError naming the grid path(s) and value(s). A path the config cannot take (an index
past the end of its list, a list or mapping expected where the config has another value) raises
one ConfigError line per path, naming it.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast, get_args, get_origin

import numpy as np
import yaml
from pydantic import BaseModel

from isac_mission.config import Scenario, ScenarioFile, parse_scenario, read_scenario_data
from isac_mission.config.loading import load_yaml
from isac_mission.errors import ConfigError
from isac_mission.planning.registry import METHODS
from isac_mission.planning.slot import Method

RESERVED_KEYS = ("methods", "runs", "seed", "slots")
UAV_COUNT_PATH = "uavs.count"
DEFAULT_RUNS = 4

Value = bool | int | float | str | list[Any] | None


@dataclass(frozen=True)
class GridSpec:
    """A parsed grid file.

    axes: (dotted path, values) in file order; methods; runs >= 1; seed (None = the config's);
    slots (None = the config's duration).
    """

    axes: tuple[tuple[str, tuple[Value, ...]], ...]
    methods: tuple[Method, ...] = ("proposed",)
    runs: int = DEFAULT_RUNS
    seed: int | None = None
    slots: int | None = None

    @property
    def paths(self) -> tuple[str, ...]:
        """The swept dotted paths, in file order."""
        return tuple(p for p, _ in self.axes)

    def combinations(self) -> list[tuple[Value, ...]]:
        """The cartesian product of the axes' values (last axis varies fastest)."""
        return list(itertools.product(*(values for _, values in self.axes)))


@dataclass(frozen=True)
class GridPoint:
    """One validated grid point: its index, its swept values, its scenario and a cache key."""

    index: int
    values: tuple[tuple[str, Value], ...]
    scenario: Scenario
    key: str

    def label(self) -> str:
        """`path=value, ...` for tables and errors."""
        return ", ".join(f"{p}={fmt_value(v)}" for p, v in self.values) or "(base)"


def fmt_value(v: Value) -> str:
    """A swept value as text: JSON for lists and strings, else `str` (15, 2.5, True, None)."""
    return json.dumps(v) if isinstance(v, list | str) else f"{v}"


_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def _coerce(v: Value) -> Value:
    """Numbers that YAML 1.1 reads as strings (`1.0e7` has no exponent sign) become numbers."""
    if isinstance(v, str) and _NUMBER.match(v.strip()):
        text = v.strip()
        return int(text) if re.fullmatch(r"[+-]?\d+", text) else float(text)
    return v


_INDEX = re.compile(r"0|[1-9][0-9]*")


def _index(part: str) -> int | None:
    """The list index a path part names (a non-negative integer, no sign or leading zero)."""
    return int(part) if _INDEX.fullmatch(part) else None


def _non_optional(ann: Any) -> Any:
    """`X` of an optional `X | None` annotation (the deprecated `target:`, `multi_target:`)."""
    args = get_args(ann)
    if type(None) in args:
        rest = [a for a in args if a is not type(None)]
        return rest[0] if len(rest) == 1 else ann
    return ann


def _is_section(ann: Any) -> bool:
    return isinstance(ann, type) and issubclass(ann, BaseModel)


def _check_path(path: str, source: str) -> None:
    """Raise ConfigError unless `path` names a value of ScenarioFile (or is uavs.count): keys of
    sections, non-negative integer indexes of lists (and of fixed-length tuples, within them)."""
    if path == UAV_COUNT_PATH:
        return
    ann: Any = ScenarioFile
    parts = path.split(".")
    for i, part in enumerate(parts):
        where = ".".join(parts[:i])
        if _is_section(ann):
            model = cast(type[BaseModel], ann)
            field = model.model_fields.get(part)
            if field is None:
                known = ", ".join(sorted(model.model_fields))
                raise ConfigError(
                    f"{source}: {path}: unknown key {part!r} under {where or 'the top level'} "
                    f"(known: {known})"
                )
            ann = _non_optional(field.annotation)
        elif get_origin(ann) in (list, tuple):
            index = _index(part)
            if index is None:
                raise ConfigError(
                    f"{source}: {path}: {where} is a list: index it by a non-negative integer "
                    f"(got {part!r})"
                )
            args = get_args(ann)
            if get_origin(ann) is tuple and Ellipsis not in args:
                if index >= len(args):
                    raise ConfigError(
                        f"{source}: {path}: index {index} is out of range: {where} has "
                        f"{len(args)} entries"
                    )
                ann = _non_optional(args[index])
            else:
                ann = _non_optional(args[0]) if args else Any
        else:
            raise ConfigError(f"{source}: {path}: {where} is not a section or a list")
    if _is_section(ann):
        raise ConfigError(f"{source}: {path}: is a section, not a value; name one of its keys")


def _overlapping(paths: Sequence[str]) -> tuple[str, str] | None:
    """Two swept paths one inside the other (`uavs.start_xy_m`, `uavs.start_xy_m.0`), if any."""
    for a, b in itertools.permutations(paths, 2):
        if b.startswith(a + "."):
            return a, b
    return None


def parse_grid(data: Any, source: str = "<grid>") -> GridSpec:
    """Validate a grid mapping (as read from YAML). Raises ConfigError with the offending key."""
    if not isinstance(data, dict) or not data:
        raise ConfigError(
            f"{source}: the grid must be a non-empty mapping of dotted paths to lists"
        )
    methods: tuple[Method, ...] = ("proposed",)
    if "methods" in data:
        raw = data["methods"]
        if isinstance(raw, str):
            raw = [m.strip() for m in raw.split(",") if m.strip()]
        if not isinstance(raw, list) or not raw or any(m not in METHODS for m in raw):
            raise ConfigError(
                f"{source}: methods: must be a non-empty list of {', '.join(METHODS)} (got {raw!r})"
            )
        methods = tuple(dict.fromkeys(cast(list[Method], raw)))
    ints: dict[str, int | None] = {}
    for key, minimum in (("runs", 1), ("seed", 0), ("slots", 1)):
        raw = data.get(key)
        if raw is not None and (not isinstance(raw, int) or isinstance(raw, bool) or raw < minimum):
            raise ConfigError(f"{source}: {key}: must be an integer >= {minimum} (got {raw!r})")
        ints[key] = raw
    axes: list[tuple[str, tuple[Value, ...]]] = []
    for path, values in data.items():
        if path in RESERVED_KEYS:
            continue
        if not isinstance(path, str):
            raise ConfigError(f"{source}: {path!r}: keys must be dotted config paths")
        _check_path(path, source)
        if not isinstance(values, list) or not values:
            raise ConfigError(
                f"{source}: {path}: must be a non-empty list of values (got {values!r})"
            )
        if path == UAV_COUNT_PATH and any(
            not isinstance(v, int) or isinstance(v, bool) or v < 1 for v in values
        ):
            raise ConfigError(f"{source}: {path}: values must be integers >= 1 (got {values!r})")
        axes.append((path, tuple(_coerce(v) for v in values)))
    paths = [p for p, _ in axes]
    ring = [p for p in paths if p == "uavs.start_xy_m" or p.startswith("uavs.start_xy_m.")]
    if UAV_COUNT_PATH in paths and ring:
        raise ConfigError(f"{source}: uavs.count and {ring[0]} cannot both be swept")
    if (pair := _overlapping(paths)) is not None:
        raise ConfigError(
            f"{source}: {pair[0]} and {pair[1]} cannot both be swept (one is inside the other)"
        )
    runs = ints["runs"]
    return GridSpec(
        axes=tuple(axes),
        methods=methods,
        runs=DEFAULT_RUNS if runs is None else runs,
        seed=ints["seed"],
        slots=ints["slots"],
    )


def load_grid(path: str | Path) -> GridSpec:
    """Read and validate a grid YAML file. Raises ConfigError."""
    p = Path(path)
    try:
        data = load_yaml(p.read_text())
    except OSError as err:
        raise ConfigError(f"{p}: cannot read: {err.strerror}") from None
    except yaml.YAMLError as err:
        raise ConfigError(f"{p}: not valid YAML: {err}") from None
    return parse_grid(data, str(p))


def ring_start_points(
    base_xy: Sequence[Sequence[float]], area_m: Sequence[float], m: int
) -> list[list[float]]:
    """[m, 2] start points (m) evenly on the ring through the base start points (uavs.count)."""
    xy = np.asarray(base_xy, dtype=float).reshape(-1, 2)
    centre = xy.mean(axis=0)
    offsets = xy - centre
    radius = float(np.mean(np.linalg.norm(offsets, axis=1)))
    if radius <= 0.0:
        radius = 0.25 * float(min(area_m))
        phase = math.pi / 2
    else:
        phase = math.atan2(float(offsets[0, 1]), float(offsets[0, 0]))
    angles = phase + 2 * math.pi * np.arange(m) / m
    pts = centre + radius * np.column_stack([np.cos(angles), np.sin(angles)])
    return [[float(round(x, 6)), float(round(y, 6))] for x, y in pts]


@dataclass(frozen=True)
class _MapPlace:
    """Where a path's value goes: `node[key]` of a mapping."""

    node: dict[str, Any]
    key: str


@dataclass(frozen=True)
class _ListPlace:
    """Where a path's value goes: `node[index]` of a list, within it."""

    node: list[Any]
    index: int


_Place = _MapPlace | _ListPlace


def _defaults(section: str) -> dict[str, Any]:
    field = ScenarioFile.model_fields[section]
    return cast(BaseModel, field.get_default(call_default_factory=True)).model_dump(mode="json")


def _kind(value: Any) -> str:
    """What a config value is, in YAML's words (never the value: it may be a secret)."""
    if value is None:
        return "null"
    if isinstance(value, dict | list):
        return "a mapping" if isinstance(value, dict) else "a list"
    if isinstance(value, bool):
        return "a boolean"
    return "a number" if isinstance(value, int | float) else "a string"


def _place(data: dict[str, Any], path: str, create: bool) -> _Place | None:
    """Where `path` puts its value in the config mapping `data`: (the mapping, its key) or (the
    list, its index). A section the config leaves out is created empty (create=True; with
    create=False the walk stops there and returns None). Raises ConfigError, one line naming
    the path, for an index past the end of its list (or into a list the config leaves out) and
    for a list or a mapping expected where the config has another value."""
    parts = path.split(".")
    node: dict[str, Any] | list[Any] = data
    for i, part in enumerate(parts):
        parent, here = ".".join(parts[:i]), ".".join(parts[: i + 1])
        child: Any
        if isinstance(node, list):
            index = _index(part)
            if index is None:
                raise ConfigError(
                    f"{path}: {parent} is a list: index it by a non-negative integer (got {part!r})"
                )
            if index >= len(node):
                n = len(node)
                raise ConfigError(
                    f"{path}: index {index} is out of range: {parent} has {n} "
                    f"{'entry' if n == 1 else 'entries'} in the config"
                )
            if i == len(parts) - 1:
                return _ListPlace(node, index)
            child = node[index]
        else:
            if i == len(parts) - 1:
                return _MapPlace(node, part)
            child = node.get(part)
        wants_list = _index(parts[i + 1]) is not None
        if child is None and isinstance(node, dict):
            if wants_list:
                raise ConfigError(
                    f"{path}: index {parts[i + 1]} is out of range: the config gives no {here}"
                )
            if not create:
                return None
            child = {}
            node[part] = child
        if wants_list and not isinstance(child, list):
            raise ConfigError(f"{path}: {here} is not a list in the config ({_kind(child)})")
        if not wants_list and not isinstance(child, dict):
            raise ConfigError(f"{path}: {here} is not a mapping in the config ({_kind(child)})")
        node = child
    return None  # unreachable: str.split gives at least one part


def apply_overrides(
    base: dict[str, Any], values: Iterable[tuple[str, Value]], slots: int | None
) -> dict[str, Any]:
    """A deep copy of the config mapping with the grid point's values and the slots override."""
    data = copy.deepcopy(base)
    count: int | None = None
    for path, value in values:
        if path == UAV_COUNT_PATH:
            count = cast(int, value)
            continue
        place = _place(data, path, create=True)
        if isinstance(place, _ListPlace):
            place.node[place.index] = copy.deepcopy(value)
        elif isinstance(place, _MapPlace):
            place.node[place.key] = copy.deepcopy(value)
    if count is not None:
        uavs = data.setdefault("uavs", {})
        if not isinstance(uavs, dict):
            raise ConfigError("uavs: must be a mapping")
        start = uavs.get("start_xy_m", _defaults("uavs")["start_xy_m"])
        area = data.get("area", {})
        size = area.get("size_m", _defaults("area")["size_m"]) if isinstance(area, dict) else None
        uavs["start_xy_m"] = ring_start_points(start, size or (3000.0, 3000.0), count)
    if slots is not None:
        timing = data.setdefault("timing", {})
        if not isinstance(timing, dict):
            raise ConfigError("timing: must be a mapping")
        slot_s = timing.get("slot_s", _defaults("timing")["slot_s"])
        timing["duration_s"] = slots * float(slot_s)
    return data


def scenario_key(data: dict[str, Any]) -> str:
    """A stable key of a config mapping (sha1 of its canonical JSON), for per-worker caches."""
    text = json.dumps(data, sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def expand_grid(base: dict[str, Any], grid: GridSpec, source: str = "<config>") -> list[GridPoint]:
    """Validate every grid point; raise one ConfigError listing every bad point."""
    paths = [p for p in grid.paths if p != UAV_COUNT_PATH]
    problems: list[str] = []
    for path in paths:
        try:
            _place(base, path, create=False)
        except ConfigError as err:
            hint = ""
            if path.startswith("targets.") and "targets" not in base and "target" in base:
                hint = " (it gives its target under the deprecated target:, e.g. target.rcs_dbsm)"
            problems.append(f"{source}: {err}{hint}")
    if problems:
        raise ConfigError("\n".join(problems))
    points: list[GridPoint] = []
    for i, combo in enumerate(grid.combinations()):
        values = tuple(zip(grid.paths, combo, strict=True))
        label = ", ".join(f"{p}={fmt_value(v)}" for p, v in values) or "(base)"
        try:
            data = apply_overrides(base, values, grid.slots)
            s = parse_scenario(data, f"grid point {i} ({label})")
        except ConfigError as err:
            problems.append(str(err))
            continue
        points.append(GridPoint(index=i, values=values, scenario=s, key=scenario_key(data)))
    if problems:
        raise ConfigError("\n".join(problems))
    return points


def load_config_mapping(path: str | Path) -> dict[str, Any]:
    """The raw YAML mapping of a scenario file (or a shipped scenario by name), validated once
    with `parse_scenario`."""
    data, source = read_scenario_data(path)
    parse_scenario(data, source)
    return cast(dict[str, Any], data)
