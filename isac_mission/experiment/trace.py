"""The run trace: JSON Lines, one file per run and method (format in DESIGN.md, "Trace").

Line 1 is `{"config": {...}}` with every resolved parameter (SI units); every further line is one
slot's `SlotRecord`. The writer appends one complete line per slot and flushes it at once (and
`os.fsync`s it on request), so a killed run leaves every completed slot on disk; the reader drops
an incomplete final line (the one a killed writer was in the middle of) and refuses anything else
that does not parse, naming the line. `TraceWriter.resume` reopens a trace to continue it.

In memory, arrays are numpy float64 (`assoc` int64) and a missing number is NaN; on disk every
non-finite number is written as JSON `null` (the file is strict JSON: no NaN or Infinity tokens),
and `null` reads back as NaN. Shapes: M UAVs; uav_xy, plan_xy [M, 2] m; eta [M]; assoc [M] 0-based
BS index (-1 = none; `null` on disk reads as -1); target_* [4] = [x, y, vx, vy] in m and m/s;
r_diag [2M] = range variances (m^2) then radial-velocity variances (m^2/s^2), NaN for a measurement
that did not arrive; P, J [4, 4].
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Final

import numpy as np

from isac_mission.errors import MessageError
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
"""The fields every slot line carries (DESIGN.md), in the order they are written."""

OPTIONAL_KEYS: Final[tuple[str, ...]] = ("plan_xy", "plan_pcrb_trace", "reason")
"""Named optional fields; written only when set."""

_RESERVED: Final[frozenset[str]] = frozenset((*CONTRACT_KEYS, *OPTIONAL_KEYS, "config"))


# --------------------------------------------------------------------------------------------
# JSON conversion


def to_jsonable(value: Any, where: str = "value") -> Any:
    """A JSON-ready copy of value: numpy arrays and scalars to lists and Python numbers, tuples
    to lists, non-finite floats to None. Raises MessageError naming `where` for anything else."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        f = float(value)
        return f if math.isfinite(f) else None
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist(), where)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, Mapping):
        out: dict[str, Any] = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise MessageError(f"{where}: keys must be strings (got {k!r})")
            out[k] = to_jsonable(v, f"{where}.{k}")
        return out
    if isinstance(value, list | tuple):
        return [to_jsonable(v, f"{where}[{i}]") for i, v in enumerate(value)]
    raise MessageError(f"{where}: cannot write {type(value).__name__} to JSON (got {value!r})")


def _dumps(obj: Any) -> str:
    return json.dumps(obj, allow_nan=False, separators=(",", ":"), ensure_ascii=False)


def _reject_constant(token: str) -> Any:
    raise MessageError(f"non-standard JSON constant {token} (non-finite numbers are written null)")


def _loads(text: str) -> Any:
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as err:
        raise MessageError(f"not valid JSON: {err.msg} at column {err.colno}") from None


# --------------------------------------------------------------------------------------------
# Field coercion (raises MessageError naming the field)


def _leaves_are_numbers(value: Any) -> bool:
    if isinstance(value, list | tuple):
        return all(_leaves_are_numbers(v) for v in value)
    return value is None or (
        isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
    )


def _float_array(value: Any, name: str, shape: tuple[int | None, ...]) -> FloatArray:
    """value as a float64 array of the given shape (None = any length); None/null become NaN."""
    if isinstance(value, np.ndarray):
        if not (np.issubdtype(value.dtype, np.number) and not np.issubdtype(value.dtype, np.bool_)):
            raise MessageError(f"{name}: expected numbers, got an array of {value.dtype}")
        arr = np.array(value, dtype=np.float64)
    else:
        if not _leaves_are_numbers(value):
            raise MessageError(f"{name}: expected numbers or null (got {value!r})")
        try:
            arr = np.array(value, dtype=np.float64)
        except ValueError:
            raise MessageError(f"{name}: ragged nested lists (got {value!r})") from None
    if arr.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(arr.shape, shape, strict=True)
    ):
        want_txt = "[" + ", ".join("M" if w is None else str(w) for w in shape) + "]"
        raise MessageError(f"{name}: expected shape {want_txt}, got {list(arr.shape)}")
    arr.setflags(write=False)
    return arr


def _is_integral(v: Any) -> bool:
    """True for an int (not bool) or an integral finite float."""
    if isinstance(v, bool | np.bool_):
        return False
    if isinstance(v, int | np.integer):
        return True
    return isinstance(v, float | np.floating) and math.isfinite(v) and float(v).is_integer()


def _int_array(value: Any, name: str) -> IntArray:
    """value as an int64 vector; None/null become -1 (no BS); non-integral numbers are refused."""
    raw = value.tolist() if isinstance(value, np.ndarray) else value
    if not isinstance(raw, list | tuple):
        raise MessageError(f"{name}: expected a list of BS indices (got {value!r})")
    out: list[int] = []
    for i, v in enumerate(raw):
        if v is None:
            out.append(-1)
        elif _is_integral(v):
            out.append(int(v))
        else:
            raise MessageError(f"{name}[{i}]: expected an integer BS index (got {v!r})")
    arr = np.array(out, dtype=np.int64).reshape(len(out))
    arr.setflags(write=False)
    return arr


def _float(value: Any, name: str) -> float:
    """A float from a number or None (NaN)."""
    if value is None:
        return math.nan
    if isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool):
        return float(value)
    raise MessageError(f"{name}: expected a number or null (got {value!r})")


def _int(value: Any, name: str) -> int:
    if isinstance(value, int | np.integer) and not isinstance(value, bool):
        return int(value)
    raise MessageError(f"{name}: expected an integer (got {value!r})")


def _str(value: Any, name: str) -> str:
    if isinstance(value, str):
        return value
    raise MessageError(f"{name}: expected a string (got {value!r})")


# --------------------------------------------------------------------------------------------
# Records


@dataclass(frozen=True, eq=False)
class SlotRecord:
    """One slot of a run, as logged (DESIGN.md, "Trace"). Arrays are read-only numpy copies.

    slot: slot index n; method: planning method; status: "ok", "infeasible", ...;
    uav_xy [M, 2] m: where this slot's measurements were taken; eta [M]: bandwidth shares;
    assoc [M]: 0-based BS index per UAV (-1 = none); target_true [4] or None (unknown);
    target_est [4]: EKF posterior mean; target_pred [4]: EKF prediction (the bound's
    linearisation point); r_diag [2M]: measurement variances used for the bound (m^2 then
    m^2/s^2; NaN = measurement did not arrive); pcrb_trace: tr(J^-1) (m^2 + m^2/s^2);
    solve_ms: planner wall time (ms); P [4, 4]: EKF covariance; J [4, 4]: PCRB information.
    Optional: plan_xy [M, 2] planned waypoints; plan_pcrb_trace: the planner's objective;
    reason: why status is not "ok"; extra: further JSON-ready fields, written at the top level.

    Construction checks shapes and types and raises MessageError naming the field. Two records
    are equal when their JSON forms are (so NaN equals NaN).
    """

    slot: int
    method: str
    status: str
    uav_xy: FloatArray
    eta: FloatArray
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
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "slot", _int(self.slot, "slot"))
        put(self, "method", _str(self.method, "method"))
        put(self, "status", _str(self.status, "status"))
        uav_xy = _float_array(self.uav_xy, "uav_xy", (None, 2))
        m = uav_xy.shape[0]
        put(self, "uav_xy", uav_xy)
        put(self, "eta", _float_array(self.eta, "eta", (m,)))
        assoc = _int_array(self.assoc, "assoc")
        if assoc.shape != (m,):
            raise MessageError(f"assoc: expected {m} BS indices (one per UAV), got {assoc.size}")
        put(self, "assoc", assoc)
        if self.target_true is not None:
            put(self, "target_true", _float_array(self.target_true, "target_true", (4,)))
        put(self, "target_est", _float_array(self.target_est, "target_est", (4,)))
        put(self, "target_pred", _float_array(self.target_pred, "target_pred", (4,)))
        put(self, "r_diag", _float_array(self.r_diag, "r_diag", (2 * m,)))
        put(self, "pcrb_trace", _float(self.pcrb_trace, "pcrb_trace"))
        put(self, "solve_ms", _float(self.solve_ms, "solve_ms"))
        put(self, "P", _float_array(self.P, "P", (4, 4)))
        put(self, "J", _float_array(self.J, "J", (4, 4)))
        if self.plan_xy is not None:
            put(self, "plan_xy", _float_array(self.plan_xy, "plan_xy", (m, 2)))
        if self.plan_pcrb_trace is not None:
            put(self, "plan_pcrb_trace", _float(self.plan_pcrb_trace, "plan_pcrb_trace"))
        if self.reason is not None:
            put(self, "reason", _str(self.reason, "reason"))
        if not isinstance(self.extra, Mapping):
            raise MessageError(f"extra: expected a mapping (got {self.extra!r})")
        clash = sorted(_RESERVED.intersection(self.extra))
        if clash:
            raise MessageError(f"extra: keys {clash} are reserved for the trace's named fields")
        put(self, "extra", to_jsonable(dict(self.extra), "extra"))

    @property
    def n_uavs(self) -> int:
        """M, the number of UAVs."""
        return int(self.uav_xy.shape[0])

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready line: contract fields in DESIGN.md order, set optionals, then extras."""
        out: dict[str, Any] = {key: to_jsonable(getattr(self, key), key) for key in CONTRACT_KEYS}
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
        named = {key: data[key] for key in CONTRACT_KEYS}
        optional = {key: data[key] for key in OPTIONAL_KEYS if data.get(key) is not None}
        extra = {key: value for key, value in data.items() if key not in _RESERVED}
        return cls(**named, **optional, extra=extra)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, SlotRecord):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class Trace:
    """A trace read from disk: the config mapping and the slot records in file order.

    truncated is True when an incomplete final line (a killed writer's) was dropped.
    """

    config: dict[str, Any]
    slots: list[SlotRecord]
    path: Path | None = None
    truncated: bool = False

    @property
    def method(self) -> str:
        """The run's method: config["method"], else the first slot's, else ""."""
        named = self.config.get("method")
        if isinstance(named, str):
            return named
        return self.slots[0].method if self.slots else ""

    def stack(self, name: str) -> FloatArray:
        """One array field stacked over slots: e.g. "uav_xy" -> [N, M, 2]; "pcrb_trace" -> [N].

        Fields that are None in a slot (target_true, plan_xy) become NaN of the right shape.
        """
        values = [getattr(rec, name) for rec in self.slots]
        default: tuple[int, ...] = ()
        if name == "target_true":
            default = (4,)
        elif name == "plan_xy" and self.slots:
            default = (self.slots[0].n_uavs, 2)
        shape = next((np.shape(v) for v in values if v is not None), default)
        return np.array(
            [np.full(shape, np.nan) if v is None else np.asarray(v, dtype=float) for v in values],
            dtype=np.float64,
        ).reshape((len(values), *shape))

    def __iter__(self) -> Iterator[SlotRecord]:
        return iter(self.slots)

    def __len__(self) -> int:
        return len(self.slots)


# --------------------------------------------------------------------------------------------
# Reading


@dataclass(frozen=True)
class _Scan:
    trace: Trace
    good_end: int  # byte offset just past the last line that parsed
    tail_unterminated_ok: bool  # the last line parsed but has no newline


def _check_sequence(rec: SlotRecord, prev: SlotRecord | None, m_config: Any) -> None:
    if isinstance(m_config, int) and not isinstance(m_config, bool) and rec.n_uavs != m_config:
        raise MessageError(f"slot {rec.slot} has {rec.n_uavs} UAVs but config M is {m_config}")
    if prev is not None and rec.slot <= prev.slot:
        raise MessageError(f"slot {rec.slot} does not follow slot {prev.slot} (append-only)")


def _parse_config_line(text: str) -> dict[str, Any]:
    obj = _loads(text)
    if not (isinstance(obj, dict) and set(obj) == {"config"} and isinstance(obj["config"], dict)):
        raise MessageError('the first line must be {"config": {...}}')
    config: dict[str, Any] = obj["config"]
    return config


def _scan(path: Path) -> _Scan:
    try:
        data = path.read_bytes()
    except OSError as err:
        raise MessageError(f"{path}: cannot read: {err.strerror}") from None
    pieces = data.split(b"\n")
    # pieces[-1] is b"" when the file ends with a newline, else the unterminated last line.
    config: dict[str, Any] | None = None
    slots: list[SlotRecord] = []
    offset = good_end = 0
    truncated = tail_ok = False
    n_lines = len(pieces) if pieces[-1] else len(pieces) - 1
    for lineno, raw in enumerate(pieces[:n_lines], start=1):
        terminated = lineno < len(pieces)
        end = offset + len(raw) + (1 if terminated else 0)
        is_last_unterminated = not terminated
        try:
            text = raw.decode("utf-8")
            if not text.strip():
                offset = good_end = end
                continue
            if config is None:
                config = _parse_config_line(text)
            else:
                obj = _loads(text)
                rec = SlotRecord.from_dict(obj)
                _check_sequence(rec, slots[-1] if slots else None, config.get("M"))
                slots.append(rec)
        except (MessageError, UnicodeDecodeError) as err:
            if is_last_unterminated and config is not None:
                truncated = True
                break
            what = "incomplete config line" if is_last_unterminated else str(err)
            raise MessageError(f"{path}: line {lineno}: {what}") from None
        tail_ok = is_last_unterminated
        offset = good_end = end
    if config is None:
        raise MessageError(f"{path}: empty trace: no config line")
    trace = Trace(config=config, slots=slots, path=path, truncated=truncated)
    return _Scan(trace=trace, good_end=good_end, tail_unterminated_ok=tail_ok)


def read_trace(path: str | Path) -> Trace:
    """Read a trace file. An incomplete final line (a killed writer's) is dropped and flagged
    with `Trace.truncated`; any other line that does not parse, or breaks the slot order, raises
    MessageError naming the file and the 1-based line number."""
    return _scan(Path(path)).trace


# --------------------------------------------------------------------------------------------
# Writing


class TraceWriter:
    """Append-only trace writer; a context manager.

    `TraceWriter(path, config)` creates (or replaces) the file and writes `{"config": ...}`;
    `write_slot(record)` appends one line and flushes it (and fsyncs it when `fsync=True`), so
    the file holds every completed slot even if the process is killed. Slot numbers must
    increase, and every record must have config["M"] UAVs when the config names M.
    To continue a trace after a restart, use `TraceWriter.resume(path)`.
    """

    def __init__(self, path: str | Path, config: Mapping[str, Any], *, fsync: bool = False) -> None:
        jsonable = to_jsonable(dict(config), "config")
        self._setup(Path(path), jsonable, None, fsync)
        self._file = self._path.open("w", encoding="utf-8", newline="\n")
        self._write_line(_dumps({"config": jsonable}))

    def _setup(
        self, path: Path, config: dict[str, Any], last: SlotRecord | None, fsync: bool
    ) -> None:
        self._path = path
        self._config = config
        self._last = last
        self._fsync = fsync
        self._written = 0

    @classmethod
    def resume(cls, path: str | Path, *, fsync: bool = False) -> TraceWriter:
        """Reopen an existing trace for appending after a restart.

        Reads (and so validates) the whole file; drops an incomplete final line from the file
        so that the next line starts clean; `config` and `last_record` (with its `P` and `J`)
        tell the caller where to pick up. Raises MessageError if the file is corrupt.
        """
        p = Path(path)
        scan = _scan(p)
        writer = cls.__new__(cls)
        last = scan.trace.slots[-1] if scan.trace.slots else None
        writer._setup(p, scan.trace.config, last, fsync)
        with p.open("r+b") as raw:
            if scan.tail_unterminated_ok:
                raw.seek(0, os.SEEK_END)
                raw.write(b"\n")
            else:
                raw.truncate(scan.good_end)
            raw.flush()
            os.fsync(raw.fileno())
        writer._file = p.open("a", encoding="utf-8", newline="\n")
        return writer

    @property
    def path(self) -> Path:
        """The trace file."""
        return self._path

    @property
    def config(self) -> dict[str, Any]:
        """The config as written on line 1 (JSON-ready)."""
        return self._config

    @property
    def last_record(self) -> SlotRecord | None:
        """The last slot on disk (written or, after resume, read); None if there is none."""
        return self._last

    @property
    def slots_written(self) -> int:
        """Slot lines written by this writer (not counting lines already there on resume)."""
        return self._written

    @property
    def closed(self) -> bool:
        return self._file.closed

    def _write_line(self, line: str) -> None:
        self._file.write(line + "\n")
        self._file.flush()
        if self._fsync:
            os.fsync(self._file.fileno())

    def write_slot(self, record: SlotRecord) -> None:
        """Append one slot line and flush it. Raises MessageError for an out-of-order slot or a
        wrong number of UAVs, ValueError if the writer is closed."""
        if self._file.closed:
            raise ValueError(f"{self._path}: trace writer is closed")
        _check_sequence(record, self._last, self._config.get("M"))
        self._write_line(_dumps(record.to_dict()))
        self._last = record
        self._written += 1

    def close(self) -> None:
        """Close the file (idempotent)."""
        if not self._file.closed:
            self._file.close()

    def __enter__(self) -> TraceWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


__all__ = [
    "CONTRACT_KEYS",
    "OPTIONAL_KEYS",
    "SlotRecord",
    "Trace",
    "TraceWriter",
    "read_trace",
    "to_jsonable",
]
