"""Strict JSON for trace lines: numpy values to JSON-ready Python, no NaN or Infinity tokens.

A trace file is strict JSON (docs/trace.md): every non-finite number is written as `null`, and a
reader refuses the non-standard constants `NaN`, `Infinity` and `-Infinity`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from isac_mission.errors import MessageError


def to_jsonable(value: Any, where: str = "value") -> Any:
    """A JSON-ready copy of value: numpy arrays and scalars to lists and Python numbers, tuples
    to lists, non-finite floats to None. Raises MessageError naming `where` for anything else."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        f = float(value)
        return f if math.isfinite(f) else None
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist(), where)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, Mapping):
        out: dict[str, Any] = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise MessageError(f"{where}: keys must be strings (got {k!r})")
            out[k] = to_jsonable(v, f"{where}.{k}")
        return out
    if isinstance(value, list | tuple):
        return [to_jsonable(v, f"{where}[{i}]") for i, v in enumerate(value)]
    raise MessageError(f"{where}: cannot write {type(value).__name__} to JSON (got {value!r})")


def dumps_line(obj: Any) -> str:
    """One compact strict-JSON line (no newline) of a JSON-ready object."""
    return json.dumps(obj, allow_nan=False, separators=(",", ":"), ensure_ascii=False)


def _reject_constant(token: str) -> Any:
    raise MessageError(f"non-standard JSON constant {token} (non-finite numbers are written null)")


def loads_line(text: str) -> Any:
    """Parse one line; raises MessageError for invalid JSON or a NaN/Infinity token."""
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as err:
        raise MessageError(f"not valid JSON: {err.msg} at column {err.colno}") from None
