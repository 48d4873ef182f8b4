"""Field coercion for trace records: numbers, arrays and strings, each error naming the field.

Arrays come back read-only: float64 (`None`/`null` -> NaN) or int64 BS indices (`null` -> -1).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from isac_mission.errors import MessageError
from isac_mission.types import FloatArray, IntArray


def _leaves_are_numbers(value: Any) -> bool:
    if isinstance(value, list | tuple):
        return all(_leaves_are_numbers(v) for v in value)
    return value is None or (
        isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
    )


def float_array(value: Any, name: str, shape: tuple[int | None, ...]) -> FloatArray:
    """value as a float64 array of the given shape (None = any length); None/null become NaN."""
    if isinstance(value, np.ndarray):
        if not (np.issubdtype(value.dtype, np.number) and not np.issubdtype(value.dtype, np.bool_)):
            raise MessageError(f"{name}: expected numbers, got an array of {value.dtype}")
        arr = np.array(value, dtype=np.float64)
    else:
        if not _leaves_are_numbers(value):
            raise MessageError(f"{name}: expected numbers or null (got {value!r})")
        try:
            arr = np.array(value, dtype=np.float64)
        except ValueError:
            raise MessageError(f"{name}: ragged nested lists (got {value!r})") from None
    if arr.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(arr.shape, shape, strict=True)
    ):
        want_txt = "[" + ", ".join("M" if w is None else str(w) for w in shape) + "]"
        raise MessageError(f"{name}: expected shape {want_txt}, got {list(arr.shape)}")
    arr.setflags(write=False)
    return arr


def _is_integral(v: Any) -> bool:
    """True for an int (not bool) or an integral finite float."""
    if isinstance(v, bool | np.bool_):
        return False
    if isinstance(v, int | np.integer):
        return True
    return isinstance(v, float | np.floating) and math.isfinite(v) and float(v).is_integer()


def int_array(value: Any, name: str) -> IntArray:
    """value as an int64 vector; None/null become -1 (no BS); non-integral numbers are refused."""
    raw = value.tolist() if isinstance(value, np.ndarray) else value
    if not isinstance(raw, list | tuple):
        raise MessageError(f"{name}: expected a list of BS indices (got {value!r})")
    out: list[int] = []
    for i, v in enumerate(raw):
        if v is None:
            out.append(-1)
        elif _is_integral(v):
            out.append(int(v))
        else:
            raise MessageError(f"{name}[{i}]: expected an integer BS index (got {v!r})")
    arr = np.array(out, dtype=np.int64).reshape(len(out))
    arr.setflags(write=False)
    return arr


def as_float(value: Any, name: str) -> float:
    """A float from a number or None (NaN)."""
    if value is None:
        return math.nan
    if isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool):
        return float(value)
    raise MessageError(f"{name}: expected a number or null (got {value!r})")


def as_int(value: Any, name: str) -> int:
    """An int (not bool) from an integer."""
    if isinstance(value, int | np.integer) and not isinstance(value, bool):
        return int(value)
    raise MessageError(f"{name}: expected an integer (got {value!r})")


def as_str(value: Any, name: str) -> str:
    """A str, or MessageError naming the field."""
    if isinstance(value, str):
        return value
    raise MessageError(f"{name}: expected a string (got {value!r})")
