"""A refused payload in the project's words: pydantic's first validation error as a MessageError
whose message starts with the field at fault (``plan.bandwidth_share: 2 values, expected 3``).

The wire models (`wire.models`) validate; this module only words what they found, using the
failing input and the bounds declared on the field, so that the texts stay those the receivers
count and log (`envelope.rejection_reason`). Checks that pydantic cannot express (a bound given
by the receiver, a sum over a list) raise `refuse(text)` with the whole text.
"""

from __future__ import annotations

import math
import types
import typing
from collections.abc import Sequence
from typing import Any, Final, Union

import annotated_types
from pydantic import BaseModel, ValidationError, ValidationInfo
from pydantic.fields import FieldInfo
from pydantic_core import ErrorDetails, PydanticCustomError

from isac_mission.errors import MessageError
from isac_mission.wire.envelope import (
    MAX_ABS,
    MAX_ABS_COVARIANCE,
    MAX_STATUS_CHARS,
    MAX_UAVS,
    SCHEMA,
)
from isac_mission.wire.fields import WIRE_LENGTH, Held

WIRE_ERROR: Final = "isac_wire"
"""The pydantic error type of a check written in this package (its context holds the text)."""

CHOICES: Final[dict[str, tuple[str, frozenset[str]]]] = {}
"""Field name -> (how a wrong value is worded, the allowed values) of the string choices
(filled by wire.models: telemetry mode and link, control command)."""


def refuse(text: str) -> PydanticCustomError:
    """The error a validator raises for a check of its own; `text` names the field first."""
    return PydanticCustomError(WIRE_ERROR, "{text}", {"text": text})


def number_problem(
    value: Any, *, lo: float | None = None, hi: float | None = None, limit: float = MAX_ABS
) -> str | None:
    """What is wrong with a JSON number (not a bool) that must be finite, |x| <= limit and in
    [lo, hi]; None if nothing is."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return f"expected a number, got {type(value).__name__}"
    try:
        x = float(value)
    except OverflowError:
        return f"{value} is too large (limit {limit:g})"
    if not math.isfinite(x):
        return f"{x} is not finite"
    if abs(x) > limit:
        return f"{x:g} is too large (limit {limit:g})"
    if lo is not None and x < lo:
        return f"{x:g} is below {lo:g}"
    if hi is not None and x > hi:
        return f"{x:g} is above {hi:g}"
    return None


def int_problem(value: int, lo: int, hi: int) -> str | None:
    """What is wrong with an integer that must lie in [lo, hi]; None if nothing is."""
    if lo <= value <= hi:
        return None
    shown = value if abs(value) < 10**12 else f"{str(value)[:8]}..."
    return f"{shown} is outside [{lo}, {hi}]"


def receiver_size(info: ValidationInfo, name: str) -> int | None:
    """A size the receiver passed as validation context ("n_uavs", "n_bs"), or None."""
    ctx = info.context
    value = ctx.get(name) if isinstance(ctx, dict) else None
    return value if isinstance(value, int) else None


def check_uav(where: str, uav: Any, info: ValidationInfo) -> Any:
    """A before-check: an integer UAV index lies in [0, n_uavs) (the receiver's n_uavs, else
    MAX_UAVS); anything else is left to the model's type check."""
    if isinstance(uav, int) and not isinstance(uav, bool):
        n_uavs = receiver_size(info, "n_uavs")
        problem = int_problem(uav, 0, (n_uavs if n_uavs is not None else MAX_UAVS) - 1)
        if problem:
            raise refuse(f"{where}: {problem}")
    return uav


def _unwrap(tp: Any, metadata: list[Any]) -> tuple[Any, list[Any]]:
    """Strip Annotated (collecting its constraints), Optional, and a `Held` field's holding
    (down to its JSON shape) from a field's type."""
    while True:
        held = next((m for m in metadata if isinstance(m, Held)), None)
        if held is not None:
            metadata = [m for m in metadata if m is not held]
            tp = held.json
            continue
        origin = typing.get_origin(tp)
        if origin is typing.Annotated:
            base, *extra = typing.get_args(tp)
            for item in extra:
                metadata += item.metadata if isinstance(item, FieldInfo) else [item]
            tp = base
        elif origin in (Union, types.UnionType):
            tp = next(a for a in typing.get_args(tp) if a is not type(None))
        else:
            return tp, metadata


def _leaf(model: type[BaseModel], loc: Sequence[int | str]) -> tuple[Any, list[Any]]:
    """The type and the constraints of the value at `loc` in `model` (list items, dict values);
    loc[0] is the field's name on the wire."""
    info = next((f for name, f in model.model_fields.items() if (f.alias or name) == loc[0]), None)
    if info is None:
        return None, []
    tp, meta = _unwrap(info.annotation, list(info.metadata))
    for _ in loc[1:]:
        args = typing.get_args(tp)
        if not args:
            return None, []
        tp, meta = _unwrap(args[-1], [])
    return tp, meta


def _bounds(meta: list[Any]) -> tuple[Any, Any]:
    lo = next((m.ge for m in meta if isinstance(m, annotated_types.Ge)), None)
    hi = next((m.le for m in meta if isinstance(m, annotated_types.Le)), None)
    return lo, hi


def _bound_text(model: type[BaseModel], loc: Sequence[int | str], value: Any) -> str:
    tp, meta = _leaf(model, loc)
    lo, hi = _bounds(meta)
    if tp is int and lo is not None and hi is not None:
        return int_problem(int(value), int(lo), int(hi)) or f"{value} is out of range"
    limit = MAX_ABS_COVARIANCE if hi == MAX_ABS_COVARIANCE else MAX_ABS
    return (
        number_problem(
            value,
            lo=None if lo == -limit else lo,
            hi=None if hi == limit else hi,
            limit=limit,
        )
        or f"{value} is out of range"
    )


def _where(kind: str, loc: Sequence[int | str]) -> str:
    text = f"{kind}.{loc[0]}" if kind else str(loc[0])
    return text + "".join(f"[{s}]" if isinstance(s, int) else f".{s}" for s in loc[1:])


def _choice_text(field: str, value: Any) -> str:
    wording, allowed = CHOICES[field]
    if not isinstance(value, str):
        return f"expected a string, got {type(value).__name__}"
    if len(value) > MAX_STATUS_CHARS:
        return f"{len(value)} characters, limit {MAX_STATUS_CHARS}"
    return wording.format(value=value, allowed=sorted(allowed))


def _envelope_text(field: str, kind: str, value: Any) -> str:
    if field == "schema":
        if isinstance(value, str) and value.startswith("isac/"):
            return f"schema: unsupported version {value!r} (expected {SCHEMA!r})"
        return f"schema: expected {SCHEMA!r}, got {value!r}"
    return f"type: expected {kind!r}, got {value!r}"


_TYPE_NAMES: Final = {
    "float_type": "a number",
    "int_type": "an integer",
    "string_type": "a string",
    "list_type": "an array",
    "bool_type": "true or false",
    "dict_type": "an object",
    "model_type": "an object",
}


def explain(e: ErrorDetails, kind: str, model: type[BaseModel]) -> str:
    """One pydantic error as a message naming the field (`kind.field[i]...: what is wrong`)."""
    loc, kind_of, value = e["loc"], e["type"], e.get("input")
    ctx = e.get("ctx") or {}
    if kind_of == WIRE_ERROR:
        return str(ctx["text"])
    if not loc:
        return f"payload: {e['msg']}"
    field = str(loc[0])
    if len(loc) == 1 and field in ("schema", "type"):
        return _envelope_text(field, kind, None if kind_of == "missing" else value)
    where = _where(kind, loc)
    if kind_of == "missing":
        return f"{where}: missing"
    if kind_of == WIRE_LENGTH:
        return f"{where}: {ctx['got']} values, expected {ctx['want']}"
    if kind_of == "literal_error" and field in CHOICES:
        return f"{where}: {_choice_text(field, value)}"
    if kind_of in ("greater_than_equal", "less_than_equal", "finite_number") or (
        kind_of == "float_type" and isinstance(value, int) and not isinstance(value, bool)
    ):
        return f"{where}: {_bound_text(model, loc, value)}"
    if kind_of in _TYPE_NAMES:
        return f"{where}: expected {_TYPE_NAMES[kind_of]}, got {type(value).__name__}"
    if kind_of in ("too_short", "too_long"):
        want = ctx.get("min_length") if kind_of == "too_short" else ctx.get("max_length")
        got = len(value) if isinstance(value, list) else ctx.get("actual_length")
        return f"{where}: {got} values, expected {want}"
    if kind_of == "string_too_long":
        return f"{where}: {len(value)} characters, limit {ctx['max_length']}"
    if kind_of == "string_too_short":
        return f"{where}: empty"
    return f"{where}: {e['msg']}"


def message_error(
    err: ValidationError, kind: str, model: type[BaseModel], *, tagged: bool = False
) -> MessageError:
    """The MessageError of the first error pydantic found in a payload of type `kind`.

    tagged: the error comes from the discriminated union, whose locations start with the tag.
    """
    first = err.errors(include_url=False)[0]
    if tagged and first["loc"]:
        first["loc"] = first["loc"][1:]
    return MessageError(explain(first, kind, model))
