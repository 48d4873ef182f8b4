"""The field types the bus messages are made of: each one's JSON shape (type, bounds, lengths:
what a receiver validates and the JSON Schema shows) and how the message holds it in code.

A number is held as a float and written with `float()`, an integer with `int()`, a flag with
`bool()`, so that numpy scalars and Python ints write as they always have (`1.0`, not `1`).
A field held otherwise carries a `Held` marker: validated as its JSON shape, then held as
`load(value)` (numpy float64 arrays, `assoc` int64, NaN for null, tuples for lists) and written
back as `dump(held)`. Units and shapes are in the message models (`wire.models`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any, Final

import numpy as np
from pydantic import BeforeValidator, Field, GetCoreSchemaHandler, PlainSerializer
from pydantic_core import CoreSchema, PydanticCustomError, core_schema

from isac_mission.types import FloatArray, IntArray
from isac_mission.wire.envelope import (
    MAX_ABS,
    MAX_ABS_COVARIANCE,
    MAX_SLOT,
    MAX_STATUS_CHARS,
    MAX_UAVS,
)
from isac_mission.wire.strict_json import finite_or_none

WIRE_LENGTH: Final = "isac_wire_length"
"""The pydantic error type of an array of the wrong length (checked before its items)."""


def length_of(n: int) -> Callable[[Any], Any]:
    """A before-validator: an array (a list) must hold exactly n items; checked before the
    items are, so that a short array is refused as such whatever it holds."""

    def check(value: Any) -> Any:
        if isinstance(value, list) and len(value) != n:
            raise PydanticCustomError(
                WIRE_LENGTH, "{got} values, expected {want}", {"got": len(value), "want": n}
            )
        return value

    return check


@dataclass(frozen=True)
class Held:
    """A field validated as the JSON shape `json`, held as `load(validated)` and written back
    as `dump(held)` (then through `json`'s own serializers: item types, nested models)."""

    json: Any
    load: Callable[[Any], Any]
    dump: Callable[[Any], Any]

    def __get_pydantic_core_schema__(
        self, source: Any, handler: GetCoreSchemaHandler
    ) -> CoreSchema:
        shape = handler.generate_schema(self.json)
        return core_schema.no_info_after_validator_function(
            self.load,
            shape,
            serialization=core_schema.plain_serializer_function_ser_schema(
                self.dump, return_schema=shape
            ),
        )


def cut(n: int) -> PlainSerializer:
    """Written as its first n characters (the receivers' limit)."""
    return PlainSerializer(lambda text: text[:n])


AS_FLOAT: Final = PlainSerializer(float)
AS_INT: Final = PlainSerializer(int)
Flag = Annotated[bool, PlainSerializer(bool)]
Number = Annotated[float, Field(ge=-MAX_ABS, le=MAX_ABS), AS_FLOAT]
NonNegative = Annotated[float, Field(ge=0.0, le=MAX_ABS), AS_FLOAT]
Positive = Annotated[float, Field(ge=1e-6, le=MAX_ABS), AS_FLOAT]
Share = Annotated[float, Field(ge=0.0, le=1.0), AS_FLOAT]
CovarianceEntry = Annotated[float, Field(ge=-MAX_ABS_COVARIANCE, le=MAX_ABS_COVARIANCE), AS_FLOAT]
SlotOrBefore = Annotated[int, Field(ge=-1, le=MAX_SLOT), AS_INT]
"""A slot index, or -1 before the mission has started."""
UavIndex = Annotated[int, Field(ge=0, le=MAX_UAVS - 1), AS_INT]
Status = Annotated[str, Field(max_length=MAX_STATUS_CHARS)]
PlaneXY = Annotated[list[Number], Field(min_length=2, max_length=2), BeforeValidator(length_of(2))]
"""[x, y] in the scenario plane (m): x east, y north."""
State4 = Annotated[list[Number], Field(min_length=4, max_length=4), BeforeValidator(length_of(4))]
"""[x, y, vx, vy] (m, m/s)."""
Row4 = Annotated[
    list[CovarianceEntry], Field(min_length=4, max_length=4), BeforeValidator(length_of(4))
]
Matrix4 = Annotated[list[Row4], Field(min_length=4, max_length=4), BeforeValidator(length_of(4))]
"""A 4 x 4 matrix, row-major, over [x, y, vx, vy]."""


def _floats(value: Any) -> FloatArray:
    return np.array(value, dtype=float)


def _flat(held: Any) -> list[float]:
    out: list[float] = np.asarray(held, dtype=float).ravel().tolist()
    return out


def _nested(held: Any) -> Any:
    return np.asarray(held, dtype=float).tolist()


def vector(json: Any) -> Held:
    """A JSON array of numbers held as a float64 array (written flat, row-major)."""
    return Held(json, _floats, _flat)


def matrix(json: Any) -> Held:
    """A JSON array of arrays of numbers held as a 2-D float64 array."""
    return Held(json, _floats, _nested)


def rows(json: Any, width: int) -> Held:
    """A JSON array of k arrays of `width` numbers held as a float64 array [k, width] (k = 0:
    shape (0, width))."""
    return Held(
        json, lambda value: np.array(value, dtype=float).reshape(len(value), width), _nested
    )


def _int64s(value: Any) -> IntArray:
    return np.array(value, dtype=np.int64)


def _ints(held: Any) -> list[int]:
    return [int(k) for k in np.asarray(held).ravel()]


def int_vector(json: Any) -> Held:
    """A JSON array of integers held as an int64 array."""
    return Held(json, _int64s, _ints)


def int_tuple(json: Any) -> Held:
    """A JSON array of integers held as a tuple of ints."""
    return Held(json, tuple, lambda held: [int(k) for k in held])


def _nan_for_none(value: float | None) -> float:
    return math.nan if value is None else value


def nan_for_null(json: Any) -> Held:
    """A JSON number or null held as a float, NaN for null (a NaN or infinity is written null)."""
    return Held(json, _nan_for_none, finite_or_none)
