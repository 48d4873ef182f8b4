"""The web requests the console accepts, as strict pydantic models, and their error texts.

Every request body is a JSON object of at most MAX_BODY_BYTES; unknown fields are refused (a
typo must not pass silently). A refusal is a `RequestError` with the HTTP status and a text
that starts with the field at fault, e.g. `command: 'fly' is not one of set, hold, ...` or
`params.rate_min_mbps: -3 is below 0.001`. A control request that passes here is then checked
by the bus's own `control` model (`wire.models.MODELS`) before anything is sent.
"""

from __future__ import annotations

import json
import uuid
from typing import Any, Final, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from isac_mission.errors import MessageError
from isac_mission.wire.control_models import MAX_TRACK_ID
from isac_mission.wire.envelope import dumps, envelope
from isac_mission.wire.models import MODELS
from isac_mission.wire.refusal import message_error

MAX_BODY_BYTES: Final = 4096
COMMANDS: Final = ("set", "hold", "resume", "land", "release", "priority")
"""The fleet commands of `control` (docs/bus.md); the bus model decides which it accepts."""


class RequestError(Exception):
    """A refused web request: HTTP `status` and a text naming the field first."""

    def __init__(self, status: int, text: str) -> None:
        super().__init__(text)
        self.status = status
        self.text = text

    @property
    def field(self) -> str:
        """The field at fault (the text up to its first colon)."""
        return self.text.partition(":")[0]


_STRICT: Final = ConfigDict(strict=True, extra="forbid", frozen=True, allow_inf_nan=False)


class LoginRequest(BaseModel):
    """`POST /api/login`: the operator role's Zenoh password."""

    model_config = _STRICT
    password: str = Field(min_length=1, max_length=256)


class ControlRequest(BaseModel):
    """`POST /api/control`: one fleet command. uav: one vehicle (absent: every vehicle, where
    the command allows it); params: `set`, e.g. {"rate_min_mbps": 20} (R_th, Mbit/s), and
    `priority`, {"weight": 5} (0 to 10); track: `priority` only, the track id."""

    model_config = _STRICT
    command: Literal["set", "hold", "resume", "land", "release", "priority"]
    uav: int | None = Field(default=None, ge=0, le=255)
    params: dict[str, float] | None = None
    track: int | None = Field(default=None, ge=1, le=MAX_TRACK_ID)


def _first_error(err: ValidationError) -> str:
    e = err.errors()[0]
    where = ".".join(str(p) for p in e["loc"]) or "body"
    if e["type"] == "literal_error":
        return f"{where}: {e['input']!r} is not one of {', '.join(COMMANDS)}"
    if e["type"] == "extra_forbidden":
        return f"{where}: unknown field"
    if e["type"] == "missing":
        return f"{where}: missing"
    return f"{where}: {e['msg']}"


RequestT = TypeVar("RequestT", bound=BaseModel)


def parse_body(model: type[RequestT], body: bytes) -> RequestT:
    """The request `body` as `model`; RequestError (413, 400 or 422) naming the field."""
    if len(body) > MAX_BODY_BYTES:
        raise RequestError(413, f"body: {len(body)} bytes, more than {MAX_BODY_BYTES}")
    try:
        obj = json.loads(body.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        raise RequestError(400, "body: not JSON") from None
    if not isinstance(obj, dict):
        raise RequestError(422, "body: expected a JSON object")
    try:
        return model.model_validate(obj)
    except ValidationError as err:
        raise RequestError(422, _first_error(err)) from None


def control_payload(
    req: ControlRequest, *, slot: int, t_s: float, n_uavs: int, request_id: str | None = None
) -> tuple[str, bytes]:
    """The request id and the bus payload of `req`, validated by the bus's `control` model
    (RequestError 422 with its text when the bus would refuse it: nothing is sent)."""
    rid = request_id or uuid.uuid4().hex[:16]
    obj = envelope("control", max(slot, -1), max(t_s, 0.0))
    obj.update(id=rid, command=req.command)
    if req.uav is not None:
        obj["uav"] = req.uav
    if req.params is not None:
        obj["params"] = req.params
    if req.track is not None:
        obj["track"] = req.track
    model = MODELS["control"]
    try:
        model.model_validate(obj, strict=True, context={"n_uavs": n_uavs})
    except ValidationError as err:
        raise RequestError(422, str(message_error(err, "control", model))) from None
    try:
        return rid, dumps(obj)
    except MessageError as err:
        raise RequestError(422, str(err)) from None


def as_json(model: BaseModel) -> dict[str, Any]:
    """A validated request as a JSON-ready dict (for logs and the page's history)."""
    return model.model_dump(mode="json", exclude_none=True)
