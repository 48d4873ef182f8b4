"""The bus messages (docs/bus.md): one pydantic model per payload type, which is at once its JSON
shape, what a receiver validates, its JSON Schema, and the message the code builds and reads.

On the wire, strict (no coercion: a string is not a number, 1.0 is not an integer, true is not a
number), no NaN or infinities, every number bounded (|x| <= MAX_ABS, covariances
MAX_ABS_COVARIANCE), array lengths fixed where the physics fixes them, unknown extra fields
ignored. `WireMessage` is the discriminated union on `type`. A receiver that knows the mission's
sizes passes them as validation context: ``{"n_uavs": M, "n_bs": K}`` bounds UAV and BS indices
and the plan's length. Errors are worded by `wire.refusal` (the field first).

In code, a message holds numpy float64 arrays (`assoc` int64), NaN for a number sent as null,
tuples for lists, and the domain names where they differ from the wire's (`t_s` is `t`); built
in code it is not checked (`wire.envelope.WireModel`), `wire.codec.encode` checks it. Each
class's first docstring paragraph is its description in the JSON Schema.

Slot convention of a plan (docs/bus.md): plan n carries the waypoints q_n that the vehicles fly to
during (n-1, n] and the bandwidth shares eta_n used for slot n's detections; the ground publishes
plan n+1 after it has processed the detections of slot n.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Final, Literal, get_args

import numpy as np
from pydantic import (
    AfterValidator,
    BeforeValidator,
    Field,
    SerializerFunctionWrapHandler,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_serializer,
)

from isac_mission.tracking.priorities import DEFAULT_PRIORITY, MAX_PRIORITY
from isac_mission.types import FloatArray, IntArray, SlotPlan, SolveReport
from isac_mission.wire.control_models import (
    CONTROL_PARAMS as CONTROL_PARAMS,
)
from isac_mission.wire.control_models import (
    ControlMsg,
    ControlReplyMsg,
    FleetMsg,
)
from isac_mission.wire.envelope import (
    MAX_ABS,
    MAX_REASON_CHARS,
    MAX_SLOT,
    MAX_STATUS_CHARS,
    MAX_UAVS,
    SHARE_SUM_TOL,
    Message,
    WireModel,
    carried,
)
from isac_mission.wire.fields import (
    AS_FLOAT,
    AS_INT,
    Flag,
    Held,
    Matrix4,
    NonNegative,
    Number,
    PlaneXY,
    Positive,
    Share,
    SlotOrBefore,
    State4,
    Status,
    UavIndex,
    cut,
    int_vector,
    length_of,
    matrix,
    nan_for_null,
    rows,
    vector,
)
from isac_mission.wire.refusal import (
    CHOICES,
    check_uav,
    int_problem,
    message_error,
    number_problem,
    receiver_size,
    refuse,
)

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
    Annotated[float, Field(ge=0.0, le=MAX_WALL_S), AS_FLOAT] | None,
    Field(
        description="Wall clock (Unix time, s) at which the publisher put the message; optional."
    ),
]
"""Wall clock (Unix time, s) at which the message was put, None when not stamped (not sent)."""

Priority = Annotated[
    float,
    Field(
        ge=0.0,
        le=MAX_PRIORITY,
        description="The track's priority: its weight in the planner's objective, 0 (not "
        "planned for, still kept clear of) to 10; absent: 1 (written only when it is not 1).",
    ),
    AS_FLOAT,
]
"""A track's priority (an operator's `priority` command): 0 to MAX_PRIORITY, DEFAULT_PRIORITY
when not sent."""


def _without_default_priority(fields: dict[str, Any]) -> dict[str, Any]:
    """A track's fields as written: `priority` left out at DEFAULT_PRIORITY, so that a mission
    whose operator sets none sends the bytes it always has."""
    if fields.get("priority") == DEFAULT_PRIORITY:
        del fields["priority"]
    return fields


CHOICES.update(
    mode=("{value!r} is not one of {allowed}", TELEMETRY_MODES),
    link=("{value!r} is not one of {allowed}", LINK_STATES),
)


def _at_most(where: str, value: Any, most: int) -> Any:
    """A before-check: an array (a list) holds at most `most` items (pydantic's own text would
    say "expected <most>")."""
    if isinstance(value, list) and len(value) > most:
        raise refuse(f"{where}: {len(value)} values, expected at most {most}")
    return value


class DetectionMsg(Message):
    """One UAV's detection of one slot (`isac/<mission>/detections/<m>`); a miss has null range
    and radial velocity, so the receiver knows at once that nothing more will come.

    range_m (m) and radial_velocity_mps (m/s) are NaN when missed; uav_xy_m [2] is the horizontal
    position (scenario plane, m) at which it was taken; bandwidth_share is the eta in use.
    """

    type: Literal["detection"] = carried()
    uav: UavIndex = Field(description="0-based UAV index (< n_uavs when the receiver knows M).")
    range_m: Annotated[float, nan_for_null(NonNegative | None)] = Field(
        description="Measured range (m); null when missed."
    )
    radial_velocity_mps: Annotated[float, nan_for_null(Number | None)] = Field(
        description="Measured radial velocity (m/s); null when missed."
    )
    uav_xy_m: Annotated[FloatArray, vector(PlaneXY)] = Field(
        description="Where the UAV was when it measured (m)."
    )
    bandwidth_share: Share = Field(description="The bandwidth share eta in use.")

    @field_validator("uav", mode="before")
    @classmethod
    def _uav_known(cls, uav: Any, info: ValidationInfo) -> Any:
        return check_uav("detection.uav", uav, info)

    @property
    def detected(self) -> bool:
        """True when both the range and the radial velocity are present."""
        return math.isfinite(self.range_m) and math.isfinite(self.radial_velocity_mps)

    @property
    def report(self) -> FloatArray:
        """The detection as a report of measurements [k, 2] (range m, radial velocity m/s; a
        NaN where one of the two is missing): k = 1, or 0 when both are missing."""
        row = np.array([[self.range_m, self.radial_velocity_mps]], dtype=float)
        return row if np.isfinite(row).any() else np.zeros((0, 2))


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


class DetectionSetMsg(Message):
    """One UAV's unlabelled report of one slot on a multi-target mission
    (`isac/<mission>/detections/<m>`): every echo it detected, targets and false alarms alike, in
    no particular order; an empty list when it detected nothing (still sent).

    measurements [k, 2]: (range m, radial velocity m/s) per echo (k = 0: shape (0, 2));
    uav_xy_m [2]: where it measured (scenario plane, m); bandwidth_share: the eta in use.
    """

    type: Literal["detection_set"] = carried()
    uav: UavIndex = Field(description="0-based UAV index (< n_uavs when the receiver knows M).")
    measurements: Annotated[
        FloatArray, rows(Annotated[list[Measurement], Field(max_length=MAX_MEASUREMENTS)], 2)
    ] = Field(description="[range m >= 0, radial velocity m/s] per echo; may be empty.")
    uav_xy_m: Annotated[FloatArray, vector(PlaneXY)] = Field(
        description="Where the UAV was when it measured (m)."
    )
    bandwidth_share: Share = Field(description="The bandwidth share eta in use.")

    @field_validator("uav", mode="before")
    @classmethod
    def _uav_known(cls, uav: Any, info: ValidationInfo) -> Any:
        return check_uav("detection_set.uav", uav, info)

    @field_validator("measurements", mode="before")
    @classmethod
    def _few_measurements(cls, value: Any) -> Any:
        return _at_most("detection_set.measurements", value, MAX_MEASUREMENTS)

    @property
    def report(self) -> FloatArray:
        """The report: measurements [k, 2] (range m, radial velocity m/s)."""
        return self.measurements

    @field_validator("measurements")
    @classmethod
    def _ranges_non_negative(cls, measurements: FloatArray) -> FloatArray:
        for i, (range_m, _) in enumerate(measurements):
            if range_m < 0.0:
                problem = number_problem(range_m, lo=0.0)
                raise refuse(f"detection_set.measurements[{i}][0]: {problem}")
        return measurements


class ClockMsg(Message):
    """Simulation time (`isac/<mission>/clock`): slot n means t >= mission_t0 + n slot_s.

    slot: current slot n, -1 before the mission has started; t_s: the world's simulation time
    (s); slot_s: slot length (s); speed: simulation seconds per wall second; mission_t0_s:
    simulation time (s) at which slot 0 began (None before it has).
    """

    type: Literal["clock"] = carried()
    slot: SlotOrBefore
    slot_s: Positive = Field(description="Slot length (s).")
    speed: Positive = Field(description="Simulation seconds per wall second.")
    mission_t0_s: Annotated[NonNegative | None, Field(alias="mission_t0")] = Field(
        description="Simulation time (s) at which slot 0 began; null before it has."
    )


class TruthMsg(Message):
    """The target's true state at a slot (`isac/<mission>/truth`), from the simulated world.

    target_x [4]: [x, y, vx, vy] (m, m/s) at the end of `slot`.
    """

    type: Literal["truth"] = carried()
    target_x: Annotated[FloatArray, vector(State4)] = Field(description="[x, y, vx, vy] (m, m/s).")

    @property
    def target_states(self) -> FloatArray:
        """[1, 4]: the one target's state, as a truth_set's `states`."""
        return np.asarray(self.target_x, dtype=float)[None]

    @property
    def measurement_origins(self) -> tuple[tuple[int, ...], ...]:
        """() : a labelled detection's origin is its target; not sent."""
        return ()


OriginIndex = Annotated[int, Field(ge=-1, le=MAX_TARGETS - 1)]
"""The target a measurement came from, or -1: a false alarm."""
OriginsOfUav = Annotated[list[OriginIndex], Field(max_length=MAX_MEASUREMENTS)]
"""One UAV's origins, one per measurement of its `detection_set`, in the same order."""


def _states(targets: list[list[float] | None]) -> FloatArray:
    states = np.full((len(targets), 4), np.nan)
    for i, x in enumerate(targets):
        if x is not None:
            states[i] = x
    return states


def _targets(states: Any) -> list[list[float] | None]:
    a = np.asarray(states, dtype=float)
    a = a.reshape(len(a), -1) if a.size else np.zeros((0, 4))
    return [None if np.isnan(row).all() else row.tolist() for row in a]


class TruthSetMsg(Message):
    """Every target's true state at a slot on a multi-target mission (`isac/<mission>/truth`),
    from the simulated world; evaluation only.

    states [T, 4]: [x, y, vx, vy] (m, m/s) of target t = 0..T-1 (`targets` on the wire), a NaN
    row for a target not in the scene (null); origins: per UAV the target index of each
    measurement of its `detection_set` of the slot, in the same order (-1: a false alarm); ()
    when not given.
    """

    type: Literal["truth_set"] = carried()
    states: Annotated[
        FloatArray,
        Held(Annotated[list[State4 | None], Field(max_length=MAX_TARGETS)], _states, _targets),
        Field(alias="targets"),
    ] = Field(description="[x, y, vx, vy] (m, m/s) of target t = 0..T-1; null: not in the scene.")
    origins: Annotated[
        tuple[tuple[int, ...], ...],
        Held(
            Annotated[list[OriginsOfUav], Field(max_length=MAX_UAVS)],
            lambda origins: tuple(tuple(of_uav) for of_uav in origins),
            lambda held: [[int(k) for k in of_uav] for of_uav in held],
        ),
    ] = Field(
        default_factory=tuple,
        description="Per UAV, the target index of each measurement of its detection_set of the "
        "slot, in order (-1: a false alarm); [] when not given.",
    )

    @field_validator("states", mode="before")
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

    @property
    def target_states(self) -> FloatArray:
        """[T, 4]: `states`."""
        return self.states

    @property
    def measurement_origins(self) -> tuple[tuple[int, ...], ...]:
        """`origins`."""
        return self.origins


def _assoc_fits(assoc: list[int], info: ValidationInfo) -> list[int]:
    """Each BS index lies in [-1, n_bs) (the receiver's n_bs, else 10 MAX_UAVS)."""
    n_bs = receiver_size(info, "n_bs")
    hi = (n_bs if n_bs is not None else 10 * MAX_UAVS) - 1
    if min(assoc) < -1 or max(assoc) > hi:
        i = next(i for i, k in enumerate(assoc) if not -1 <= k <= hi)
        raise refuse(f"plan.assoc[{i}]: {int_problem(assoc[i], -1, hi)}")
    return assoc


class PlanMsg(Message):
    """A slot plan (`isac/<mission>/plan`) for M UAVs: all three arrays have length M.

    assoc [M] int64: BS index per UAV, -1 outside the plan; bandwidth_share [M]: eta;
    waypoints_xy_m [M, 2] (m); objective: tr(PCRB), NaN if unknown; status, reason, solve_s
    (s): the planner's report; end_velocity_mps [M, 2] (m/s) or None: not planned. `plan` is the
    same as a `SlotPlan`, `from_plan` makes one of a `SlotPlan`. slot: the slot the plan is for.
    """

    type: Literal["plan"] = carried()
    assoc: Annotated[IntArray, int_vector(Annotated[list[int], AfterValidator(_assoc_fits)])] = (
        Field(description="BS index per UAV, or -1 for a vehicle outside the plan (share 0).")
    )
    bandwidth_share: Annotated[FloatArray, vector(list[Share])] = Field(
        description="eta per UAV; sums to 1, or every share is 0 when no UAV has a BS."
    )
    waypoints_xy_m: Annotated[FloatArray, rows(list[PlaneXY], 2)] = Field(
        description="Next waypoint per UAV (m)."
    )
    objective: Annotated[float, nan_for_null(NonNegative | None)] = Field(
        description="tr(PCRB) of the plan; null if unknown."
    )
    status: Status = Field(min_length=1, description="Solver status: ok, infeasible, ...")
    reason: str = Field(default="", max_length=MAX_REASON_CHARS, description="Why, if not ok.")
    solve_s: NonNegative = Field(description="Planner wall time (s).")
    end_velocity_mps: Annotated[FloatArray, rows(list[PlaneXY], 2)] | None = Field(
        default=None,
        description="Planned velocity per UAV at its waypoint (m/s, planner.vehicle_model); "
        "absent or null: not planned (the bridge ends the leg at its mean velocity).",
    )

    @classmethod
    def from_plan(cls, slot: int, t_s: float, plan: SlotPlan) -> PlanMsg:
        """The message of `plan` for slot `slot`, made at simulation time t_s (s)."""
        return cls(
            slot=slot,
            t_s=t_s,
            assoc=plan.bs_of_uav,
            bandwidth_share=plan.bandwidth_share,
            waypoints_xy_m=plan.uav_xy_m,
            objective=plan.pcrb_trace,
            status=plan.report.status,
            reason=plan.report.reason,
            solve_s=plan.report.solve_s,
            end_velocity_mps=plan.uav_velocity_mps,
        )

    @property
    def plan(self) -> SlotPlan:
        """The plan as the planner's `SlotPlan` (report: status, reason, solve_s)."""
        return SlotPlan(
            uav_xy_m=self.waypoints_xy_m,
            bs_of_uav=self.assoc,
            bandwidth_share=self.bandwidth_share,
            pcrb_trace=self.objective,
            report=SolveReport(status=self.status, reason=self.reason, solve_s=self.solve_s),
            uav_velocity_mps=self.end_velocity_mps,
        )

    @field_validator("assoc", mode="before")
    @classmethod
    def _assoc_size(cls, assoc: Any, info: ValidationInfo) -> Any:
        if isinstance(assoc, list):
            m, n_uavs = len(assoc), receiver_size(info, "n_uavs")
            if n_uavs is not None and m != n_uavs:
                raise refuse(f"plan.assoc: {m} values, expected {n_uavs}")
            if not 1 <= m <= MAX_UAVS:
                raise refuse(f"plan.assoc: {m} values, expected 1 to {MAX_UAVS}")
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
    def _shares_fit(cls, shares: FloatArray, info: ValidationInfo) -> FloatArray:
        assoc = info.data.get("assoc")
        if assoc is not None and min(assoc) < 0:
            for i, (k, eta) in enumerate(zip(assoc, shares, strict=True)):
                if k < 0 and eta > 0:
                    raise refuse(f"plan.assoc[{i}]: -1 (no BS) with a share > 0")
        # numpy's sum (pairwise from 8 terms on); below 8 terms it adds in order, as sum() does.
        total = float(sum(shares.tolist())) if len(shares) < 8 else float(shares.sum())
        if assoc is not None and max(assoc) < 0 and total == 0.0:
            return shares  # nobody served (every vehicle held): every share 0
        if abs(total - 1.0) > SHARE_SUM_TOL:
            raise refuse(f"plan.bandwidth_share: sums to {total:.9g}, expected 1")
        return shares


class TelemetryMsg(Message):
    """One vehicle's state as its MAVLink bridge saw it (`isac/<mission>/telemetry/<m>`).

    position_xy_m [2] (m) and velocity_xy_mps [2] (m/s) in the scenario plane (x east, y north);
    altitude_m above the scenario ground; mode: a flight-mode name (TELEMETRY_MODES); link: "ok"
    or "lost"; slot: the last slot the bridge knows of (-1 before the mission); override: why the
    service does not fly the vehicle ("operator: HOLD", "RTL: low battery", ...), "" while it does.
    """

    type: Literal["telemetry"] = carried()
    slot: SlotOrBefore
    uav: UavIndex = Field(description="0-based UAV index.")
    position_xy_m: Annotated[FloatArray, vector(PlaneXY)] = Field(
        description="Position in the scenario plane (m)."
    )
    altitude_m: Annotated[float, AS_FLOAT] = Field(
        ge=-1000.0, le=100_000.0, description="Above scenario ground (m)."
    )
    velocity_xy_mps: Annotated[
        FloatArray,
        vector(
            Annotated[
                list[Annotated[float, Field(ge=-1000.0, le=1000.0)]],
                Field(min_length=2, max_length=2),
                BeforeValidator(length_of(2)),
            ]
        ),
    ] = Field(description="Horizontal velocity [east, north] (m/s).")
    mode: TelemetryMode = Field(description="Flight mode.")
    armed: Flag
    landed: Flag
    link: LinkState = Field(description="The MAVLink link: ok or lost.")
    override: Annotated[Status, cut(MAX_STATUS_CHARS)] = Field(
        default="",
        description="Why the service does not fly the vehicle ('operator: HOLD', 'RTL: low "
        "battery', 'landed', ...); '' while it does (docs/service.md, 'Operator override').",
    )
    published_wall_s: PublishedWall = None

    @field_validator("uav", mode="before")
    @classmethod
    def _uav_known(cls, uav: Any, info: ValidationInfo) -> Any:
        return check_uav("telemetry.uav", uav, info)


class TrackMsg(Message):
    """The ground's estimate after slot `slot` (`isac/<mission>/track`).

    x [4]: EKF state [x, y, vx, vy] (m, m/s); P [4, 4]: its covariance; J [4, 4]: the PCRB
    information; pcrb_trace = tr(J^-1); priority: the track's (track 1) priority, 0 to 10
    (DEFAULT_PRIORITY when not sent; written only when it differs).
    """

    type: Literal["track"] = carried()
    x: Annotated[FloatArray, vector(State4)] = Field(
        description="EKF state [x, y, vx, vy] (m, m/s)."
    )
    P: Annotated[FloatArray, matrix(Matrix4)] = Field(description="EKF covariance.")
    J: Annotated[FloatArray, matrix(Matrix4)] = Field(description="PCRB information.")
    pcrb_trace: NonNegative = Field(description="tr(J^-1) (m^2 + m^2/s^2).")
    published_wall_s: PublishedWall = None
    priority: Priority = DEFAULT_PRIORITY

    @model_serializer(mode="wrap")
    def _written(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        return _without_default_priority(handler(self))


class TrackEntry(WireModel):
    """One track of a `track_set`.

    track_id (`id` on the wire): stable, >= 1, never reused; x [4]: state (m, m/s); P [4, 4]:
    its covariance; pcrb_position_trace: tr of the position block of its bound with origin
    uncertainty (m^2); priority: 0 to 10 (DEFAULT_PRIORITY when not sent; written only when it
    differs).
    """

    track_id: Annotated[int, Field(alias="id"), AS_INT] = Field(
        ge=1, le=MAX_TRACK_ID, description="Track id: stable, never reused."
    )
    confirmed: Flag = Field(description="Confirmed (true) or tentative (false).")
    x: Annotated[FloatArray, vector(State4)] = Field(
        description="Track state [x, y, vx, vy] (m, m/s)."
    )
    P: Annotated[FloatArray, matrix(Matrix4)] = Field(description="Its covariance.")
    pcrb_position_trace: NonNegative = Field(
        description="Trace of the position block of its bound with origin uncertainty (m^2)."
    )
    priority: Priority = DEFAULT_PRIORITY

    @model_serializer(mode="wrap")
    def _written(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        return _without_default_priority(handler(self))


class TrackSetMsg(Message):
    """The ground's tracks after slot `slot` on a multi-target mission (`isac/<mission>/track`):
    tentative and confirmed, each id at most once.

    tracks: the tracks, as a tuple.
    """

    type: Literal["track_set"] = carried()
    tracks: Annotated[
        tuple[TrackEntry, ...],
        Held(Annotated[list[TrackEntry], Field(max_length=MAX_TRACKS)], tuple, list),
    ] = Field(description="The tracks.")
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
                entries.append(TrackEntry.model_validate(entry, strict=True))
            except ValidationError as err:
                where = f"track_set.tracks[{i}]"
                raise refuse(str(message_error(err, where, TrackEntry))) from None
        return entries

    @field_validator("tracks")
    @classmethod
    def _distinct_ids(cls, tracks: tuple[TrackEntry, ...]) -> tuple[TrackEntry, ...]:
        first: dict[int, int] = {}
        for i, track in enumerate(tracks):
            j = first.setdefault(track.track_id, i)
            if j != i:
                raise refuse(f"track_set.tracks[{i}].id: {track.track_id} repeats tracks[{j}].id")
        return tracks


class HealthMsg(Message):
    """Service status (`isac/<mission>/health`): counters by name, vehicle states, last error.

    counters: name (cut to 64 characters) -> count; vehicles: vehicle index -> "active" or
    "excluded: <why>" (cut to 64 characters).
    """

    type: Literal["health"] = carried()
    slot: SlotOrBefore
    status: Status = Field(description="Status word.")
    counters: Annotated[
        dict[str, int],
        Held(
            dict[str, Annotated[int, Field(ge=0, le=MAX_SLOT)]],
            lambda counters: {k[:MAX_STATUS_CHARS]: v for k, v in counters.items()},
            lambda held: {str(k): int(v) for k, v in held.items()},
        ),
    ] = Field(description=f"Counter name -> count (at most {MAX_COUNTERS} counters).")
    last_error: Annotated[str, cut(MAX_REASON_CHARS)] = Field(
        max_length=MAX_REASON_CHARS, description="The last error, or ''."
    )
    vehicles: Annotated[
        dict[int, str],
        Held(
            dict[str, str],
            lambda states: {int(k): v[:MAX_STATUS_CHARS] for k, v in states.items()},
            lambda held: {str(m): v[:MAX_STATUS_CHARS] for m, v in held.items()},
        ),
    ] = Field(default_factory=dict, description='Vehicle index -> "active" or "excluded: <why>".')

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
    DetectionMsg
    | DetectionSetMsg
    | ClockMsg
    | TruthMsg
    | TruthSetMsg
    | PlanMsg
    | TelemetryMsg
    | TrackMsg
    | TrackSetMsg
    | HealthMsg
    | ControlMsg
    | ControlReplyMsg
    | FleetMsg,
    Field(discriminator="type"),
]
"""Any bus payload, told apart by its `type`."""

AnyMsg = (
    DetectionMsg
    | DetectionSetMsg
    | TruthSetMsg
    | TrackSetMsg
    | ClockMsg
    | TruthMsg
    | PlanMsg
    | TelemetryMsg
    | TrackMsg
    | HealthMsg
    | ControlMsg
    | ControlReplyMsg
    | FleetMsg
)
"""Any message (`wire.codec.decode_any`)."""

MODELS: Final[dict[str, type[Message]]] = {
    model.kind(): model
    for model in (
        DetectionMsg,
        DetectionSetMsg,
        ClockMsg,
        TruthMsg,
        TruthSetMsg,
        PlanMsg,
        TelemetryMsg,
        TrackMsg,
        TrackSetMsg,
        HealthMsg,
        ControlMsg,
        ControlReplyMsg,
        FleetMsg,
    )
}
"""Message type -> its model."""
