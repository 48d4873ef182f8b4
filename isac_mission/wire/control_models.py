"""The operator's side of the bus as pydantic models: `control` requests, their `control_reply`,
and the `fleet` commands the ground loop sends the bridges (docs/bus.md, "control").

A request names its command and carries an id chosen by the sender; the reply repeats the id.
Which fields a command takes (checked here, so that nothing is executed on a malformed request):

| command | uav | params |
|---|---|---|
| `set` | - | required (CONTROL_PARAMS) |
| `hold`, `land`, `resume` | optional (absent or null: every vehicle) | - |
| `release` | required | - |

In code the request id is `request_id` (`id` on the wire) and lists are tuples
(`wire.models` has the rest of the conventions).
"""

from __future__ import annotations

from typing import Annotated, Any, Final, Literal, get_args

from pydantic import Field, PlainSerializer, ValidationInfo, field_validator, model_validator

from isac_mission.wire.envelope import MAX_REASON_CHARS, MAX_UAVS, Message, carried
from isac_mission.wire.fields import Flag, SlotOrBefore, UavIndex, cut, int_tuple
from isac_mission.wire.refusal import CHOICES, check_uav, number_problem, refuse

ControlCommand = Literal["set", "hold", "resume", "land", "release"]
CONTROL_COMMANDS: Final = frozenset(get_args(ControlCommand))
FleetCommand = Literal["hold", "resume", "land", "release"]
FLEET_COMMANDS: Final = frozenset(get_args(FleetCommand))
CONTROL_PARAMS: Final = {"rate_min_mbps": (1e-3, 1e5)}
"""Operator-settable planning parameters and their accepted ranges (`isac/<mission>/control`)."""
MAX_ID_CHARS: Final = 64
"""Longest request id."""

RequestId = Annotated[str, Field(min_length=1, max_length=MAX_ID_CHARS)]

CHOICES.update(
    command=("{value!r} is not a command (expected one of {allowed})", CONTROL_COMMANDS),
)


def _written_params(params: dict[str, float] | None) -> dict[str, float] | None:
    """None (left out) for no parameters, else each value as a float."""
    return {name: float(x) for name, x in params.items()} if params else None


class ControlMsg(Message):
    """An operator's request (`isac/<mission>/control`), answered on `control/reply`.

    request_id: chosen by the sender, repeated in the reply; uav: the vehicle index, None for
    every vehicle (hold, land, resume; release names one; set takes none); params (set only, else
    None): name (CONTROL_PARAMS) -> value, rate_min_mbps is R_th in Mbit/s, from the next planned
    slot on.
    """

    type: Literal["control"] = carried()
    slot: SlotOrBefore
    request_id: Annotated[RequestId, Field(alias="id")] = Field(
        description="Request id chosen by the sender; the reply repeats it."
    )
    command: ControlCommand = Field(description="set, hold, resume, land or release.")
    uav: UavIndex | None = Field(
        default=None,
        description="Vehicle index: hold/land/resume one vehicle (absent: all); release: required.",
    )
    params: Annotated[dict[str, float] | None, PlainSerializer(_written_params)] = Field(
        default=None, description="set only: parameter name -> value (CONTROL_PARAMS)."
    )

    @classmethod
    def set_params(cls, slot: int, t_s: float, request_id: str, **params: float) -> ControlMsg:
        """A `set` request, e.g. ControlMsg.set_params(3, 30.0, "r1", rate_min_mbps=20.0)."""
        return cls(slot=slot, t_s=t_s, request_id=request_id, command="set", params=dict(params))

    @field_validator("uav", mode="before")
    @classmethod
    def _uav_known(cls, uav: Any, info: ValidationInfo) -> Any:
        return check_uav("control.uav", uav, info)

    @field_validator("params", mode="before")
    @classmethod
    def _known_params(cls, value: Any) -> Any:
        if value is None:
            return value
        if not isinstance(value, dict) or not value:
            raise refuse("control.params: expected a non-empty object")
        for name, x in value.items():
            if name not in CONTROL_PARAMS:
                known = ", ".join(sorted(CONTROL_PARAMS))
                raise refuse(f"control.params.{name}: unknown parameter (known: {known})")
            lo, hi = CONTROL_PARAMS[name]
            problem = number_problem(x, lo=lo, hi=hi)
            if problem:
                raise refuse(f"control.params.{name}: {problem}")
        return value

    @model_validator(mode="after")
    def _fields_of_command(self) -> ControlMsg:
        if self.command == "set":
            if self.params is None:
                raise refuse("control.params: missing (command 'set' needs parameters)")
            if self.uav is not None:
                raise refuse("control.uav: not allowed with command 'set'")
        elif self.params is not None:
            raise refuse(f"control.params: not allowed with command {self.command!r}")
        if self.command == "release" and self.uav is None:
            raise refuse("control.uav: missing (command 'release' names one vehicle)")
        return self


class ControlReplyMsg(Message):
    """The ground loop's answer to one request (`isac/<mission>/control/reply`).

    request_id, command: as sent (None when they could not be read); a refusal's reason names the
    field at fault first; vehicles: the vehicle indices it acted on.
    """

    type: Literal["control_reply"] = carried()
    slot: SlotOrBefore
    request_id: Annotated[RequestId | None, Field(alias="id")] = Field(
        description="The request's id; null when it could not be read."
    )
    command: Annotated[str, Field(max_length=MAX_ID_CHARS), cut(MAX_ID_CHARS)] | None = Field(
        description="The request's command as sent (null when it could not be read)."
    )
    accepted: Flag = Field(description="True: executed; false: refused, nothing was executed.")
    reason: Annotated[str, cut(MAX_REASON_CHARS)] = Field(
        max_length=MAX_REASON_CHARS,
        description="Why it was refused (the field at fault first), or why accepted.",
    )
    effect: Annotated[str, cut(MAX_REASON_CHARS)] = Field(
        max_length=MAX_REASON_CHARS, description="What the ground loop did."
    )
    vehicles: Annotated[
        tuple[int, ...], int_tuple(Annotated[list[UavIndex], Field(max_length=MAX_UAVS)])
    ] = Field(default_factory=tuple, description="The vehicles it acted on.")


class FleetMsg(Message):
    """A command of the ground loop to the bridges (`isac/<mission>/fleet`), on an operator's
    request `id`: hold, resume, land or release the listed vehicles.

    request_id: the operator's request id; uavs: the vehicle indices.
    """

    type: Literal["fleet"] = carried()
    slot: SlotOrBefore
    request_id: Annotated[RequestId, Field(alias="id")] = Field(
        description="The operator's request id."
    )
    command: FleetCommand = Field(description="hold, resume, land or release.")
    uavs: Annotated[
        tuple[int, ...],
        int_tuple(Annotated[list[UavIndex], Field(min_length=1, max_length=MAX_UAVS)]),
    ] = Field(description="Vehicles.")

    @field_validator("uavs", mode="before")
    @classmethod
    def _uavs_known(cls, uavs: Any, info: ValidationInfo) -> Any:
        if isinstance(uavs, list):
            for i, uav in enumerate(uavs):
                check_uav(f"fleet.uavs[{i}]", uav, info)
        return uavs
