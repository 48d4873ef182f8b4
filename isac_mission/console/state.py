"""What the console knows of a live mission: the latest message of each kind, each vehicle's
trail, and the time series, built from the bus messages as any observer receives them.

`MissionView.ingest(key, payload)` validates a payload with the bus's own models
(`wire.models.MODELS`, the receivers' sizes as context), updates the view and returns the
updates to push to the pages as `(topic, data)` pairs (`console.feed`). A bad payload is counted
by reason (`wire.rejection_reason`) and changes nothing. `snapshot()` is everything a page that
has just connected needs. All data are JSON-ready (lists, floats, str), SI units.

Targets are drawn one way whatever their number: as the state topics `tracks` (every track with
its 2-sigma ellipse) and `truths` (the targets present at the latest truth's slot). A `track_set`
and a `truth_set` (docs/bus.md) give them directly; a single-target `track` gives the `tracks`
of a one-entry `track_set` (track id 1, confirmed, `pcrb_position_trace` the position part of
tr(J^-1)) and `truth` the `truths` of a one-state `truth_set`, unless a `track_set` (a
`truth_set`) of the same or a later slot has arrived: a ground that publishes both sends its
lead track as `track` beside the `track_set`, which wins. Every track carries its `priority`
(the operator's weight of it in the planner's objective, 0 to 10; 1 when the message has none).
Once the slot's truth is known,
`tracks` also holds the targets present then (`truths_of_slot`), each present target's distance
to the nearest confirmed track (`target_errors`), and per confirmed track its distance to the
nearest present target (`error_m`) and the target it follows (`target`). Per confirmed track,
its position bound and its error are kept by slot (`track_series`, in the snapshot; the last
slots' rows ride with each `tracks` update) for the page's charts.

`track` and `truth` also stay state topics of their own, with the slot series (`series`): tr(PCRB)
and its position and velocity parts, and |estimate - truth|, of the lead track; `track` carries,
once known, the truth of its own slot (`truth_of_slot`). `detection_set` is taken as `detection`
is.
"""

from __future__ import annotations

import time
from collections import Counter, deque
from collections.abc import Callable
from typing import Any, Final

from pydantic import ValidationError

from isac_mission.console.geometry import ellipse_2sigma, pcrb_parts, position_error_m
from isac_mission.errors import MessageError
from isac_mission.wire import DEFAULT_PRIORITY
from isac_mission.wire.envelope import loads, rejection_reason
from isac_mission.wire.models import MODELS
from isac_mission.wire.refusal import message_error

TRAIL_POINTS: Final = 3000
"""Trail points kept per vehicle (a point every TRAIL_STEP_M of motion)."""
TRAIL_STEP_M: Final = 0.5
SERIES_SLOTS: Final = 20_000
"""Slots of time series kept."""
TRACK_SERIES_SLOTS: Final = 5_000
"""Slots of per-track series kept (the charts per track)."""
TRACK_ROWS_SENT: Final = 16
"""Slots of per-track series sent with each `tracks` update."""
DEFAULT_FOLLOW_GATE_M: Final = 10.0
"""A confirmed track follows a target when it is the target's nearest confirmed track and within
this distance (m): the scenario's GOSPA cutoff `multi_target.gospa_cutoff_m` when it has one."""
REPLIES_KEPT: Final = 50

Update = tuple[str, Any]


class MissionView:
    """The console's picture of one mission (single-threaded: the console's event loop).

    config: the trace config of the mission (`Scenario.trace_config()`, docs/trace.md): M, K,
    N, dt, area, bs_xy, d_th, v_max, ...; clock: wall clock (Unix s), replaceable in tests.
    """

    def __init__(self, config: dict[str, Any], clock: Callable[[], float] = time.time) -> None:
        self.config = config
        self.n_uavs = int(config["M"])
        self.n_bs = int(config["K"])
        self.clock = clock
        self.latest: dict[str, Any] = {}
        self.trails: dict[int, deque[list[float]]] = {
            m: deque(maxlen=TRAIL_POINTS) for m in range(self.n_uavs)
        }
        self.series: dict[int, dict[str, Any]] = {}
        self.replies: deque[dict[str, Any]] = deque(maxlen=REPLIES_KEPT)
        self.truth_by_slot: dict[int, list[float]] = {}
        self.estimate_by_slot: dict[int, list[float]] = {}
        self.truths_by_slot: dict[int, list[dict[str, Any]]] = {}
        self.confirmed_by_slot: dict[int, list[list[float]]] = {}
        self.track_series: dict[int, dict[str, Any]] = {}
        self.track_set_slot: int | None = None
        """The latest slot of a `track_set` received (a `track` of it or before draws nothing)."""
        self.truth_set_slot: int | None = None
        multi = config.get("multi_target")
        gate = multi.get("gospa_cutoff_m") if isinstance(multi, dict) else None
        self.follow_gate_m = (
            float(gate) if isinstance(gate, int | float) and gate > 0 else DEFAULT_FOLLOW_GATE_M
        )
        self.detection_wall_s: dict[int, float] = {}
        self.received: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()
        self.last_rejection = ""

    # ------------------------------------------------------------------ ingest

    def ingest(self, key: str, payload: bytes) -> list[Update]:
        """Validate one bus payload received on `key` and fold it in; the page updates."""
        now = self.clock()
        try:
            obj = loads(payload)
            kind = obj.get("type")
            model = MODELS.get(kind) if isinstance(kind, str) else None
            if model is None:
                raise MessageError(f"type: {kind!r} is not a message type the console knows")
            context = {"n_uavs": self.n_uavs, "n_bs": self.n_bs}
            try:
                msg = model.model_validate(obj, strict=True, context=context)
            except ValidationError as err:
                raise message_error(err, str(kind), model) from None
        except MessageError as err:
            reason = rejection_reason(err)
            self.rejected[reason] += 1
            self.last_rejection = f"{key}: {err}"[:1000]
            return []
        self.received[str(kind)] += 1
        data = msg.model_dump(mode="json", by_alias=True)
        handler = _HANDLERS.get(str(kind))
        return handler(self, data, now) if handler is not None else []

    def _telemetry(self, d: dict[str, Any], now: float) -> list[Update]:
        d["received_wall_s"] = now
        m = int(d["uav"])
        trail = self.trails[m]
        xy = [float(v) for v in d["position_xy_m"]]
        if not trail or abs(trail[-1][0] - xy[0]) + abs(trail[-1][1] - xy[1]) >= TRAIL_STEP_M:
            trail.append(xy)
        return self._state(f"telemetry/{m}", d)

    def _plan(self, d: dict[str, Any], now: float) -> list[Update]:
        n = int(d["slot"])
        point: dict[str, Any] = {"slot": n, "solve_ms": float(d["solve_s"]) * 1e3}
        det = self.detection_wall_s.get(n - 1)
        if det is not None:
            point["det_to_plan_ms"] = (now - det) * 1e3
        d["received_wall_s"] = now
        return [*self._state("plan", d), *self._point(point)]

    def _track(self, d: dict[str, Any], now: float) -> list[Update]:
        n = int(d["slot"])
        d.setdefault("priority", DEFAULT_PRIORITY)  # written only when it is not 1
        d["ellipse"] = ellipse_2sigma(d["P"])
        parts = pcrb_parts(d["J"])
        d["pcrb_pos"], d["pcrb_vel"] = parts if parts is not None else (None, None)
        d["received_wall_s"] = now
        del d["J"]
        self.estimate_by_slot[n] = list(d["x"])
        _trim(self.estimate_by_slot, n)
        d["truth_of_slot"] = self.truth_by_slot.get(n)
        point: dict[str, Any] = {"slot": n, "pcrb_trace": d["pcrb_trace"]}
        point |= {"pcrb_pos": d["pcrb_pos"], "pcrb_vel": d["pcrb_vel"]}
        error = position_error_m(d["x"], self.truth_by_slot.get(n))
        if error is not None:
            point["error_m"] = error
        out = [*self._state("track", d), *self._point(point)]
        if not _covered(self.track_set_slot, n):
            out += self._tracks(_one_track_set(d), now)
        return out

    def _truth(self, d: dict[str, Any], now: float) -> list[Update]:
        n = int(d["slot"])
        self.truth_by_slot[n] = list(d["target_x"])
        _trim(self.truth_by_slot, n)
        out = self._state("truth", d)
        track = self.latest.get("track")
        if track is not None and int(track["slot"]) == n:  # the truth of the estimate's slot
            track["truth_of_slot"] = self.truth_by_slot[n]
            out += self._state("track", track)
        error = position_error_m(self.estimate_by_slot.get(n, [float("nan")] * 2), d["target_x"])
        if error is not None:
            out += self._point({"slot": n, "error_m": error})
        if not _covered(self.truth_set_slot, n):
            out += self._truths(_one_truth_set(d), now)
        return out

    def _track_set(self, d: dict[str, Any], now: float) -> list[Update]:
        n = int(d["slot"])
        self.track_set_slot = n if self.track_set_slot is None else max(self.track_set_slot, n)
        self.track_series.pop(n, None)  # the slot's tracks are these: none drawn from `track`
        return self._tracks(d, now)

    def _truth_set(self, d: dict[str, Any], now: float) -> list[Update]:
        n = int(d["slot"])
        self.truth_set_slot = n if self.truth_set_slot is None else max(self.truth_set_slot, n)
        return self._truths(d, now)

    def _tracks(self, d: dict[str, Any], now: float) -> list[Update]:
        """The `tracks` of a `track_set` d (received, or made of a `track`)."""
        n = int(d["slot"])
        for track in d["tracks"]:
            track["ellipse"] = ellipse_2sigma(track["P"])
            track.setdefault("priority", DEFAULT_PRIORITY)  # written only when it is not 1
        d["received_wall_s"] = now
        self.confirmed_by_slot[n] = [list(tr["x"]) for tr in d["tracks"] if tr["confirmed"]]
        _trim(self.confirmed_by_slot, n)
        self._track_points(d)
        truths = self.truths_by_slot.get(n)
        if truths is not None:
            d["target_errors"] = _target_errors(truths, self.confirmed_by_slot[n])
            self._follow(d, truths)
        d["truths_of_slot"] = truths
        d["series_rows"] = self._recent_track_rows()
        return self._state("tracks", d)

    def _truths(self, d: dict[str, Any], now: float) -> list[Update]:
        """The `truths` of a `truth_set` d (received, or made of a `truth`), and the `tracks` of
        the same slot again with their errors."""
        n = int(d["slot"])
        present = [{"index": i, "x": list(x)} for i, x in enumerate(d["targets"]) if x is not None]
        self.truths_by_slot[n] = present
        _trim(self.truths_by_slot, n)
        del d["targets"], d["origins"]  # the origins are for the trace's metrics, not the page
        d["present"] = present
        out = self._state("truths", d)
        tracks = self.latest.get("tracks")
        confirmed = self.confirmed_by_slot.get(n)
        if tracks is not None and confirmed is not None and int(tracks["slot"]) == n:
            tracks["target_errors"] = _target_errors(present, confirmed)
            self._follow(tracks, present)
            tracks["truths_of_slot"] = present
            tracks["series_rows"] = self._recent_track_rows()
            out += self._state("tracks", tracks)
        return out

    def _track_points(self, d: dict[str, Any]) -> None:
        """Each confirmed track's position bound (m^2) at the slot of `track_set` d, kept for
        the charts as `pcrb/<id>`."""
        n = int(d["slot"])
        row = self.track_series.setdefault(n, {"slot": n})
        for track in d["tracks"]:
            if track["confirmed"] and track["pcrb_position_trace"] is not None:
                row[f"pcrb/{track['id']}"] = float(track["pcrb_position_trace"])
        _trim(self.track_series, n, TRACK_SERIES_SLOTS)

    def _recent_track_rows(self) -> list[dict[str, Any]]:
        """The per-track series of the last TRACK_ROWS_SENT slots (copies): `tracks` is a state
        topic, so a page may not see every slot's; these rows fill its charts' gaps."""
        recent = sorted(self.track_series)[-TRACK_ROWS_SENT:]
        return [dict(self.track_series[n]) for n in recent]

    def _follow(self, d: dict[str, Any], present: list[dict[str, Any]]) -> None:
        """Per confirmed track of `track_set` d: `error_m`, its distance (m) to the nearest
        present target, and `target`, the index of the target it follows (None when it follows
        none: it is not that target's nearest confirmed track within the follow gate). The
        errors are kept for the charts as `error/<id>`."""
        n = int(d["slot"])
        confirmed = [tr for tr in d["tracks"] if tr["confirmed"]]
        nearest_track: dict[int, tuple[float, int]] = {}
        for truth in present:
            for tr in confirmed:
                dist = position_error_m(tr["x"], truth["x"])
                best = nearest_track.get(truth["index"])
                if dist is not None and (best is None or dist < best[0]):
                    nearest_track[truth["index"]] = (dist, int(tr["id"]))
        row = self.track_series.setdefault(n, {"slot": n})
        for tr in confirmed:
            errors = [position_error_m(tr["x"], t["x"]) for t in present]
            finite = [e for e in errors if e is not None]
            tr["error_m"] = min(finite) if finite else None
            followed = [
                (dist, index)
                for index, (dist, track_id) in nearest_track.items()
                if track_id == tr["id"] and dist <= self.follow_gate_m
            ]
            tr["target"] = min(followed)[1] if followed else None
            if tr["error_m"] is not None:
                row[f"error/{tr['id']}"] = tr["error_m"]
        _trim(self.track_series, n, TRACK_SERIES_SLOTS)
        d["follow_gate_m"] = self.follow_gate_m

    def _detection(self, d: dict[str, Any], now: float) -> list[Update]:
        n = int(d["slot"])
        self.detection_wall_s[n] = now
        _trim(self.detection_wall_s, n)
        return []

    def _reply(self, d: dict[str, Any], now: float) -> list[Update]:
        d["received_wall_s"] = now
        self.replies.append(d)
        return [("reply", d)]

    def _plain(self, d: dict[str, Any], now: float) -> list[Update]:
        d["received_wall_s"] = now
        return self._state(str(d["type"]), d)

    def _state(self, topic: str, data: dict[str, Any]) -> list[Update]:
        self.latest[topic] = data
        return [(topic, data)]

    def _point(self, point: dict[str, Any]) -> list[Update]:
        n = int(point["slot"])
        self.series.setdefault(n, {"slot": n}).update(point)
        _trim(self.series, n, SERIES_SLOTS)
        return [("series", point)]

    # ------------------------------------------------------------------ snapshot

    def stats(self) -> dict[str, Any]:
        """Messages received by type and rejected by reason, and the last rejection."""
        return {
            "received": dict(self.received),
            "rejected": dict(self.rejected),
            "last_rejection": self.last_rejection,
        }

    def snapshot(self) -> dict[str, Any]:
        """Everything a page needs when it connects: config, latest state of each topic,
        trails [M][k][2], the series (sorted by slot), the per-track
        series (`pcrb/<id>` m^2, `error/<id>` m, sorted by slot), the recent replies, the
        stats."""
        return {
            "config": self.config,
            "latest": self.latest,
            "trails": {str(m): list(t) for m, t in self.trails.items()},
            "series": [self.series[n] for n in sorted(self.series)],
            "track_series": [self.track_series[n] for n in sorted(self.track_series)],
            "replies": list(self.replies),
            "stats": self.stats(),
        }


def _target_errors(
    truths: list[dict[str, Any]], confirmed_xy: list[list[float]]
) -> list[dict[str, Any]]:
    """Per present target (`{"index", "x"}`), the distance (m) from its true position to the
    nearest confirmed track's, None when no track is confirmed."""
    out: list[dict[str, Any]] = []
    for truth in truths:
        errors = [position_error_m(xy, truth["x"]) for xy in confirmed_xy]
        finite = [e for e in errors if e is not None]
        out.append({"index": truth["index"], "error_m": min(finite) if finite else None})
    return out


def _one_track_set(track: dict[str, Any]) -> dict[str, Any]:
    """The `track_set` of one confirmed track, id 1, that a single-target `track` (as folded in:
    `pcrb_pos` the position part of tr(J^-1), None when J is singular) stands for."""
    entry = {
        "id": 1,
        "confirmed": True,
        "x": list(track["x"]),
        "P": [list(row) for row in track["P"]],
        "pcrb_position_trace": track["pcrb_pos"],
        "priority": track.get("priority", DEFAULT_PRIORITY),
    }
    return {
        "schema": track["schema"],
        "type": "track_set",
        "slot": track["slot"],
        "t": track["t"],
        "tracks": [entry],
        "published_wall_s": track["published_wall_s"],
    }


def _one_truth_set(truth: dict[str, Any]) -> dict[str, Any]:
    """The `truth_set` of one target that a single-target `truth` stands for."""
    return {
        "schema": truth["schema"],
        "type": "truth_set",
        "slot": truth["slot"],
        "t": truth["t"],
        "targets": [list(truth["target_x"])],
        "origins": [],
    }


def _covered(set_slot: int | None, slot: int) -> bool:
    """Whether a `track_set` (`truth_set`) of `set_slot` stands for slot `slot`'s targets: it is
    of the same or a later slot, so a `track` (`truth`) of `slot` adds no second drawing."""
    return set_slot is not None and slot <= set_slot


def _trim(by_slot: dict[int, Any], newest: int, keep: int = 64) -> None:
    """Forget slots more than `keep` before `newest` (bounded memory over long missions)."""
    for old in [n for n in by_slot if n < newest - keep]:
        del by_slot[old]


_HANDLERS: Final[dict[str, Callable[[MissionView, dict[str, Any], float], list[Update]]]] = {
    "telemetry": MissionView._telemetry,
    "plan": MissionView._plan,
    "track": MissionView._track,
    "truth": MissionView._truth,
    "detection": MissionView._detection,
    "track_set": MissionView._track_set,
    "truth_set": MissionView._truth_set,
    "detection_set": MissionView._detection,  # counted, and its slot's time, as `detection`
    "control_reply": MissionView._reply,
    "health": MissionView._plain,
    "clock": MissionView._plain,
    "control": MissionView._plain,
}
