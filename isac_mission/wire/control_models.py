"""The operator's side of the bus as pydantic models: `control` requests, their `control_reply`,
and the `fleet` commands the ground loop sends the bridges (docs/bus.md, "control").

A request names its command and carries an id chosen by the sender; the reply repeats the id.
Which fields a command takes (checked here, so that nothing is executed on a malformed request):

| command | uav | params |
|---|---|---|
| `set` | - | required (CONTROL_PARAMS) |
| `hold`, `land`, `resume` | optional (absent or null: every vehicle) | - |
| `release` | required | - |
"""

from __future__ import annotations

from typing import Annotated, Any, Final, Literal, get_args

from pydantic import Field, ValidationInfo, field_validator, model_validator

from isac_mission.wire.envelope import MAX_REASON_CHARS, MAX_SLOT, MAX_UAVS, Envelope
from isac_mission.wire.refusal import CHOICES, int_problem, number_problem, refuse

ControlCommand = Literal["set", "hold", "resume", "land", "release"]
CONTROL_COMMANDS: Final = frozenset(get_args(ControlCommand))
FleetCommand = Literal["hold", "resume", "land", "release"]
FLEET_COMMANDS: Final = frozenset(get_args(FleetCommand))
CONTROL_PARAMS: Final = {"rate_min_mbps": (1e-3, 1e5)}
"""Operator-settable planning parameters and their accepted ranges (`isac/<mission>/control`)."""
MAX_ID_CHARS: Final = 64
"""Longest request id."""

RequestId = Annotated[str, Field(min_length=1, max_length=MAX_ID_CHARS)]
SlotOrBefore = Annotated[int, Field(ge=-1, le=MAX_SLOT)]
UavIndex = Annotated[int, Field(ge=0, le=MAX_UAVS - 1)]

CHOICES.update(
    command=("{value!r} is not a command (expected one of {allowed})", CONTROL_COMMANDS),
)


def _n_uavs(info: ValidationInfo) -> int:
    ctx = info.context
    value = ctx.get("n_uavs") if isinstance(ctx, dict) else None
    return value if isinstance(value, int) else MAX_UAVS


def _check_uav(where: str, uav: Any, info: ValidationInfo) -> Any:
    if isinstance(uav, int) and not isinstance(uav, bool):
        problem = int_problem(uav, 0, _n_uavs(info) - 1)
        if problem:
            raise refuse(f"{where}: {problem}")
    return uav


class ControlWire(Envelope):
    """An operator's request (`isac/<mission>/control`), answered on `control/reply`."""

    type: Literal["control"]
    slot: SlotOrBefore
    id: RequestId = Field(description="Request id chosen by the sender; the reply repeats it.")
    command: ControlCommand = Field(description="set, hold, resume, land or release.")
    uav: UavIndex | None = Field(
        default=None,
        description="Vehicle index: hold/land/resume one vehicle (absent: all); release: required.",
    )
    params: dict[str, float] | None = Field(
        default=None, description="set only: parameter name -> value (CONTROL_PARAMS)."
    )

    @field_validator("uav", mode="before")
    @classmethod
    def _uav_known(cls, uav: Any, info: ValidationInfo) -> Any:
        return _check_uav("control.uav", uav, info)

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
    def _fields_of_command(self) -> ControlWire:
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


class ControlReplyWire(Envelope):
    """The ground loop's answer to one request (`isac/<mission>/control/reply`)."""

    type: Literal["control_reply"]
    slot: SlotOrBefore
    id: RequestId | None = Field(description="The request's id; null when it could not be read.")
    command: Annotated[str, Field(max_length=MAX_ID_CHARS)] | None = Field(
        description="The request's command as sent (null when it could not be read)."
    )
    accepted: bool = Field(description="True: executed; false: refused, nothing was executed.")
    reason: str = Field(
        max_length=MAX_REASON_CHARS,
        description="Why it was refused (the field at fault first), or why accepted.",
    )
    effect: str = Field(max_length=MAX_REASON_CHARS, description="What the ground loop did.")
    vehicles: list[UavIndex] = Field(
        default_factory=list, max_length=MAX_UAVS, description="The vehicles it acted on."
    )


class FleetWire(Envelope):
    """A command of the ground loop to the bridges (`isac/<mission>/fleet`), on an operator's
    request `id`: hold, resume, land or release the listed vehicles."""

    type: Literal["fleet"]
    slot: SlotOrBefore
    id: RequestId = Field(description="The operator's request id.")
    command: FleetCommand = Field(description="hold, resume, land or release.")
    uavs: list[UavIndex] = Field(min_length=1, max_length=MAX_UAVS, description="Vehicles.")

    @field_validator("uavs", mode="before")
    @classmethod
    def _uavs_known(cls, uavs: Any, info: ValidationInfo) -> Any:
        if isinstance(uavs, list):
            for i, uav in enumerate(uavs):
                _check_uav(f"fleet.uavs[{i}]", uav, info)
        return uavs
