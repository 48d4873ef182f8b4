"""Bus payloads: bytes <-> small frozen dataclasses. JSON only; no sockets, no zenoh.

Every payload is a UTF-8 JSON object of at most `MAX_PAYLOAD_BYTES` bytes with

    "schema": "isac/1"      format and version (a different version is refused),
    "type":   "detection" | "clock" | "truth" | "plan" | ...,
    "slot":   int           the slot the payload belongs to (>= 0; a clock may say -1: not started),
    "t":      float         simulation time in seconds,

plus the fields of its type (SI units, names carry the unit). Unknown extra fields are ignored so
that a newer isac/1 sender can add fields. The decoders validate everything — JSON syntax, schema,
type, the presence and JSON type of each field, finiteness, magnitude (|x| <= `MAX_ABS`), array
sizes and value ranges — and raise `MessageError` whose message starts with the field at fault,
e.g. ``plan.bandwidth_share: 2 values, expected 3``. The encoders run the same checks on what they
produce, so a sender cannot publish a payload its receivers would refuse.

Slot convention of a plan (see sim/world.py): plan n carries the waypoints q_n that the vehicles
fly to during (n-1, n] and the bandwidth shares eta_n used for slot n's detections; the ground
publishes plan n+1 after it has processed the detections of slot n.

Missed detections are sent with ``null`` range and radial velocity (NaN in the dataclasses), so
the receiver knows at once that nothing more will come for that UAV and slot.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np

from isac_mission.errors import MessageError
from isac_mission.types import Detections, FloatArray, SlotPlan, SolveReport

SCHEMA: Final = "isac/1"
"""Format name and major version carried in every payload."""
MAX_PAYLOAD_BYTES: Final = 64 * 1024
"""Longest payload accepted (a plan for 256 UAVs is about 20 kB)."""
MAX_ABS: Final = 1.0e9
MAX_ABS_COVARIANCE: Final = 1.0e150
"""Covariance and information entries span many decades (the literal eq. 8 gives PCRB
information near 1e20 m^-2, a UAV close to the target 1e9 with the calibrated model): only
finiteness and a bound far beyond them are checked."""
"""Largest magnitude accepted for any number (m, m/s, s, m^2): far beyond any sane value."""
MAX_SLOT: Final = 1_000_000_000
MAX_UAVS: Final = 256
MAX_STATUS_CHARS: Final = 64
MAX_REASON_CHARS: Final = 1000
SHARE_SUM_TOL: Final = 1.0e-6
"""|sum(eta) - 1| allowed in a plan."""


# --------------------------------------------------------------------------- dataclasses


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
    plan.bandwidth_share [M] (sums to 1), plan.pcrb_trace (objective, NaN if unknown) and
    plan.report (status, reason, solve_s). slot: the slot the plan is for; t_s: when it was made."""

    slot: int
    t_s: float
    plan: SlotPlan


# --------------------------------------------------------------------------- generic helpers


def dumps(obj: Mapping[str, Any]) -> bytes:
    """Compact UTF-8 JSON; refuses NaN and infinities (MessageError)."""
    try:
        text = json.dumps(obj, separators=(",", ":"), allow_nan=False)
    except (ValueError, TypeError) as err:
        raise MessageError(f"cannot encode: {err}") from None
    data = text.encode()
    if len(data) > MAX_PAYLOAD_BYTES:
        raise MessageError(f"payload: {len(data)} bytes, more than {MAX_PAYLOAD_BYTES}")
    return data


def _reject_constant(name: str) -> Any:
    raise MessageError(f"payload: {name} is not allowed (numbers must be finite)")


def loads(payload: bytes | bytearray | memoryview | str) -> dict[str, Any]:
    """Parse a payload into a JSON object: size, UTF-8, JSON syntax, no NaN/Infinity literals."""
    if isinstance(payload, str):
        payload = payload.encode()
    data = bytes(payload)
    if len(data) > MAX_PAYLOAD_BYTES:
        raise MessageError(f"payload: {len(data)} bytes, more than {MAX_PAYLOAD_BYTES}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise MessageError("payload: not UTF-8") from None
    try:
        obj = json.loads(text, parse_constant=_reject_constant)
    except MessageError:
        raise
    except (ValueError, RecursionError) as err:
        raise MessageError(f"payload: not JSON ({err})") from None
    if not isinstance(obj, dict):
        raise MessageError(f"payload: expected a JSON object, got {type(obj).__name__}")
    return obj


_PAYLOAD_REASONS: Final = (
    ("bytes, more than", "payload too large"),
    ("not UTF-8", "payload not UTF-8"),
    ("is not allowed", "payload non-finite"),
    ("not JSON", "payload not JSON"),
    ("expected a JSON object", "payload not an object"),
)
_REASON_NAME_RE: Final = re.compile(r"[A-Za-z_][A-Za-z0-9_.\[\]]{0,63}")


def rejection_reason(err: MessageError) -> str:
    """A short, stable name for why a payload was refused, for counters: the field at fault
    ("schema", "type", "detection.range_m", ...) or, for the payload as a whole, "payload too
    large" (refused before parsing), "payload not UTF-8", "payload not JSON", "payload
    non-finite" (a NaN/Infinity token) or "payload not an object". Anything unexpected is
    "other", so that the set of names stays small whatever a sender puts in a payload."""
    name, _, detail = str(err).partition(":")
    if name == "payload":
        return next((r for needle, r in _PAYLOAD_REASONS if needle in detail), "payload")
    return name if _REASON_NAME_RE.fullmatch(name) else "other"


def envelope(kind: str, slot: int, t_s: float) -> dict[str, Any]:
    """The common fields of a payload of type `kind`."""
    return {"schema": SCHEMA, "type": kind, "slot": int(slot), "t": float(t_s)}


def open_envelope(
    payload: bytes | bytearray | memoryview | str, kind: str, *, min_slot: int = 0
) -> tuple[dict[str, Any], int, float]:
    """Parse and check the common fields; returns (object, slot, t_s).

    Raises MessageError naming the field: schema (missing, other format or version), type (not
    `kind`), slot (not an int in [min_slot, MAX_SLOT]), t (not a finite number in [0, MAX_ABS]).
    """
    obj = loads(payload)
    schema = obj.get("schema")
    if schema != SCHEMA:
        if isinstance(schema, str) and schema.startswith("isac/"):
            raise MessageError(f"schema: unsupported version {schema!r} (expected {SCHEMA!r})")
        raise MessageError(f"schema: expected {SCHEMA!r}, got {schema!r}")
    got = obj.get("type")
    if got != kind:
        raise MessageError(f"type: expected {kind!r}, got {got!r}")
    slot = get_int(obj, "slot", kind, lo=min_slot, hi=MAX_SLOT)
    t_s = get_float(obj, "t", kind, lo=0.0)
    return obj, slot, t_s


def _where(kind: str, name: str) -> str:
    return f"{kind}.{name}" if kind else name


def _require(obj: Mapping[str, Any], name: str, kind: str) -> Any:
    if name not in obj:
        raise MessageError(f"{_where(kind, name)}: missing")
    return obj[name]


def check_number(
    value: Any,
    where: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    limit: float = MAX_ABS,
) -> float:
    """A JSON number (not a bool) that is finite, |x| <= limit (MAX_ABS unless the field's
    scale needs more) and within [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise MessageError(f"{where}: expected a number, got {type(value).__name__}")
    try:
        x = float(value)
    except OverflowError:
        raise MessageError(f"{where}: {value} is too large (limit {limit:g})") from None
    if not math.isfinite(x):
        raise MessageError(f"{where}: {x} is not finite")
    if abs(x) > limit:
        raise MessageError(f"{where}: {x:g} is too large (limit {limit:g})")
    if lo is not None and x < lo:
        raise MessageError(f"{where}: {x:g} is below {lo:g}")
    if hi is not None and x > hi:
        raise MessageError(f"{where}: {x:g} is above {hi:g}")
    return x


def get_float(
    obj: Mapping[str, Any],
    name: str,
    kind: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    nullable: bool = False,
) -> float:
    """Field `name` as a float (see check_number); null gives NaN when nullable."""
    value = _require(obj, name, kind)
    if value is None and nullable:
        return math.nan
    return check_number(value, _where(kind, name), lo=lo, hi=hi)


def get_int(obj: Mapping[str, Any], name: str, kind: str, *, lo: int, hi: int) -> int:
    """Field `name` as an int in [lo, hi] (a JSON integer; bools and 1.0 are refused)."""
    return check_int(_require(obj, name, kind), _where(kind, name), lo=lo, hi=hi)


def check_int(value: Any, where: str, *, lo: int, hi: int) -> int:
    """A JSON integer (not a bool) in [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise MessageError(f"{where}: expected an integer, got {type(value).__name__}")
    if not lo <= value <= hi:
        shown = value if abs(value) < 10**12 else f"{str(value)[:8]}..."
        raise MessageError(f"{where}: {shown} is outside [{lo}, {hi}]")
    return value


def get_str(obj: Mapping[str, Any], name: str, kind: str, *, max_chars: int) -> str:
    """Field `name` as a string of at most max_chars characters."""
    value = _require(obj, name, kind)
    if not isinstance(value, str):
        raise MessageError(f"{_where(kind, name)}: expected a string, got {type(value).__name__}")
    if len(value) > max_chars:
        raise MessageError(f"{_where(kind, name)}: {len(value)} characters, limit {max_chars}")
    return value


def get_list(
    obj: Mapping[str, Any], name: str, kind: str, *, length: int | None = None
) -> list[Any]:
    """Field `name` as a JSON array, of exactly `length` items when given."""
    value = _require(obj, name, kind)
    return check_list(value, _where(kind, name), length=length)


def check_list(value: Any, where: str, *, length: int | None = None) -> list[Any]:
    """A JSON array, of exactly `length` items when given."""
    if not isinstance(value, list):
        raise MessageError(f"{where}: expected an array, got {type(value).__name__}")
    if length is not None and len(value) != length:
        raise MessageError(f"{where}: {len(value)} values, expected {length}")
    return value


def get_vector(
    obj: Mapping[str, Any],
    name: str,
    kind: str,
    *,
    length: int,
    lo: float | None = None,
    hi: float | None = None,
) -> FloatArray:
    """Field `name` as a float vector [length] of checked numbers."""
    items = get_list(obj, name, kind, length=length)
    where = _where(kind, name)
    return np.array([check_number(v, f"{where}[{i}]", lo=lo, hi=hi) for i, v in enumerate(items)])


def get_matrix(
    obj: Mapping[str, Any],
    name: str,
    kind: str,
    *,
    rows: int,
    cols: int,
    limit: float = MAX_ABS,
) -> FloatArray:
    """Field `name` as a float matrix [rows, cols] of checked numbers (|x| <= limit)."""
    items = get_list(obj, name, kind, length=rows)
    where = _where(kind, name)
    out = np.empty((rows, cols))
    for i, row in enumerate(items):
        r = check_list(row, f"{where}[{i}]", length=cols)
        for j, v in enumerate(r):
            out[i, j] = check_number(v, f"{where}[{i}][{j}]", limit=limit)
    return out


def _nullable(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _floats(values: Any, where: str) -> list[float]:
    """A flat list of finite floats for encoding; MessageError naming `where` otherwise."""
    out = [float(v) for v in np.asarray(values, dtype=float).ravel()]
    for i, v in enumerate(out):
        if not math.isfinite(v):
            raise MessageError(f"{where}[{i}]: {v} is not finite")
    return out


# --------------------------------------------------------------------------- detection


def encode_detection(msg: DetectionMsg) -> bytes:
    """Payload of `isac/<mission>/detections/<m>`; NaN range/velocity are sent as null."""
    obj = envelope("detection", msg.slot, msg.t_s)
    obj.update(
        uav=int(msg.uav),
        range_m=_nullable(msg.range_m),
        radial_velocity_mps=_nullable(msg.radial_velocity_mps),
        uav_xy_m=_floats(msg.uav_xy_m, "detection.uav_xy_m"),
        bandwidth_share=float(msg.bandwidth_share),
    )
    data = dumps(obj)
    decode_detection(data)
    return data


def decode_detection(
    payload: bytes | bytearray | memoryview | str, *, n_uavs: int | None = None
) -> DetectionMsg:
    """Validate a detection payload. n_uavs, when given, bounds the UAV index (< n_uavs)."""
    kind = "detection"
    obj, slot, t_s = open_envelope(payload, kind)
    hi = (n_uavs if n_uavs is not None else MAX_UAVS) - 1
    return DetectionMsg(
        slot=slot,
        t_s=t_s,
        uav=get_int(obj, "uav", kind, lo=0, hi=hi),
        range_m=get_float(obj, "range_m", kind, lo=0.0, nullable=True),
        radial_velocity_mps=get_float(obj, "radial_velocity_mps", kind, nullable=True),
        uav_xy_m=get_vector(obj, "uav_xy_m", kind, length=2),
        bandwidth_share=get_float(obj, "bandwidth_share", kind, lo=0.0, hi=1.0),
    )


def detection_messages(d: Detections, t_s: float, eta: FloatArray) -> list[DetectionMsg]:
    """Split one slot's `Detections` [M] into per-UAV messages (eta [M]: shares in use)."""
    return [
        DetectionMsg(
            slot=d.slot,
            t_s=t_s,
            uav=m,
            range_m=float(d.range_m[m]),
            radial_velocity_mps=float(d.radial_velocity_mps[m]),
            uav_xy_m=np.array(d.uav_xy_m[m], dtype=float),
            bandwidth_share=float(eta[m]),
        )
        for m in range(len(d.range_m))
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


# --------------------------------------------------------------------------- clock


def encode_clock(msg: ClockMsg) -> bytes:
    """Payload of `isac/<mission>/clock`."""
    obj = envelope("clock", msg.slot, msg.t_s)
    obj.update(
        slot_s=float(msg.slot_s),
        speed=float(msg.speed),
        mission_t0=None if msg.mission_t0_s is None else float(msg.mission_t0_s),
    )
    data = dumps(obj)
    decode_clock(data)
    return data


def decode_clock(payload: bytes | bytearray | memoryview | str) -> ClockMsg:
    """Validate a clock payload (slot may be -1: the mission has not started)."""
    kind = "clock"
    obj, slot, t_s = open_envelope(payload, kind, min_slot=-1)
    t0 = get_float(obj, "mission_t0", kind, lo=0.0, nullable=True)
    return ClockMsg(
        slot=slot,
        t_s=t_s,
        slot_s=get_float(obj, "slot_s", kind, lo=1e-6),
        speed=get_float(obj, "speed", kind, lo=1e-6),
        mission_t0_s=None if math.isnan(t0) else t0,
    )


# --------------------------------------------------------------------------- truth


def encode_truth(msg: TruthMsg) -> bytes:
    """Payload of `isac/<mission>/truth`."""
    obj = envelope("truth", msg.slot, msg.t_s)
    obj["target_x"] = _floats(msg.target_x, "truth.target_x")
    data = dumps(obj)
    decode_truth(data)
    return data


def decode_truth(payload: bytes | bytearray | memoryview | str) -> TruthMsg:
    """Validate a truth payload: target_x is [x, y, vx, vy]."""
    kind = "truth"
    obj, slot, t_s = open_envelope(payload, kind)
    return TruthMsg(slot=slot, t_s=t_s, target_x=get_vector(obj, "target_x", kind, length=4))


# --------------------------------------------------------------------------- plan


def encode_plan(msg: PlanMsg) -> bytes:
    """Payload of `isac/<mission>/plan` (objective NaN is sent as null)."""
    p = msg.plan
    obj = envelope("plan", msg.slot, msg.t_s)
    obj.update(
        assoc=[int(k) for k in np.asarray(p.bs_of_uav).ravel()],
        bandwidth_share=_floats(p.bandwidth_share, "plan.bandwidth_share"),
        waypoints_xy_m=[
            _floats(row, f"plan.waypoints_xy_m[{i}]")
            for i, row in enumerate(np.asarray(p.uav_xy_m))
        ],
        objective=_nullable(p.pcrb_trace),
        status=p.report.status,
        reason=p.report.reason,
        solve_s=float(p.report.solve_s),
    )
    data = dumps(obj)
    decode_plan(data)
    return data


def decode_plan(
    payload: bytes | bytearray | memoryview | str,
    *,
    n_uavs: int | None = None,
    n_bs: int | None = None,
) -> PlanMsg:
    """Validate a plan payload.

    Checks: assoc, bandwidth_share and waypoints_xy_m have the same length M (= n_uavs when
    given, 1 <= M <= MAX_UAVS); assoc entries are BS indices in [0, n_bs), or -1 for a vehicle
    outside the plan (link lost; its share must then be 0); shares lie in [0, 1]
    and sum to 1 within SHARE_SUM_TOL; waypoints are finite [M, 2]; objective is >= 0 or null;
    status is a non-empty string; solve_s >= 0. reason is optional ("" when absent).
    """
    kind = "plan"
    obj, slot, t_s = open_envelope(payload, kind)
    assoc_raw = get_list(obj, "assoc", kind)
    m = len(assoc_raw)
    if n_uavs is not None and m != n_uavs:
        raise MessageError(f"plan.assoc: {m} values, expected {n_uavs}")
    if not 1 <= m <= MAX_UAVS:
        raise MessageError(f"plan.assoc: {m} values, expected 1 to {MAX_UAVS}")
    hi_bs = (n_bs if n_bs is not None else 10 * MAX_UAVS) - 1
    assoc = np.array(
        [check_int(v, f"plan.assoc[{i}]", lo=-1, hi=hi_bs) for i, v in enumerate(assoc_raw)],
        dtype=np.int64,
    )
    shares = get_vector(obj, "bandwidth_share", kind, length=m, lo=0.0, hi=1.0)
    unserved = np.flatnonzero((assoc < 0) & (shares > 0))
    if len(unserved):
        raise MessageError(f"plan.assoc[{unserved[0]}]: -1 (no BS) with a share > 0")
    total = float(shares.sum())
    if abs(total - 1.0) > SHARE_SUM_TOL:
        raise MessageError(f"plan.bandwidth_share: sums to {total:.9g}, expected 1")
    waypoints = get_matrix(obj, "waypoints_xy_m", kind, rows=m, cols=2)
    objective = get_float(obj, "objective", kind, lo=0.0, nullable=True)
    status = get_str(obj, "status", kind, max_chars=MAX_STATUS_CHARS)
    if not status:
        raise MessageError("plan.status: empty")
    reason = get_str(obj, "reason", kind, max_chars=MAX_REASON_CHARS) if "reason" in obj else ""
    solve_s = get_float(obj, "solve_s", kind, lo=0.0)
    plan = SlotPlan(
        uav_xy_m=waypoints,
        bs_of_uav=assoc,
        bandwidth_share=shares,
        pcrb_trace=objective,
        report=SolveReport(status=status, reason=reason, solve_s=solve_s),
    )
    return PlanMsg(slot=slot, t_s=t_s, plan=plan)


# --------------------------------------------------------------------------- dispatch


# --------------------------------------------------------------------------- telemetry


TELEMETRY_MODES: Final = frozenset(
    {"unknown", "manual", "takeoff", "hold", "offboard", "land", "mission", "rtl", "other"}
)
LINK_STATES: Final = frozenset({"ok", "lost"})


@dataclass(frozen=True)
class TelemetryMsg:
    """One vehicle's state as its MAVLink bridge saw it (`isac/<mission>/telemetry/<m>`).

    position_xy_m [2] and velocity_xy_mps [2] in the scenario plane (x east, y north); altitude_m
    above the scenario ground; mode is a flight-mode name (TELEMETRY_MODES); link is "ok" or "lost".
    slot is the last slot the bridge knows of (-1 before the mission).
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


def _get_bool(obj: Mapping[str, Any], name: str, kind: str) -> bool:
    value = _require(obj, name, kind)
    if not isinstance(value, bool):
        raise MessageError(
            f"{_where(kind, name)}: expected true or false, got {type(value).__name__}"
        )
    return value


def _get_choice(obj: Mapping[str, Any], name: str, kind: str, choices: frozenset[str]) -> str:
    value = get_str(obj, name, kind, max_chars=MAX_STATUS_CHARS)
    if value not in choices:
        raise MessageError(f"{_where(kind, name)}: {value!r} is not one of {sorted(choices)}")
    return value


def encode_telemetry(msg: TelemetryMsg) -> bytes:
    """Payload of `isac/<mission>/telemetry/<m>`."""
    obj = envelope("telemetry", msg.slot, msg.t_s)
    obj.update(
        uav=int(msg.uav),
        position_xy_m=_floats(msg.position_xy_m, "telemetry.position_xy_m"),
        altitude_m=float(msg.altitude_m),
        velocity_xy_mps=_floats(msg.velocity_xy_mps, "telemetry.velocity_xy_mps"),
        mode=msg.mode,
        armed=bool(msg.armed),
        landed=bool(msg.landed),
        link=msg.link,
    )
    data = dumps(obj)
    decode_telemetry(data)
    return data


def decode_telemetry(
    payload: bytes | bytearray | memoryview | str, *, n_uavs: int | None = None
) -> TelemetryMsg:
    """Validate a telemetry payload (uav in [0, n_uavs) when n_uavs is given)."""
    kind = "telemetry"
    obj, slot, t_s = open_envelope(payload, kind, min_slot=-1)
    hi = MAX_UAVS - 1 if n_uavs is None else n_uavs - 1
    return TelemetryMsg(
        slot=slot,
        t_s=t_s,
        uav=get_int(obj, "uav", kind, lo=0, hi=hi),
        position_xy_m=get_vector(obj, "position_xy_m", kind, length=2),
        altitude_m=get_float(obj, "altitude_m", kind, lo=-1000.0, hi=100_000.0),
        velocity_xy_mps=get_vector(obj, "velocity_xy_mps", kind, length=2, lo=-1000.0, hi=1000.0),
        mode=_get_choice(obj, "mode", kind, TELEMETRY_MODES),
        armed=_get_bool(obj, "armed", kind),
        landed=_get_bool(obj, "landed", kind),
        link=_get_choice(obj, "link", kind, LINK_STATES),
    )


# --------------------------------------------------------------------------- track


@dataclass(frozen=True)
class TrackMsg:
    """The ground's estimate after slot `slot` (`isac/<mission>/track`).

    x [4] EKF state, P [4, 4] its covariance, J [4, 4] the PCRB information, pcrb_trace = tr(J^-1).
    """

    slot: int
    t_s: float
    x: FloatArray
    P: FloatArray
    J: FloatArray
    pcrb_trace: float


def encode_track(msg: TrackMsg) -> bytes:
    """Payload of `isac/<mission>/track`."""
    obj = envelope("track", msg.slot, msg.t_s)
    obj.update(
        x=_floats(msg.x, "track.x"),
        P=[_floats(r, f"track.P[{i}]") for i, r in enumerate(np.asarray(msg.P))],
        J=[_floats(r, f"track.J[{i}]") for i, r in enumerate(np.asarray(msg.J))],
        pcrb_trace=float(msg.pcrb_trace),
    )
    data = dumps(obj)
    decode_track(data)
    return data


def decode_track(payload: bytes | bytearray | memoryview | str) -> TrackMsg:
    """Validate a track payload."""
    kind = "track"
    obj, slot, t_s = open_envelope(payload, kind)
    return TrackMsg(
        slot=slot,
        t_s=t_s,
        x=get_vector(obj, "x", kind, length=4),
        P=get_matrix(obj, "P", kind, rows=4, cols=4, limit=MAX_ABS_COVARIANCE),
        J=get_matrix(obj, "J", kind, rows=4, cols=4, limit=MAX_ABS_COVARIANCE),
        pcrb_trace=get_float(obj, "pcrb_trace", kind, lo=0.0),
    )


# --------------------------------------------------------------------------- health


MAX_COUNTERS: Final = 200


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


def encode_health(msg: HealthMsg) -> bytes:
    """Payload of `isac/<mission>/health`."""
    obj = envelope("health", msg.slot, msg.t_s)
    obj.update(
        status=msg.status,
        counters={str(k): int(v) for k, v in msg.counters.items()},
        last_error=msg.last_error[:MAX_REASON_CHARS],
        vehicles={str(m): state[:MAX_STATUS_CHARS] for m, state in msg.vehicles.items()},
    )
    data = dumps(obj)
    decode_health(data)
    return data


def decode_health(payload: bytes | bytearray | memoryview | str) -> HealthMsg:
    """Validate a health payload."""
    kind = "health"
    obj, slot, t_s = open_envelope(payload, kind, min_slot=-1)
    raw = _require(obj, "counters", kind)
    if not isinstance(raw, dict) or len(raw) > MAX_COUNTERS:
        raise MessageError(
            f"{_where(kind, 'counters')}: expected an object of at most {MAX_COUNTERS} counters"
        )
    counters = {
        str(k)[:MAX_STATUS_CHARS]: check_int(
            v, f"{_where(kind, 'counters')}.{k}", lo=0, hi=MAX_SLOT
        )
        for k, v in raw.items()
    }
    vehicles: dict[int, str] = {}
    raw_vehicles = obj.get("vehicles", {})
    if not isinstance(raw_vehicles, dict) or len(raw_vehicles) > MAX_UAVS:
        raise MessageError(f"{_where(kind, 'vehicles')}: expected an object of vehicle states")
    for k, v in raw_vehicles.items():
        if not str(k).isdigit() or not isinstance(v, str):
            raise MessageError(f"{_where(kind, 'vehicles')}.{k}: expected index -> state string")
        vehicles[int(k)] = v[:MAX_STATUS_CHARS]
    return HealthMsg(
        slot=slot,
        t_s=t_s,
        status=get_str(obj, "status", kind, max_chars=MAX_STATUS_CHARS),
        counters=counters,
        last_error=get_str(obj, "last_error", kind, max_chars=MAX_REASON_CHARS),
        vehicles=vehicles,
    )


# --------------------------------------------------------------------------- control


CONTROL_PARAMS: Final = {"rate_min_mbps": (1e-3, 1e5)}
"""Operator-settable planning parameters and their accepted ranges (`isac/<mission>/control`)."""


@dataclass(frozen=True)
class ControlMsg:
    """An operator's command (`isac/<mission>/control`): set planning parameters from the next
    planned slot on. params: name (CONTROL_PARAMS) -> value; rate_min_mbps is R_th in Mbit/s."""

    slot: int
    t_s: float
    params: dict[str, float]


def encode_control(msg: ControlMsg) -> bytes:
    """Payload of `isac/<mission>/control`."""
    obj = envelope("control", msg.slot, msg.t_s)
    obj.update(command="set", params={k: float(v) for k, v in msg.params.items()})
    data = dumps(obj)
    decode_control(data)
    return data


def decode_control(payload: bytes | bytearray | memoryview | str) -> ControlMsg:
    """Validate a control payload: command "set" and known parameters within their ranges."""
    kind = "control"
    obj, slot, t_s = open_envelope(payload, kind, min_slot=-1)
    command = get_str(obj, "command", kind, max_chars=MAX_STATUS_CHARS)
    if command != "set":
        raise MessageError(f"control.command: {command!r} is not a command (expected 'set')")
    raw = _require(obj, "params", kind)
    if not isinstance(raw, dict) or not raw:
        raise MessageError("control.params: expected a non-empty object")
    params: dict[str, float] = {}
    for name, value in raw.items():
        if name not in CONTROL_PARAMS:
            known = ", ".join(sorted(CONTROL_PARAMS))
            raise MessageError(f"control.params.{name}: unknown parameter (known: {known})")
        lo, hi = CONTROL_PARAMS[name]
        params[name] = check_number(value, f"control.params.{name}", lo=lo, hi=hi)
    return ControlMsg(slot=slot, t_s=t_s, params=params)


AnyMsg = DetectionMsg | ClockMsg | TruthMsg | PlanMsg | TelemetryMsg | TrackMsg | HealthMsg


def decode_any(payload: bytes | bytearray | memoryview | str) -> AnyMsg:
    """Decode a payload of any type this module knows, by its "type" field."""
    obj = loads(payload)
    kind = obj.get("type")
    decoders: dict[str, Any] = {
        "detection": decode_detection,
        "clock": decode_clock,
        "truth": decode_truth,
        "plan": decode_plan,
        "telemetry": decode_telemetry,
        "track": decode_track,
        "health": decode_health,
    }
    if not isinstance(kind, str) or kind not in decoders:
        raise MessageError(f"type: unknown payload type {kind!r}")
    result: AnyMsg = decoders[kind](payload)
    return result
