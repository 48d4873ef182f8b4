"""The operator's side of the bus as pydantic models: `control` requests, their `control_reply`,
and the `fleet` commands the ground loop sends the bridges (docs/bus.md, "control").

A request names its command and carries an id chosen by the sender; the reply repeats the id.
Which fields a command takes (checked here, so that nothing is executed on a malformed request):

| command | uav | params | track |
|---|---|---|---|
| `set` | - | required (CONTROL_PARAMS) | - |
| `priority` | - | required: `weight` (PRIORITY_PARAMS) | required |
| `hold`, `land`, `resume` | optional (absent or null: every vehicle) | - | - |
| `release` | required | - | - |

In code the request id is `request_id` (`id` on the wire) and lists are tuples
(`wire.models` has the rest of the conventions).
"""

from __future__ import annotations

from typing import Annotated, Any, Final, Literal, get_args

from pydantic import Field, PlainSerializer, ValidationInfo, field_validator, model_validator

from isac_mission.tracking.priorities import MAX_PRIORITY
from isac_mission.wire.envelope import MAX_REASON_CHARS, MAX_SLOT, MAX_UAVS, Message, carried
from isac_mission.wire.fields import AS_INT, Flag, SlotOrBefore, UavIndex, cut, int_tuple
from isac_mission.wire.refusal import CHOICES, check_uav, number_problem, refuse

ControlCommand = Literal["set", "priority", "hold", "resume", "land", "release"]
CONTROL_COMMANDS: Final = frozenset(get_args(ControlCommand))
FleetCommand = Literal["hold", "resume", "land", "release"]
FLEET_COMMANDS: Final = frozenset(get_args(FleetCommand))
CONTROL_PARAMS: Final = {"rate_min_mbps": (1e-3, 1e5)}
"""Operator-settable planning parameters of `set` and their accepted ranges
(`isac/<mission>/control`)."""
PRIORITY_PARAMS: Final = {"weight": (0.0, MAX_PRIORITY)}
"""The parameter of `priority`: the track's weight, 0 (not planned for, still kept clear of) to
MAX_PRIORITY."""
COMMAND_PARAMS: Final = {"set": CONTROL_PARAMS, "priority": PRIORITY_PARAMS}
"""The commands that take parameters, and which."""
MAX_TRACK_ID: Final = MAX_SLOT
"""Largest track id (ids start at 1; as `wire.models.MAX_TRACK_ID`)."""
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
    every vehicle (hold, land, resume; release names one; set and priority take none); params
    (set and priority, else None): name -> value, for set (CONTROL_PARAMS) rate_min_mbps is R_th
    in Mbit/s, for priority (PRIORITY_PARAMS) weight is the track's priority in [0, 10], each from
    the next planned slot on; track (priority only, else None): the track id.
    """

    type: Literal["control"] = carried()
    slot: SlotOrBefore
    request_id: Annotated[RequestId, Field(alias="id")] = Field(
        description="Request id chosen by the sender; the reply repeats it."
    )
    command: ControlCommand = Field(description="set, priority, hold, resume, land or release.")
    uav: UavIndex | None = Field(
        default=None,
        description="Vehicle index: hold/land/resume one vehicle (absent: all); release: required.",
    )
    params: Annotated[dict[str, float] | None, PlainSerializer(_written_params)] = Field(
        default=None,
        description="set: parameter name -> value (rate_min_mbps); priority: {weight}.",
    )
    track: Annotated[int, Field(ge=1, le=MAX_TRACK_ID), AS_INT] | None = Field(
        default=None, description="priority only: the track id (>= 1)."
    )

    @classmethod
    def set_params(cls, slot: int, t_s: float, request_id: str, **params: float) -> ControlMsg:
        """A `set` request, e.g. ControlMsg.set_params(3, 30.0, "r1", rate_min_mbps=20.0)."""
        return cls(slot=slot, t_s=t_s, request_id=request_id, command="set", params=dict(params))

    @classmethod
    def priority(
        cls, slot: int, t_s: float, request_id: str, track: int, weight: float
    ) -> ControlMsg:
        """A `priority` request: track `track`'s weight in [0, 10] from the next planned slot on,
        e.g. ControlMsg.priority(3, 30.0, "p1", track=2, weight=5.0)."""
        return cls(
            slot=slot,
            t_s=t_s,
            request_id=request_id,
            command="priority",
            params={"weight": weight},
            track=track,
        )

    @field_validator("uav", mode="before")
    @classmethod
    def _uav_known(cls, uav: Any, info: ValidationInfo) -> Any:
        return check_uav("control.uav", uav, info)

    @field_validator("params", mode="before")
    @classmethod
    def _known_params(cls, value: Any, info: ValidationInfo) -> Any:
        if value is None:
            return value
        if not isinstance(value, dict) or not value:
            raise refuse("control.params: expected a non-empty object")
        known = COMMAND_PARAMS.get(info.data.get("command", ""))
        if known is None:  # a command without parameters: refused as such after the names
            known = {name: r for params in COMMAND_PARAMS.values() for name, r in params.items()}
        for name, x in value.items():
            if name not in known:
                names = ", ".join(sorted(known))
                raise refuse(f"control.params.{name}: unknown parameter (known: {names})")
            lo, hi = known[name]
            problem = number_problem(x, lo=lo, hi=hi)
            if problem:
                raise refuse(f"control.params.{name}: {problem}")
        return value

    @model_validator(mode="after")
    def _fields_of_command(self) -> ControlMsg:
        command = self.command
        if command in COMMAND_PARAMS:
            if self.params is None:
                needs = "a weight" if command == "priority" else "parameters"
                raise refuse(f"control.params: missing (command {command!r} needs {needs})")
            if self.uav is not None:
                raise refuse(f"control.uav: not allowed with command {command!r}")
        elif self.params is not None:
            raise refuse(f"control.params: not allowed with command {command!r}")
        if command == "priority":
            if self.params is not None and "weight" not in self.params:
                raise refuse("control.params.weight: missing (command 'priority' sets a weight)")
            if self.track is None:
                raise refuse("control.track: missing (command 'priority' names one track)")
        elif self.track is not None:
            raise refuse(f"control.track: not allowed with command {command!r}")
        if command == "release" and self.uav is None:
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
