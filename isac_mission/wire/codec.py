"""Bus payloads: bytes <-> messages (`wire.models`), one codec for every type.

`decode` checks the size first (`envelope.loads`: size, UTF-8, strict JSON, an object), then
validates the object with the message's model, which holds it as the code uses it (numpy
arrays, NaN for null). Every refusal is a `MessageError` whose text starts with the field at
fault, e.g. ``plan.bandwidth_share: 2 values, expected 3`` (`wire.refusal`). `encode` writes the
model's fields in declaration order by their wire names, leaves out an optional field that is
None, refuses a non-finite array entry by name (``track.P[1][2]: nan is not finite``), and
decodes what it wrote, so that a sender cannot publish a payload its receivers would refuse.

`read_request` is what the ground loop calls on a `control` request: the message, or the refusal
with whatever id and command could be read from the payload (so that the reply can name them).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Final, TypeVar, overload

import numpy as np
from pydantic import TypeAdapter, ValidationError
from pydantic_core import PydanticSerializationError

from isac_mission.errors import MessageError
from isac_mission.types import Detections, FloatArray
from isac_mission.wire.control_models import MAX_ID_CHARS, ControlMsg, ControlReplyMsg
from isac_mission.wire.envelope import Message, Payload, dumps, loads
from isac_mission.wire.models import MODELS, AnyMsg, DetectionMsg, DetectionSetMsg, WireMessage
from isac_mission.wire.refusal import message_error

M = TypeVar("M", bound=Message)
_ANY: Final[TypeAdapter[AnyMsg]] = TypeAdapter(WireMessage)


def _validate(model: type[M], obj: dict[str, Any], n_uavs: int | None, n_bs: int | None) -> M:
    try:
        return model.model_validate(obj, strict=True, context={"n_uavs": n_uavs, "n_bs": n_bs})
    except ValidationError as err:
        raise message_error(err, model.kind(), model) from None


@overload
def decode(
    kind: type[M], payload: Payload, *, n_uavs: int | None = None, n_bs: int | None = None
) -> M: ...
@overload
def decode(
    kind: str, payload: Payload, *, n_uavs: int | None = None, n_bs: int | None = None
) -> AnyMsg: ...
def decode(
    kind: type[Message] | str,
    payload: Payload,
    *,
    n_uavs: int | None = None,
    n_bs: int | None = None,
) -> Message:
    """The message of type `kind` (a model, or its name: "plan") in `payload`.

    n_uavs and n_bs are the receiver's sizes, when it knows them: n_uavs bounds the UAV indices
    (< n_uavs) and is a plan's length, n_bs bounds a plan's BS indices (< n_bs). Raises
    MessageError naming the field at fault (a payload of another type: ``type: ...``).
    """
    model = MODELS[kind] if isinstance(kind, str) else kind
    return _validate(model, loads(payload), n_uavs, n_bs)


def decode_any(payload: Payload, *, n_uavs: int | None = None, n_bs: int | None = None) -> AnyMsg:
    """The message in a payload of any type (`wire.models.WireMessage`), told apart by its
    "type"; n_uavs and n_bs as for `decode`."""
    obj = loads(payload)
    kind = obj.get("type")
    if not isinstance(kind, str) or kind not in MODELS:
        raise MessageError(f"type: unknown payload type {kind!r}")
    try:
        return _ANY.validate_python(obj, strict=True, context={"n_uavs": n_uavs, "n_bs": n_bs})
    except ValidationError as err:
        raise message_error(err, kind, MODELS[kind], tagged=True) from None


def _non_finite(values: list[Any], where: str) -> str | None:
    """The first non-finite number in an array (nested arrays, arrays of objects), named."""
    for i, v in enumerate(values):
        at = f"{where}[{i}]"
        if isinstance(v, float) and not math.isfinite(v):
            return f"{at}: {v} is not finite"
        inner = [(at, v)] if isinstance(v, list) else []
        if isinstance(v, dict):
            inner = [(f"{at}.{k}", x) for k, x in v.items() if isinstance(x, list)]
        for place, array in inner:
            problem = _non_finite(array, place)
            if problem:
                return problem
    return None


def encode(msg: Message) -> bytes:
    """The payload of `msg` (compact JSON, docs/bus.md), checked as its receivers check it.

    Raises MessageError when a receiver would refuse it (naming the field), for a non-finite
    array entry, and for a payload over MAX_PAYLOAD_BYTES.
    """
    kind = msg.kind()
    try:
        fields: dict[str, Any] = msg.model_dump(by_alias=True, warnings=False)
    except PydanticSerializationError as err:
        raise MessageError(f"{kind}: cannot encode: {err}") from None
    optional = {i.alias or n for n, i in type(msg).model_fields.items() if not i.is_required()}
    obj = {k: v for k, v in fields.items() if v is not None or k not in optional}
    for name, value in obj.items():
        problem = _non_finite(value, f"{kind}.{name}") if isinstance(value, list) else None
        if problem:
            raise MessageError(problem)
    data = dumps(obj)
    decode(type(msg), data)
    return data


# --------------------------------------------------------------------------- control requests


@dataclass(frozen=True)
class RequestRead:
    """A request as the ground loop read it: `msg`, or `error` with the readable id/command."""

    msg: ControlMsg | None
    error: MessageError | None
    request_id: str | None
    command: str | None


def _readable(obj: dict[str, Any], name: str) -> str | None:
    value = obj.get(name)
    if isinstance(value, str) and 1 <= len(value) <= MAX_ID_CHARS:
        return value
    return None


def read_request(payload: Payload, *, n_uavs: int | None = None) -> RequestRead:
    """Decode a request for the ground loop; a malformed one gives its error, and the id and
    command if they are strings of 1 to 64 characters (else None)."""
    try:
        obj = loads(payload)
    except MessageError as err:
        return RequestRead(None, err, None, None)
    request_id, command = _readable(obj, "id"), _readable(obj, "command")
    try:
        msg = _validate(ControlMsg, obj, n_uavs, None)
    except MessageError as err:
        return RequestRead(None, err, request_id, command)
    return RequestRead(msg, None, msg.request_id, msg.command)


def _deprecated(old: str, new: str) -> None:
    warnings.warn(f"wire.{old} is deprecated: use wire.{new}", DeprecationWarning, stacklevel=3)


def encode_control(msg: ControlMsg) -> bytes:
    """Deprecated, removed in 0.5.0: `encode(msg)` (the operator's example, docs/deployment.md,
    "Taking a vehicle, and fleet commands")."""
    _deprecated("encode_control", "encode")
    return encode(msg)


def decode_control_reply(payload: Payload) -> ControlReplyMsg:
    """Deprecated, removed in 0.5.0: `decode(ControlReplyMsg, payload)` (the operator's example,
    docs/deployment.md, "Taking a vehicle, and fleet commands")."""
    _deprecated("decode_control_reply", "decode")
    return decode(ControlReplyMsg, payload)


# --------------------------------------------------------------------------- detections


def detection_messages(d: Detections, t_s: float, eta: FloatArray) -> list[DetectionMsg]:
    """Split one slot's `Detections` [M] into per-UAV messages (eta [M]: shares in use)."""
    return [
        DetectionMsg(
            slot=d.slot,
            t_s=t_s,
            uav=m,
            range_m=float(d.range_m[m]),
            radial_velocity_mps=float(d.radial_velocity_mps[m]),
            uav_xy_m=np.asarray(d.uav_xy_m[m], dtype=float),
            bandwidth_share=float(eta[m]),
        )
        for m in range(len(d.range_m))
    ]


def _pairs(values: Any, where: str) -> FloatArray:
    """values as a float array [k, 2] ([0, 2] when empty); MessageError naming `where` if it is
    not one."""
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return np.zeros((0, 2))
    if a.ndim != 2 or a.shape[1] != 2:
        raise MessageError(f"{where}: shape {a.shape}, expected (k, 2)")
    return a


def detection_set_messages(
    slot: int,
    t_s: float,
    measurements_per_uav: Sequence[FloatArray],
    uav_xy_m: FloatArray,
    eta: FloatArray,
) -> list[DetectionSetMsg]:
    """One slot's unlabelled reports as per-UAV messages: measurements_per_uav [M] of [k_m, 2]
    (range m, radial velocity m/s), uav_xy_m [M, 2] where each measured, eta [M] shares in use."""
    return [
        DetectionSetMsg(
            slot=slot,
            t_s=t_s,
            uav=m,
            measurements=_pairs(z, f"detection_set.measurements (uav {m})"),
            uav_xy_m=np.asarray(uav_xy_m[m], dtype=float),
            bandwidth_share=float(eta[m]),
        )
        for m, z in enumerate(measurements_per_uav)
    ]


def collect_detections(slot: int, msgs: Iterable[DetectionMsg], n_uavs: int) -> Detections:
    """Assemble the messages of one slot into `Detections` [M]; absent UAVs get NaN and NaN xy.

    Messages of other slots are ignored; for a UAV sent twice the last message wins.
    """
    rng = np.full(n_uavs, np.nan)
    vel = np.full(n_uavs, np.nan)
    xy = np.full((n_uavs, 2), np.nan)
    for msg in msgs:
        if msg.slot != slot or not 0 <= msg.uav < n_uavs:
            continue
        rng[msg.uav] = msg.range_m
        vel[msg.uav] = msg.radial_velocity_mps
        xy[msg.uav] = msg.uav_xy_m
    return Detections(slot=slot, range_m=rng, radial_velocity_mps=vel, uav_xy_m=xy)
