"""Trace records in memory: one slot's `SlotRecord` and a whole `Trace` (format: docs/trace.md).

Shapes: M UAVs; uav_xy_m (trace: uav_xy), plan_xy, plan_start_xy [M, 2] m; plan_velocity,
plan_start_velocity [M, 2] m/s; bandwidth_share (trace: eta) [M]; assoc [M] 0-based BS index (-1 = none);
target_* [4] = [x, y, vx, vy] in m and m/s; r_diag [2M] = range variances (m^2) then
radial-velocity variances (m^2/s^2), NaN for a measurement that did not arrive; P, J [4, 4].
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Final, Protocol

from isac_mission.deprecation import renamed_fields
from isac_mission.errors import MessageError
from isac_mission.records.fields import as_float, as_int, as_str, float_array, int_array
from isac_mission.records.jsonlines import to_jsonable
from isac_mission.types import FloatArray, IntArray

CONTRACT_KEYS: Final[tuple[str, ...]] = (
    "slot",
    "method",
    "status",
    "uav_xy",
    "eta",
    "assoc",
    "target_true",
    "target_est",
    "target_pred",
    "r_diag",
    "pcrb_trace",
    "solve_ms",
    "P",
    "J",
)
"""The fields every slot line carries (docs/trace.md), in the order they are written."""

OPTIONAL_KEYS: Final[tuple[str, ...]] = (
    "plan_xy",
    "plan_pcrb_trace",
    "reason",
    "plan_velocity",
    "fallback",
    "plan_start_xy",
    "plan_start_velocity",
)
"""Named optional fields; written only when set."""

_PER_UAV_XY: Final[frozenset[str]] = frozenset(
    ("plan_xy", "plan_velocity", "plan_start_xy", "plan_start_velocity")
)
"""The optional [M, 2] fields (`Trace.stack` fills a slot without one with NaN)."""

_ATTRIBUTE: Final[dict[str, str]] = {"uav_xy": "uav_xy_m", "eta": "bandwidth_share"}
"""SlotRecord's attribute for a trace field whose name differs."""

_RESERVED: Final[frozenset[str]] = frozenset((*CONTRACT_KEYS, *OPTIONAL_KEYS, "config"))


@renamed_fields(uav_xy="uav_xy_m", eta="bandwidth_share")
@dataclass(frozen=True, eq=False)
class SlotRecord:
    """One slot of a run, as logged (docs/trace.md). Arrays are read-only numpy copies.

    slot: slot index n; method: planning method; status: "ok", "infeasible", ...;
    uav_xy_m [M, 2]: where this slot's measurements were taken; bandwidth_share [M]: the shares;
    assoc [M]: 0-based BS index per UAV (-1 = none); target_true [4] or None (unknown);
    target_est [4]: EKF posterior mean; target_pred [4]: EKF prediction (the bound's
    linearisation point); r_diag [2M]: measurement variances used for the bound (m^2 then
    m^2/s^2; NaN = measurement did not arrive); pcrb_trace: tr(J^-1) (m^2 + m^2/s^2);
    solve_ms: planner wall time (ms); P [4, 4]: EKF covariance; J [4, 4]: PCRB information.
    Optional: plan_xy [M, 2] planned waypoints; plan_pcrb_trace: the planner's objective;
    reason: why status is not "ok"; plan_velocity [M, 2] m/s: the planned velocity at each
    waypoint (planner.vehicle_model); fallback: why the method's own answer was not flown (a
    short kind, docs/trace.md); plan_start_xy [M, 2] m, plan_start_velocity [M, 2] m/s: the
    state the planner planned from (its SlotInput's prev_xy and prev_velocity; the replay's
    input, experiment/replay.py); extra: further JSON-ready fields, written at the top level.

    Construction checks shapes and types and raises MessageError naming the field. Two records
    are equal when their JSON forms are (so NaN equals NaN). The trace's names of uav_xy_m and
    bandwidth_share are "uav_xy" and "eta" (docs/trace.md); the attributes of those names are
    deprecated aliases.
    """

    slot: int
    method: str
    status: str
    uav_xy_m: FloatArray
    bandwidth_share: FloatArray
    assoc: IntArray
    target_true: FloatArray | None
    target_est: FloatArray
    target_pred: FloatArray
    r_diag: FloatArray
    pcrb_trace: float
    solve_ms: float
    P: FloatArray
    J: FloatArray
    plan_xy: FloatArray | None = None
    plan_pcrb_trace: float | None = None
    reason: str | None = None
    plan_velocity: FloatArray | None = None
    fallback: str | None = None
    plan_start_xy: FloatArray | None = None
    plan_start_velocity: FloatArray | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "slot", as_int(self.slot, "slot"))
        put(self, "method", as_str(self.method, "method"))
        put(self, "status", as_str(self.status, "status"))
        uav_xy = float_array(self.uav_xy_m, "uav_xy", (None, 2))
        m = uav_xy.shape[0]
        put(self, "uav_xy_m", uav_xy)
        put(self, "bandwidth_share", float_array(self.bandwidth_share, "eta", (m,)))
        assoc = int_array(self.assoc, "assoc")
        if assoc.shape != (m,):
            raise MessageError(f"assoc: expected {m} BS indices (one per UAV), got {assoc.size}")
        put(self, "assoc", assoc)
        if self.target_true is not None:
            put(self, "target_true", float_array(self.target_true, "target_true", (4,)))
        put(self, "target_est", float_array(self.target_est, "target_est", (4,)))
        put(self, "target_pred", float_array(self.target_pred, "target_pred", (4,)))
        put(self, "r_diag", float_array(self.r_diag, "r_diag", (2 * m,)))
        put(self, "pcrb_trace", as_float(self.pcrb_trace, "pcrb_trace"))
        put(self, "solve_ms", as_float(self.solve_ms, "solve_ms"))
        put(self, "P", float_array(self.P, "P", (4, 4)))
        put(self, "J", float_array(self.J, "J", (4, 4)))
        if self.plan_xy is not None:
            put(self, "plan_xy", float_array(self.plan_xy, "plan_xy", (m, 2)))
        if self.plan_pcrb_trace is not None:
            put(self, "plan_pcrb_trace", as_float(self.plan_pcrb_trace, "plan_pcrb_trace"))
        if self.reason is not None:
            put(self, "reason", as_str(self.reason, "reason"))
        if self.plan_velocity is not None:
            put(self, "plan_velocity", float_array(self.plan_velocity, "plan_velocity", (m, 2)))
        if self.fallback is not None:
            put(self, "fallback", as_str(self.fallback, "fallback"))
        for key in ("plan_start_xy", "plan_start_velocity"):
            if getattr(self, key) is not None:
                put(self, key, float_array(getattr(self, key), key, (m, 2)))
        if not isinstance(self.extra, Mapping):
            raise MessageError(f"extra: expected a mapping (got {self.extra!r})")
        clash = sorted(_RESERVED.intersection(self.extra))
        if clash:
            raise MessageError(f"extra: keys {clash} are reserved for the trace's named fields")
        put(self, "extra", to_jsonable(dict(self.extra), "extra"))

    @property
    def n_uavs(self) -> int:
        """M, the number of UAVs."""
        return int(self.uav_xy_m.shape[0])

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready line: contract fields in docs/trace.md order, set optionals, then extras."""
        out: dict[str, Any] = {
            key: to_jsonable(getattr(self, _ATTRIBUTE.get(key, key)), key) for key in CONTRACT_KEYS
        }
        for key in OPTIONAL_KEYS:
            value = getattr(self, key)
            if value is not None:
                out[key] = to_jsonable(value, key)
        out.update(self.extra)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SlotRecord:
        """Parse one slot line's object; unknown keys go to `extra`. Raises MessageError."""
        if not isinstance(data, Mapping):
            raise MessageError(f"a slot line must be a JSON object (got {type(data).__name__})")
        missing = [key for key in CONTRACT_KEYS if key not in data]
        if missing:
            raise MessageError(f"missing fields {missing}")
        if "config" in data:
            raise MessageError("a second config object after line 1")
        named = {_ATTRIBUTE.get(key, key): data[key] for key in CONTRACT_KEYS}
        optional = {key: data[key] for key in OPTIONAL_KEYS if data.get(key) is not None}
        extra = {key: value for key, value in data.items() if key not in _RESERVED}
        return cls(**named, **optional, extra=extra)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, SlotRecord):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]


class SlotLine(Protocol):
    """What the order of slot lines is checked on."""

    @property
    def slot(self) -> int: ...

    @property
    def n_uavs(self) -> int: ...


END_STATUSES: Final = ("complete", "interrupted")
"""How a live run of the ground loop ended: it traced slot N, or it was asked to stop before."""


@dataclass(frozen=True)
class MissionEnd:
    """How one live run of a trace ended: its `{"end": {...}}` line (docs/trace.md, "End").

    status: "complete" (slot N traced) or "interrupted" (stopped before: Ctrl-C, SIGTERM);
    last_slot: the last slot traced when it ended (0: none); n_slots: the mission's N.
    """

    status: str
    last_slot: int
    n_slots: int

    def to_dict(self) -> dict[str, Any]:
        """The line's JSON object."""
        return {"end": {"status": self.status, "last_slot": self.last_slot, "N": self.n_slots}}

    @classmethod
    def from_dict(cls, obj: Mapping[str, Any]) -> MissionEnd:
        """From a parsed `{"end": {...}}` line; MessageError naming the field at fault."""
        end = obj.get("end")
        if set(obj) != {"end"} or not isinstance(end, dict):
            raise MessageError('an end line must be {"end": {...}} alone')
        status = as_str(end.get("status"), "end.status")
        if status not in END_STATUSES:
            raise MessageError(f"end.status: {status!r} is not one of {', '.join(END_STATUSES)}")
        return cls(
            status, as_int(end.get("last_slot"), "end.last_slot"), as_int(end.get("N"), "end.N")
        )


def check_sequence(rec: SlotLine, prev: SlotLine | None, m_config: Any) -> None:
    """Raise MessageError unless rec follows prev (append-only) with config["M"] UAVs."""
    if isinstance(m_config, int) and not isinstance(m_config, bool) and rec.n_uavs != m_config:
        raise MessageError(f"slot {rec.slot} has {rec.n_uavs} UAVs but config M is {m_config}")
    if prev is not None and rec.slot <= prev.slot:
        raise MessageError(f"slot {rec.slot} does not follow slot {prev.slot} (append-only)")
