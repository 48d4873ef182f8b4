"""Bytes <-> the operator's messages: `control` requests, `control_reply`, `fleet` (docs/bus.md).

`read_request` is what the ground loop calls on a request: the decoded `ControlMsg`, or the
refusal with whatever id and command could be read from the payload (so that the reply can
name them; None when they cannot be read).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from isac_mission.errors import MessageError
from isac_mission.wire.control_models import (
    MAX_ID_CHARS,
    ControlReplyWire,
    ControlWire,
    FleetWire,
)
from isac_mission.wire.envelope import MAX_REASON_CHARS, Payload, dumps, envelope, loads
from isac_mission.wire.messages import ControlMsg, ControlReplyMsg, FleetMsg
from isac_mission.wire.refusal import message_error

M = TypeVar("M", bound=BaseModel)


def _validate(model: type[M], kind: str, obj: dict[str, Any], context: dict[str, Any]) -> M:
    try:
        return model.model_validate(obj, strict=True, context=context)
    except ValidationError as err:
        raise message_error(err, kind, model) from None


# --------------------------------------------------------------------------- control


def encode_control(msg: ControlMsg) -> bytes:
    """Payload of `isac/<mission>/control` (uav and params only when set)."""
    obj = envelope("control", msg.slot, msg.t_s)
    obj.update(id=msg.request_id, command=msg.command)
    if msg.uav is not None:
        obj["uav"] = int(msg.uav)
    if msg.params:
        obj["params"] = {k: float(v) for k, v in msg.params.items()}
    data = dumps(obj)
    decode_control(data)
    return data


def control_msg(w: ControlWire) -> ControlMsg:
    """The domain message of a validated request."""
    params = {k: float(v) for k, v in (w.params or {}).items()}
    return ControlMsg(w.slot, w.t, w.id, w.command, w.uav, params)


def decode_control(payload: Payload, *, n_uavs: int | None = None) -> ControlMsg:
    """Validate a control request: id, a known command and the fields it takes (module doc of
    wire.control_models), known parameters within their ranges, uav < n_uavs when given."""
    return control_msg(_validate(ControlWire, "control", loads(payload), {"n_uavs": n_uavs}))


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
        msg = control_msg(_validate(ControlWire, "control", obj, {"n_uavs": n_uavs}))
    except MessageError as err:
        return RequestRead(None, err, request_id, command)
    return RequestRead(msg, None, msg.request_id, msg.command)


# --------------------------------------------------------------------------- reply, fleet


def encode_control_reply(msg: ControlReplyMsg) -> bytes:
    """Payload of `isac/<mission>/control/reply` (reason and effect cut to 1000 characters)."""
    obj = envelope("control_reply", msg.slot, msg.t_s)
    obj.update(
        id=msg.request_id,
        command=None if msg.command is None else msg.command[:MAX_ID_CHARS],
        accepted=bool(msg.accepted),
        reason=msg.reason[:MAX_REASON_CHARS],
        effect=msg.effect[:MAX_REASON_CHARS],
        vehicles=[int(m) for m in msg.vehicles],
    )
    data = dumps(obj)
    decode_control_reply(data)
    return data


def control_reply_msg(w: ControlReplyWire) -> ControlReplyMsg:
    """The domain message of a validated reply."""
    return ControlReplyMsg(
        w.slot, w.t, w.id, w.command, w.accepted, w.reason, w.effect, tuple(w.vehicles)
    )


def decode_control_reply(payload: Payload) -> ControlReplyMsg:
    """Validate a reply payload."""
    return control_reply_msg(_validate(ControlReplyWire, "control_reply", loads(payload), {}))


def encode_fleet(msg: FleetMsg) -> bytes:
    """Payload of `isac/<mission>/fleet`."""
    obj = envelope("fleet", msg.slot, msg.t_s)
    obj.update(id=msg.request_id, command=msg.command, uavs=[int(m) for m in msg.uavs])
    data = dumps(obj)
    decode_fleet(data)
    return data


def fleet_msg(w: FleetWire) -> FleetMsg:
    """The domain message of a validated fleet command."""
    return FleetMsg(w.slot, w.t, w.id, w.command, tuple(w.uavs))


def decode_fleet(payload: Payload, *, n_uavs: int | None = None) -> FleetMsg:
    """Validate a fleet command (vehicle indices < n_uavs when given)."""
    return fleet_msg(_validate(FleetWire, "fleet", loads(payload), {"n_uavs": n_uavs}))
