"""The payload envelope: limits, the size guard, strict parsing, and the common fields.

Every payload is a UTF-8 JSON object of at most `MAX_PAYLOAD_BYTES` bytes with

    "schema": "isac/1"      format and version (a different version is refused),
    "type":   "detection" | "clock" | "truth" | "plan" | ...,
    "slot":   int           the slot the payload belongs to (>= 0; a clock may say -1: not started),
    "t":      float         simulation time in seconds,

plus the fields of its type (SI units, names carry the unit; docs/bus.md). Unknown extra fields
are ignored so that a newer isac/1 sender can add fields. The size is checked before anything is
parsed; NaN and Infinity tokens are refused by the parser (`strict_json`). `Message` is the base
of every message model (`wire.models`): these four fields, and `WireModel`'s construction in code.
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Final, Literal, get_args, get_origin

from pydantic import BaseModel, ConfigDict, Field, PlainSerializer

from isac_mission.errors import MessageError
from isac_mission.wire.strict_json import NonFiniteTokenError, dumps_strict, loads_strict

SCHEMA: Final = "isac/1"
"""Format name and major version carried in every payload."""
MAX_PAYLOAD_BYTES: Final = 64 * 1024
"""Longest payload accepted (a plan for 256 UAVs is about 20 kB)."""
MAX_ABS: Final = 1.0e9
"""Largest magnitude accepted for any number (m, m/s, s, m^2): far beyond any sane value."""
MAX_ABS_COVARIANCE: Final = 1.0e150
"""Covariance and information entries span many decades (the literal eq. 8 gives PCRB
information near 1e20 m^-2, a UAV close to the target 1e9 with the calibrated model): only
finiteness and a bound far beyond them are checked."""
MAX_SLOT: Final = 1_000_000_000
MAX_UAVS: Final = 256
MAX_STATUS_CHARS: Final = 64
MAX_REASON_CHARS: Final = 1000
SHARE_SUM_TOL: Final = 1.0e-6
"""|sum(eta) - 1| allowed in a plan."""

Payload = bytes | bytearray | memoryview | str
"""What a decoder accepts: the payload bytes (or their text)."""


def _schema_title(model: type) -> str:
    """A model's title in the JSON Schema: `DetectionMsg` -> `DetectionWire`, `TrackEntry` ->
    `TrackEntryWire` (the published names, whatever the classes are called)."""
    return model.__name__.removesuffix("Msg") + "Wire"


WIRE_CONFIG: Final = ConfigDict(
    strict=True,
    allow_inf_nan=False,
    frozen=True,
    extra="ignore",
    populate_by_name=False,
    model_title_generator=_schema_title,
)
"""Every wire model: strict types (no "3" for 3, no 1.0 for an int, no true for a number), no
NaN or infinities, immutable, unknown fields ignored (isac/1 senders may add fields), the wire's
names only (`t`, not `t_s`)."""


def carried(**field: Any) -> Any:
    """The field info of `schema` and `type`: required in every payload; a message built in
    code takes them from its class (`WireModel.__init__`), so a type checker sees them as
    optional (it does not look into this call)."""
    return Field(**field)


class WireModel(BaseModel):
    """A bus model: validated strictly from a payload's object (`model_validate`, the wire's
    names; `wire.codec.decode`), built in code as a frozen dataclass is.

    Built in code (`DetectionMsg(slot=4, t_s=4.0, ...)`, or positionally in declaration order),
    a model holds what it is given, unchecked, numpy arrays and NaN included, so that building
    one never fails; `wire.codec.encode` checks what it writes. A field whose type is a single
    `Literal` (`schema`, `type`) is set from that type.
    """

    model_config = WIRE_CONFIG

    def __init__(self, *args: Any, **fields: Any) -> None:
        cls = type(self)
        constants = {
            name: get_args(info.annotation)[0]
            for name, info in cls.model_fields.items()
            if get_origin(info.annotation) is Literal and len(get_args(info.annotation)) == 1
        }
        names = [name for name in cls.model_fields if name not in constants]
        if len(args) > len(names):
            raise TypeError(f"{cls.__name__} takes {len(names)} arguments, {len(args)} given")
        values = dict(zip(names, args, strict=False))
        for name, value in fields.items():
            if name in values or name not in cls.model_fields:
                raise TypeError(f"{cls.__name__}: unexpected or repeated argument {name!r}")
            values[name] = value
        missing = [n for n in names if n not in values and cls.model_fields[n].is_required()]
        if missing:
            raise TypeError(f"{cls.__name__}: missing {', '.join(missing)}")
        built = cls.model_construct(**(constants | values))
        for attr in ("__dict__", "__pydantic_fields_set__", "__pydantic_extra__"):
            object.__setattr__(self, attr, getattr(built, attr))
        object.__setattr__(self, "__pydantic_private__", None)

    # Not a custom init to pydantic (as RootModel's): validation does not go through it.
    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]


class Message(WireModel):
    """The fields every payload starts with (each message type narrows `type`, some `slot`)."""

    schema_: Literal["isac/1"] = carried(alias="schema", description="Format and major version.")
    type: str = carried(description="The message type (the union's discriminator).")
    slot: Annotated[int, PlainSerializer(int)] = Field(
        ge=0, le=MAX_SLOT, description="The slot the payload belongs to."
    )
    t_s: Annotated[
        float,
        Field(alias="t", ge=0.0, le=MAX_ABS, description="Simulation time (s) when it was sent."),
        PlainSerializer(float),
    ]
    """Simulation time (s) when the message was made (`t` on the wire)."""

    @classmethod
    def kind(cls) -> str:
        """The message type (`type` on the wire): "detection", "plan", ..."""
        kind: str = get_args(cls.model_fields["type"].annotation)[0]
        return kind


def envelope(kind: str, slot: int, t_s: float) -> dict[str, Any]:
    """The common fields of a payload of type `kind`, as a dict to add the type's fields to."""
    return {"schema": SCHEMA, "type": kind, "slot": int(slot), "t": float(t_s)}


def dumps(obj: Any) -> bytes:
    """Compact UTF-8 JSON; refuses NaN and infinities and anything over MAX_PAYLOAD_BYTES."""
    try:
        text = dumps_strict(obj)
    except (ValueError, TypeError) as err:
        raise MessageError(f"cannot encode: {err}") from None
    data = text.encode()
    if len(data) > MAX_PAYLOAD_BYTES:
        raise MessageError(f"payload: {len(data)} bytes, more than {MAX_PAYLOAD_BYTES}")
    return data


def loads(payload: Payload) -> dict[str, Any]:
    """Parse a payload into a JSON object: size (first), UTF-8, JSON syntax, no NaN/Infinity."""
    if isinstance(payload, str):
        payload = payload.encode()
    data = bytes(payload)
    if len(data) > MAX_PAYLOAD_BYTES:
        raise MessageError(f"payload: {len(data)} bytes, more than {MAX_PAYLOAD_BYTES}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise MessageError("payload: not UTF-8") from None
    try:
        obj = loads_strict(text)
    except NonFiniteTokenError as err:
        raise MessageError(
            f"payload: {err.token} is not allowed (numbers must be finite)"
        ) from None
    except (ValueError, RecursionError) as err:
        raise MessageError(f"payload: not JSON ({err})") from None
    if not isinstance(obj, dict):
        raise MessageError(f"payload: expected a JSON object, got {type(obj).__name__}")
    return obj


_PAYLOAD_REASONS: Final = (
    ("bytes, more than", "payload too large"),
    ("not UTF-8", "payload not UTF-8"),
    ("is not allowed", "payload non-finite"),
    ("not JSON", "payload not JSON"),
    ("expected a JSON object", "payload not an object"),
)
_REASON_NAME_RE: Final = re.compile(r"[A-Za-z_][A-Za-z0-9_.\[\]]{0,63}")


def rejection_reason(err: MessageError) -> str:
    """A short, stable name for why a payload was refused, for counters: the field at fault
    ("schema", "type", "detection.range_m", ...) or, for the payload as a whole, "payload too
    large" (refused before parsing), "payload not UTF-8", "payload not JSON", "payload
    non-finite" (a NaN/Infinity token) or "payload not an object". Anything unexpected is
    "other", so that the set of names stays small whatever a sender puts in a payload."""
    name, _, detail = str(err).partition(":")
    if name == "payload":
        return next((r for needle, r in _PAYLOAD_REASONS if needle in detail), "payload")
    return name if _REASON_NAME_RE.fullmatch(name) else "other"
