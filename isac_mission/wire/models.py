"""The bus messages as pydantic models: the JSON shape of each payload type (docs/bus.md).

Strict (no coercion: a string is not a number, 1.0 is not an integer, true is not a number), no
NaN or infinities, every number bounded (|x| <= MAX_ABS, covariances MAX_ABS_COVARIANCE), array
lengths fixed where the physics fixes them, unknown extra fields ignored. `WireMessage` is the
discriminated union on `type`. A receiver that knows the mission's sizes passes them as
validation context: ``{"n_uavs": M, "n_bs": K}`` bounds UAV and BS indices and the plan's length.
Errors are worded by `wire.refusal` (the field first); `wire.codec` turns a model into the domain
types (numpy arrays, NaN for a missing number).

Slot convention of a plan (docs/bus.md): plan n carries the waypoints q_n that the vehicles fly to
during (n-1, n] and the bandwidth shares eta_n used for slot n's detections; the ground publishes
plan n+1 after it has processed the detections of slot n.
"""

from __future__ import annotations

from typing import Annotated, Any, Final, Literal, get_args

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
)

from isac_mission.wire.control_models import (
    CONTROL_PARAMS as CONTROL_PARAMS,
)
from isac_mission.wire.control_models import (
    ControlReplyWire,
    ControlWire,
    FleetWire,
)
from isac_mission.wire.envelope import (
    MAX_ABS,
    MAX_ABS_COVARIANCE,
    MAX_REASON_CHARS,
    MAX_SLOT,
    MAX_STATUS_CHARS,
    MAX_UAVS,
    SHARE_SUM_TOL,
    WIRE_CONFIG,
    Envelope,
)
from isac_mission.wire.refusal import (
    CHOICES,
    int_problem,
    length_of,
    message_error,
    number_problem,
    refuse,
)

Number = Annotated[float, Field(ge=-MAX_ABS, le=MAX_ABS)]
NonNegative = Annotated[float, Field(ge=0.0, le=MAX_ABS)]
Positive = Annotated[float, Field(ge=1e-6, le=MAX_ABS)]
Share = Annotated[float, Field(ge=0.0, le=1.0)]
CovarianceEntry = Annotated[float, Field(ge=-MAX_ABS_COVARIANCE, le=MAX_ABS_COVARIANCE)]
PlaneXY = Annotated[list[Number], Field(min_length=2, max_length=2), BeforeValidator(length_of(2))]
"""[x, y] in the scenario plane (m): x east, y north."""
State4 = Annotated[list[Number], Field(min_length=4, max_length=4), BeforeValidator(length_of(4))]
"""[x, y, vx, vy] (m, m/s)."""
Row4 = Annotated[
    list[CovarianceEntry], Field(min_length=4, max_length=4), BeforeValidator(length_of(4))
]
Matrix4 = Annotated[list[Row4], Field(min_length=4, max_length=4), BeforeValidator(length_of(4))]
"""A 4 x 4 matrix, row-major, over [x, y, vx, vy]."""
SlotOrBefore = Annotated[int, Field(ge=-1, le=MAX_SLOT)]
"""A slot index, or -1 before the mission has started."""
UavIndex = Annotated[int, Field(ge=0, le=MAX_UAVS - 1)]
Status = Annotated[str, Field(max_length=MAX_STATUS_CHARS)]

TelemetryMode = Literal[
    "unknown", "manual", "takeoff", "hold", "offboard", "land", "mission", "rtl", "other"
]
TELEMETRY_MODES: Final = frozenset(get_args(TelemetryMode))
LinkState = Literal["ok", "lost"]
LINK_STATES: Final = frozenset(get_args(LinkState))
MAX_COUNTERS: Final = 200
MAX_MEASUREMENTS: Final = 512
"""Most measurements in one `detection_set` (one UAV's targets and false alarms of a slot)."""
MAX_TARGETS: Final = 64
"""Most targets in one `truth_set`; a measurement's origin is -1 (a false alarm) or a target
index, 0 to MAX_TARGETS - 1."""
MAX_TRACKS: Final = 64
"""Most tracks in one `track_set`."""
MAX_TRACK_ID: Final = MAX_SLOT
"""Largest track id (ids start at 1)."""
MAX_WALL_S: Final = 1.0e11
"""Largest wall-clock stamp accepted (Unix time, s): the year 5138."""
PublishedWall = Annotated[
    float | None,
    Field(
        default=None,
        ge=0.0,
        le=MAX_WALL_S,
        description="Wall clock (Unix time, s) at which the publisher put the message; optional.",
    ),
]

CHOICES.update(
    mode=("{value!r} is not one of {allowed}", TELEMETRY_MODES),
    link=("{value!r} is not one of {allowed}", LINK_STATES),
)


def _context(info: ValidationInfo, name: str) -> int | None:
    ctx = info.context
    value = ctx.get(name) if isinstance(ctx, dict) else None
    return value if isinstance(value, int) else None


def _at_most(where: str, value: Any, most: int) -> Any:
    """A before-check: an array (a list) holds at most `most` items (pydantic's own text would
    say "expected <most>")."""
    if isinstance(value, list) and len(value) > most:
        raise refuse(f"{where}: {len(value)} values, expected at most {most}")
    return value


def _uav_in_mission(kind: str, uav: Any, info: ValidationInfo) -> Any:
    """An integer UAV index must lie in [0, n_uavs) (n_uavs from the context, else MAX_UAVS);
    anything else is left to the model's type check."""
    if isinstance(uav, int) and not isinstance(uav, bool):
        n_uavs = _context(info, "n_uavs")
        problem = int_problem(uav, 0, (n_uavs if n_uavs is not None else MAX_UAVS) - 1)
        if problem:
            raise refuse(f"{kind}.uav: {problem}")
    return uav


class DetectionWire(Envelope):
    """One UAV's detection of one slot (`isac/<mission>/detections/<m>`); a miss has null range
    and radial velocity, so the receiver knows at once that nothing more will come."""

    type: Literal["detection"]
    uav: UavIndex = Field(description="0-based UAV index (< n_uavs when the receiver knows M).")
    range_m: NonNegative | None = Field(description="Measured range (m); null when missed.")
    radial_velocity_mps: Number | None = Field(
        description="Measured radial velocity (m/s); null when missed."
    )
    uav_xy_m: PlaneXY = Field(description="Where the UAV was when it measured (m).")
    bandwidth_share: Share = Field(description="The bandwidth share eta in use.")

    @field_validator("uav", mode="before")
    @classmethod
    def _uav_known(cls, uav: Any, info: ValidationInfo) -> Any:
        return _uav_in_mission("detection", uav, info)


Measurement = Annotated[
    list[Number],
    Field(
        min_length=2,
        max_length=2,
        json_schema_extra={
            "prefixItems": [
                {"type": "number", "minimum": 0.0, "maximum": MAX_ABS},
                {"type": "number", "minimum": -MAX_ABS, "maximum": MAX_ABS},
            ]
        },
    ),
    BeforeValidator(length_of(2)),
]
"""[range m >= 0, radial velocity m/s]."""


class DetectionSetWire(Envelope):
    """One UAV's unlabelled report of one slot on a multi-target mission
    (`isac/<mission>/detections/<m>`): every echo it detected, targets and false alarms alike, in
    no particular order; an empty list when it detected nothing (still sent)."""

    type: Literal["detection_set"]
    uav: UavIndex = Field(description="0-based UAV index (< n_uavs when the receiver knows M).")
    measurements: list[Measurement] = Field(
        max_length=MAX_MEASUREMENTS,
        description="[range m >= 0, radial velocity m/s] per echo; may be empty.",
    )
    uav_xy_m: PlaneXY = Field(description="Where the UAV was when it measured (m).")
    bandwidth_share: Share = Field(description="The bandwidth share eta in use.")

    @field_validator("uav", mode="before")
    @classmethod
    def _uav_known(cls, uav: Any, info: ValidationInfo) -> Any:
        return _uav_in_mission("detection_set", uav, info)

    @field_validator("measurements", mode="before")
    @classmethod
    def _few_measurements(cls, value: Any) -> Any:
        return _at_most("detection_set.measurements", value, MAX_MEASUREMENTS)

    @field_validator("measurements")
    @classmethod
    def _ranges_non_negative(cls, measurements: list[list[float]]) -> list[list[float]]:
        for i, (range_m, _) in enumerate(measurements):
            if range_m < 0.0:
                problem = number_problem(range_m, lo=0.0)
                raise refuse(f"detection_set.measurements[{i}][0]: {problem}")
        return measurements


class ClockWire(Envelope):
    """Simulation time (`isac/<mission>/clock`): slot n means t >= mission_t0 + n slot_s."""

    type: Literal["clock"]
    slot: SlotOrBefore
    mission_t0: NonNegative | None = Field(
        description="Simulation time (s) at which slot 0 began; null before it has."
    )
    slot_s: Positive = Field(description="Slot length (s).")
    speed: Positive = Field(description="Simulation seconds per wall second.")


class TruthWire(Envelope):
    """The target's true state at a slot (`isac/<mission>/truth`), from the simulated world."""

    type: Literal["truth"]
    target_x: State4 = Field(description="[x, y, vx, vy] (m, m/s).")


OriginIndex = Annotated[int, Field(ge=-1, le=MAX_TARGETS - 1)]
"""The target a measurement came from, or -1: a false alarm."""
OriginsOfUav = Annotated[list[OriginIndex], Field(max_length=MAX_MEASUREMENTS)]
"""One UAV's origins, one per measurement of its `detection_set`, in the same order."""


class TruthSetWire(Envelope):
    """Every target's true state at a slot on a multi-target mission (`isac/<mission>/truth`),
    from the simulated world; evaluation only."""

    type: Literal["truth_set"]
    targets: list[State4 | None] = Field(
        max_length=MAX_TARGETS,
        description="[x, y, vx, vy] (m, m/s) of target t = 0..T-1; null: not in the scene.",
    )
    origins: list[OriginsOfUav] = Field(
        default_factory=list,
        max_length=MAX_UAVS,
        description="Per UAV, the target index of each measurement of its detection_set of the "
        "slot, in order (-1: a false alarm); [] when not given.",
    )

    @field_validator("targets", mode="before")
    @classmethod
    def _few_targets(cls, value: Any) -> Any:
        return _at_most("truth_set.targets", value, MAX_TARGETS)

    @field_validator("origins", mode="before")
    @classmethod
    def _few_origins(cls, value: Any) -> Any:
        _at_most("truth_set.origins", value, MAX_UAVS)
        if isinstance(value, list):
            for m, of_uav in enumerate(value):
                _at_most(f"truth_set.origins[{m}]", of_uav, MAX_MEASUREMENTS)
        return value


class PlanWire(Envelope):
    """A slot plan (`isac/<mission>/plan`) for M UAVs: all three arrays have length M."""

    type: Literal["plan"]
    assoc: list[int] = Field(
        description="BS index per UAV, or -1 for a vehicle outside the plan (share 0)."
    )
    bandwidth_share: list[Share] = Field(
        description="eta per UAV; sums to 1, or every share is 0 when no UAV has a BS."
    )
    waypoints_xy_m: list[PlaneXY] = Field(description="Next waypoint per UAV (m).")
    end_velocity_mps: list[PlaneXY] | None = Field(
        default=None,
        description="Planned velocity per UAV at its waypoint (m/s, planner.vehicle_model); "
        "absent or null: not planned (the bridge ends the leg at its mean velocity).",
    )
    objective: NonNegative | None = Field(description="tr(PCRB) of the plan; null if unknown.")
    status: Status = Field(min_length=1, description="Solver status: ok, infeasible, ...")
    reason: str = Field(default="", max_length=MAX_REASON_CHARS, description="Why, if not ok.")
    solve_s: NonNegative = Field(description="Planner wall time (s).")

    @field_validator("assoc", mode="before")
    @classmethod
    def _assoc_size(cls, assoc: Any, info: ValidationInfo) -> Any:
        if isinstance(assoc, list):
            m, n_uavs = len(assoc), _context(info, "n_uavs")
            if n_uavs is not None and m != n_uavs:
                raise refuse(f"plan.assoc: {m} values, expected {n_uavs}")
            if not 1 <= m <= MAX_UAVS:
                raise refuse(f"plan.assoc: {m} values, expected 1 to {MAX_UAVS}")
        return assoc

    @field_validator("assoc")
    @classmethod
    def _assoc_fits(cls, assoc: list[int], info: ValidationInfo) -> list[int]:
        n_bs = _context(info, "n_bs")
        hi = (n_bs if n_bs is not None else 10 * MAX_UAVS) - 1
        if min(assoc) < -1 or max(assoc) > hi:
            i = next(i for i, k in enumerate(assoc) if not -1 <= k <= hi)
            raise refuse(f"plan.assoc[{i}]: {int_problem(assoc[i], -1, hi)}")
        return assoc

    @field_validator("bandwidth_share", "waypoints_xy_m", "end_velocity_mps", mode="before")
    @classmethod
    def _one_per_uav(cls, value: Any, info: ValidationInfo) -> Any:
        assoc = info.data.get("assoc")
        if isinstance(value, list) and assoc is not None and len(value) != len(assoc):
            raise refuse(f"plan.{info.field_name}: {len(value)} values, expected {len(assoc)}")
        return value

    @field_validator("bandwidth_share")
    @classmethod
    def _shares_fit(cls, shares: list[float], info: ValidationInfo) -> list[float]:
        assoc = info.data.get("assoc")
        if assoc is not None and min(assoc) < 0:
            for i, (k, eta) in enumerate(zip(assoc, shares, strict=True)):
                if k < 0 and eta > 0:
                    raise refuse(f"plan.assoc[{i}]: -1 (no BS) with a share > 0")
        # numpy's sum (pairwise from 8 terms on); below 8 terms it adds in order, as sum() does.
        total = float(sum(shares)) if len(shares) < 8 else float(np.asarray(shares).sum())
        if assoc is not None and max(assoc) < 0 and total == 0.0:
            return shares  # nobody served (every vehicle held): every share 0
        if abs(total - 1.0) > SHARE_SUM_TOL:
            raise refuse(f"plan.bandwidth_share: sums to {total:.9g}, expected 1")
        return shares


class TelemetryWire(Envelope):
    """One vehicle's state as its MAVLink bridge saw it (`isac/<mission>/telemetry/<m>`)."""

    type: Literal["telemetry"]
    slot: SlotOrBefore
    uav: UavIndex = Field(description="0-based UAV index.")
    position_xy_m: PlaneXY = Field(description="Position in the scenario plane (m).")
    altitude_m: float = Field(ge=-1000.0, le=100_000.0, description="Above scenario ground (m).")
    velocity_xy_mps: Annotated[
        list[Annotated[float, Field(ge=-1000.0, le=1000.0)]],
        Field(min_length=2, max_length=2),
        BeforeValidator(length_of(2)),
    ] = Field(description="Horizontal velocity [east, north] (m/s).")
    mode: TelemetryMode = Field(description="Flight mode.")
    armed: bool
    landed: bool
    link: LinkState = Field(description="The MAVLink link: ok or lost.")
    published_wall_s: PublishedWall = None
    override: Status = Field(
        default="",
        description="Why the service does not fly the vehicle ('operator: HOLD', 'RTL: low "
        "battery', 'landed', ...); '' while it does (docs/service.md, 'Operator override').",
    )

    @field_validator("uav", mode="before")
    @classmethod
    def _uav_known(cls, uav: Any, info: ValidationInfo) -> Any:
        return _uav_in_mission("telemetry", uav, info)


class TrackWire(Envelope):
    """The ground's estimate after slot `slot` (`isac/<mission>/track`)."""

    type: Literal["track"]
    x: State4 = Field(description="EKF state [x, y, vx, vy] (m, m/s).")
    P: Matrix4 = Field(description="EKF covariance.")
    J: Matrix4 = Field(description="PCRB information.")
    pcrb_trace: NonNegative = Field(description="tr(J^-1) (m^2 + m^2/s^2).")
    published_wall_s: PublishedWall = None


class TrackEntryWire(BaseModel):
    """One track of a `track_set`."""

    model_config = WIRE_CONFIG

    id: int = Field(ge=1, le=MAX_TRACK_ID, description="Track id: stable, never reused.")
    confirmed: bool = Field(description="Confirmed (true) or tentative (false).")
    x: State4 = Field(description="Track state [x, y, vx, vy] (m, m/s).")
    P: Matrix4 = Field(description="Its covariance.")
    pcrb_position_trace: NonNegative = Field(
        description="Trace of the position block of its bound with origin uncertainty (m^2)."
    )


class TrackSetWire(Envelope):
    """The ground's tracks after slot `slot` on a multi-target mission (`isac/<mission>/track`):
    tentative and confirmed, each id at most once."""

    type: Literal["track_set"]
    tracks: list[TrackEntryWire] = Field(max_length=MAX_TRACKS, description="The tracks.")
    published_wall_s: PublishedWall = None

    @field_validator("tracks", mode="before")
    @classmethod
    def _entries(cls, value: Any) -> Any:
        """Each track is validated here, so that a refusal names it (`track_set.tracks[3].P[1]`)
        with its field's bounds; anything but a list of objects is left to the type check."""
        _at_most("track_set.tracks", value, MAX_TRACKS)
        if not isinstance(value, list) or not all(isinstance(e, dict) for e in value):
            return value
        entries = []
        for i, entry in enumerate(value):
            try:
                entries.append(TrackEntryWire.model_validate(entry, strict=True))
            except ValidationError as err:
                where = f"track_set.tracks[{i}]"
                raise refuse(str(message_error(err, where, TrackEntryWire))) from None
        return entries

    @field_validator("tracks")
    @classmethod
    def _distinct_ids(cls, tracks: list[TrackEntryWire]) -> list[TrackEntryWire]:
        first: dict[int, int] = {}
        for i, track in enumerate(tracks):
            j = first.setdefault(track.id, i)
            if j != i:
                raise refuse(f"track_set.tracks[{i}].id: {track.id} repeats tracks[{j}].id")
        return tracks


class HealthWire(Envelope):
    """Service status (`isac/<mission>/health`): counters by name, vehicle states, last error."""

    type: Literal["health"]
    slot: SlotOrBefore
    counters: dict[str, Annotated[int, Field(ge=0, le=MAX_SLOT)]] = Field(
        description=f"Counter name -> count (at most {MAX_COUNTERS} counters)."
    )
    vehicles: dict[str, str] = Field(
        default_factory=dict, description='Vehicle index -> "active" or "excluded: <why>".'
    )
    status: Status = Field(description="Status word.")
    last_error: str = Field(max_length=MAX_REASON_CHARS, description="The last error, or ''.")

    @field_validator("counters", mode="before")
    @classmethod
    def _few_counters(cls, value: Any) -> Any:
        if not isinstance(value, dict) or len(value) > MAX_COUNTERS:
            raise refuse(f"health.counters: expected an object of at most {MAX_COUNTERS} counters")
        return value

    @field_validator("vehicles", mode="before")
    @classmethod
    def _vehicle_states(cls, value: Any) -> Any:
        if not isinstance(value, dict) or len(value) > MAX_UAVS:
            raise refuse("health.vehicles: expected an object of vehicle states")
        for k, v in value.items():
            if not str(k).isdecimal() or not isinstance(v, str):
                raise refuse(f"health.vehicles.{k}: expected index -> state string")
        return value


WireMessage = Annotated[
    DetectionWire
    | DetectionSetWire
    | ClockWire
    | TruthWire
    | TruthSetWire
    | PlanWire
    | TelemetryWire
    | TrackWire
    | TrackSetWire
    | HealthWire
    | ControlWire
    | ControlReplyWire
    | FleetWire,
    Field(discriminator="type"),
]
"""Any bus payload, told apart by its `type`."""

MODELS: Final[dict[str, type[Envelope]]] = {
    "detection": DetectionWire,
    "detection_set": DetectionSetWire,
    "clock": ClockWire,
    "truth": TruthWire,
    "truth_set": TruthSetWire,
    "plan": PlanWire,
    "telemetry": TelemetryWire,
    "track": TrackWire,
    "track_set": TrackSetWire,
    "health": HealthWire,
    "control": ControlWire,
    "control_reply": ControlReplyWire,
    "fleet": FleetWire,
}
"""Message type -> its model."""
