"""Strict JSON, shared by the bus payloads (`isac_mission.wire`) and the run trace (`records/`).

Strict means: the text holds no NaN, Infinity or -Infinity token (standard JSON has none, but
Python's `json` writes and reads them by default), and a writer refuses non-finite numbers instead
of writing those tokens. A non-finite number that stands for "missing" is written as JSON `null`
by the caller (`finite_or_none`, `to_jsonable`). No sockets, no zenoh; errors are `MessageError`
(or `NonFiniteTokenError`, which each caller words in its own terms).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from isac_mission.errors import MessageError


class NonFiniteTokenError(ValueError):
    """The text holds a NaN, Infinity or -Infinity token (`token` says which)."""

    def __init__(self, token: str) -> None:
        super().__init__(f"{token} is not allowed")
        self.token = token


def _reject_constant(token: str) -> Any:
    raise NonFiniteTokenError(token)


def loads_strict(text: str | bytes) -> Any:
    """`json.loads` that refuses NaN/Infinity tokens.

    Raises NonFiniteTokenError for such a token, and whatever `json.loads` raises otherwise
    (`json.JSONDecodeError`, `ValueError` for an integer beyond Python's digit limit,
    `RecursionError` for deep nesting): the caller names the place in its own words.
    """
    return json.loads(text, parse_constant=_reject_constant)


def dumps_strict(obj: Any, *, ensure_ascii: bool = True) -> str:
    """Compact JSON text (`,` and `:` separators) that refuses NaN and infinities (ValueError)."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False, ensure_ascii=ensure_ascii)


def finite_or_none(x: float) -> float | None:
    """x as a float, or None (JSON null) when it is NaN or infinite."""
    return float(x) if math.isfinite(x) else None


def finite_floats(values: Any, where: str) -> list[float]:
    """A flat list of finite floats from any array-like (shape ignored, row-major order).

    Raises MessageError naming `where[i]` for the first non-finite entry.
    """
    out = [float(v) for v in np.asarray(values, dtype=float).ravel()]
    for i, v in enumerate(out):
        if not math.isfinite(v):
            raise MessageError(f"{where}[{i}]: {v} is not finite")
    return out


def to_jsonable(value: Any, where: str = "value") -> Any:
    """A JSON-ready copy of value: numpy arrays and scalars to lists and Python numbers, tuples
    to lists, paths to strings, non-finite floats to None. Raises MessageError naming `where` for
    anything else (and for a mapping key that is not a string)."""
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
