"""The domain side of each bus message: small frozen dataclasses with numpy arrays, NaN for a
missing number (`wire.codec` converts them to and from payload bytes; `wire.models` is the JSON
shape). Units are SI and names carry them; shapes are in each docstring.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from isac_mission.types import FloatArray, SlotPlan


@dataclass(frozen=True)
class DetectionMsg:
    """One UAV's detection of one slot (`isac/<mission>/detections/<m>`).

    range_m (m) and radial_velocity_mps (m/s) are NaN when missed; uav_xy_m [2] is the horizontal
    position (scenario plane, m) at which it was taken; bandwidth_share is the eta in use.
    """

    slot: int
    t_s: float
    uav: int
    range_m: float
    radial_velocity_mps: float
    uav_xy_m: FloatArray
    bandwidth_share: float

    @property
    def detected(self) -> bool:
        """True when both the range and the radial velocity are present."""
        return math.isfinite(self.range_m) and math.isfinite(self.radial_velocity_mps)


@dataclass(frozen=True)
class ClockMsg:
    """Simulation time (`isac/<mission>/clock`).

    slot: current slot n (t >= t0 + n slot_s), -1 before the mission has started; t_s: simulation
    time (s) since the world started; slot_s: slot length (s); speed: simulation seconds per wall
    second; mission_t0_s: simulation time at which slot 0 began (None before it has).
    """

    slot: int
    t_s: float
    slot_s: float
    speed: float
    mission_t0_s: float | None


@dataclass(frozen=True)
class TruthMsg:
    """The target's true state [x, y, vx, vy] (m, m/s) at a slot (`isac/<mission>/truth`)."""

    slot: int
    t_s: float
    target_x: FloatArray


@dataclass(frozen=True)
class PlanMsg:
    """A slot plan (`isac/<mission>/plan`): plan.uav_xy_m [M, 2] waypoints, plan.bs_of_uav [M],
    plan.bandwidth_share [M] (sums to 1), plan.pcrb_trace (objective, NaN if unknown),
    plan.report (status, reason, solve_s) and plan.uav_velocity_mps [M, 2] (the planned end
    velocities, m/s; None when not planned). slot: the slot the plan is for; t_s: when it was
    made."""

    slot: int
    t_s: float
    plan: SlotPlan


@dataclass(frozen=True)
class TelemetryMsg:
    """One vehicle's state as its MAVLink bridge saw it (`isac/<mission>/telemetry/<m>`).

    position_xy_m [2] and velocity_xy_mps [2] in the scenario plane (x east, y north); altitude_m
    above the scenario ground; mode is a flight-mode name (wire.models.TELEMETRY_MODES); link is "ok" or "lost".
    slot is the last slot the bridge knows of (-1 before the mission). published_wall_s: wall
    clock (Unix time, s) at which it was published, None when not stamped.
    """

    slot: int
    t_s: float
    uav: int
    position_xy_m: FloatArray
    altitude_m: float
    velocity_xy_mps: FloatArray
    mode: str
    armed: bool
    landed: bool
    link: str
    published_wall_s: float | None = None
    override: str = ""
    """Why the service does not fly the vehicle ("operator: HOLD", "RTL: low battery", ...);
    "" while it does."""


@dataclass(frozen=True)
class TrackMsg:
    """The ground's estimate after slot `slot` (`isac/<mission>/track`).

    x [4] EKF state, P [4, 4] its covariance, J [4, 4] the PCRB information, pcrb_trace = tr(J^-1).
    published_wall_s: wall clock (Unix time, s) at which it was published, None when not stamped.
    """

    slot: int
    t_s: float
    x: FloatArray
    P: FloatArray
    J: FloatArray
    pcrb_trace: float
    published_wall_s: float | None = None


@dataclass(frozen=True)
class DetectionSetMsg:
    """One UAV's unlabelled report of one slot on a multi-target mission
    (`isac/<mission>/detections/<m>`, type `detection_set`).

    measurements [k, 2]: (range m, radial velocity m/s) of every echo it detected, targets and
    false alarms alike, in no particular order (k = 0: nothing detected, still sent so that the
    receiver knows at once); uav_xy_m [2]: where it measured (scenario plane, m);
    bandwidth_share: the eta in use.
    """

    slot: int
    t_s: float
    uav: int
    measurements: FloatArray
    uav_xy_m: FloatArray
    bandwidth_share: float


@dataclass(frozen=True)
class TruthSetMsg:
    """Every target's true state at a slot on a multi-target mission (`isac/<mission>/truth`,
    type `truth_set`; evaluation only).

    states [T, 4]: [x, y, vx, vy] (m, m/s) of target t = 0..T-1, NaN rows for targets not in the
    scene; origins: per UAV the target index of each measurement of its `detection_set` of the
    slot, in the same order (-1: a false alarm); empty when not given."""

    slot: int
    t_s: float
    states: FloatArray
    origins: tuple[tuple[int, ...], ...] = ()


@dataclass(frozen=True)
class TrackEntry:
    """One track of a `track_set`: track_id (stable, >= 1, never reused), confirmed, x [4] state
    (m, m/s), P [4, 4] its covariance, pcrb_position_trace: tr of the position block of its bound
    with origin uncertainty (m^2)."""

    track_id: int
    confirmed: bool
    x: FloatArray
    P: FloatArray
    pcrb_position_trace: float


@dataclass(frozen=True)
class TrackSetMsg:
    """The ground's tracks after slot `slot` on a multi-target mission (`isac/<mission>/track`,
    type `track_set`): tentative and confirmed. published_wall_s: wall clock (Unix time, s) at
    which it was published, None when not stamped."""

    slot: int
    t_s: float
    tracks: tuple[TrackEntry, ...]
    published_wall_s: float | None = None


@dataclass(frozen=True)
class HealthMsg:
    """Service status (`isac/<mission>/health`): status word, counters by name, last error."""

    slot: int
    t_s: float
    status: str
    counters: dict[str, int]
    last_error: str
    vehicles: dict[int, str] = field(default_factory=dict)
    """Vehicle index -> "active" or "excluded: <why>" (optional on the wire)."""


@dataclass(frozen=True)
class ControlMsg:
    """An operator's request (`isac/<mission>/control`), answered on `control/reply`.

    request_id: chosen by the sender (1 to 64 characters), repeated in the reply; command: "set",
    "hold", "resume", "land" or "release" (wire.control_models); uav: the vehicle index, or None
    for every vehicle (hold, land, resume; release names one; set takes none); params (set
    only): name (wire.CONTROL_PARAMS) -> value, rate_min_mbps is R_th in Mbit/s, from the next
    planned slot on.
    """

    slot: int
    t_s: float
    request_id: str
    command: str
    uav: int | None = None
    params: dict[str, float] = field(default_factory=dict)

    @classmethod
    def set_params(cls, slot: int, t_s: float, request_id: str, **params: float) -> ControlMsg:
        """A `set` request, e.g. ControlMsg.set_params(3, 30.0, "r1", rate_min_mbps=20.0)."""
        return cls(slot, t_s, request_id, "set", None, dict(params))


@dataclass(frozen=True)
class ControlReplyMsg:
    """The ground loop's answer to one request (`isac/<mission>/control/reply`).

    request_id: the request's id (None when it could not be read); command: as sent (None when
    unreadable); accepted: executed (True) or refused, nothing executed (False); reason: why (a
    refusal names the field at fault first); effect: what the ground loop did; vehicles: the
    vehicle indices it acted on.
    """

    slot: int
    t_s: float
    request_id: str | None
    command: str | None
    accepted: bool
    reason: str
    effect: str
    vehicles: tuple[int, ...] = ()


@dataclass(frozen=True)
class FleetMsg:
    """The ground loop's command to the bridges (`isac/<mission>/fleet`) on an operator's request
    `request_id`: command "hold", "resume", "land" or "release" for the vehicles `uavs`."""

    slot: int
    t_s: float
    request_id: str
    command: str
    uavs: tuple[int, ...]


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
"""Any decoded message (`wire.codec.decode_any`)."""
