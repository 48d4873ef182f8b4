"""The traces of `isac-mission view` as the page draws them: one run per trace, one frame per
slot, with the same derived numbers the live console computes (the estimate's 2-sigma ellipse,
the position and velocity parts of tr(PCRB), the position error against the truth).

Offline `simulate` traces and live `run`/`serve` traces have the same format (docs/trace.md),
so both replay alike, for any number of targets: each frame has the slot's tracks and the targets
in the scene (a single target's is track 1), and its estimate, bound and error are those of the
track the plan followed. Several traces of one scenario (the methods of one Monte Carlo run) are
shown side by side on one map.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from isac_mission.console.geometry import ellipse_2sigma, pcrb_parts, position_error_m
from isac_mission.errors import MessageError
from isac_mission.records import read_trace
from isac_mission.records.slot import SlotRecord
from isac_mission.records.trace import Trace
from isac_mission.records.tracks import TrackLine, TracksLine
from isac_mission.wire import DEFAULT_PRIORITY


def _finite(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _xy(a: np.ndarray) -> list[list[float | None]]:
    return [[_finite(float(v)) for v in row] for row in np.asarray(a, dtype=float)]


def frame(line: TracksLine, rec: SlotRecord | None = None) -> dict[str, Any]:
    """One slot of a trace as the page draws it (JSON-ready; null for a missing number): the
    labelled target's estimate, bound and truth from its record `rec`; for a tracker of several
    tracks, those of the track the plan followed (else the first confirmed) and its nearest
    target."""
    raw = line.line
    priorities = _priorities(raw)
    tracks = [
        {
            "id": t.track_id,
            "confirmed": t.confirmed,
            "x": [_finite(float(v)) for v in t.x],
            "ellipse": ellipse_2sigma(t.P),
            "priority": priorities.get(t.track_id, DEFAULT_PRIORITY),
        }
        for t in line.tracks
    ]
    truths = [{"index": k, "x": [float(v) for v in x]} for k, x in sorted(line.truth.items())]
    est: np.ndarray | None
    cov: np.ndarray | None
    truth: np.ndarray | None
    if rec is not None:
        parts = pcrb_parts(rec.J)
        est, cov, truth = rec.target_est, rec.P, rec.target_true
        pcrb: tuple[float | None, float | None, float | None] = (
            _finite(rec.pcrb_trace),
            parts[0] if parts else None,
            parts[1] if parts else None,
        )
    else:
        lead = _lead(line)
        est = None if lead is None else lead.x
        cov = None if lead is None else lead.P
        truth = None if est is None else _nearest(line, est)
        position = None if lead is None else _finite(lead.pcrb_position_trace)
        pcrb = (None, position, None)
    latency = raw.get("latency_ms")
    plan_xy = raw.get("plan_xy")
    return {
        "slot": line.slot,
        "status": line.status,
        "reason": raw.get("reason") or "",
        "uav_xy": _xy(line.uav_xy),
        "plan_xy": _xy(np.array(plan_xy, dtype=float)) if plan_xy is not None else None,
        "eta": [float(e) for e in line.eta],
        "assoc": [int(k) for k in line.assoc],
        "target_est": None if est is None else [_finite(float(v)) for v in est],
        "ellipse": None if cov is None else ellipse_2sigma(cov),
        "target_true": [float(v) for v in truth] if truth is not None else None,
        "pcrb_trace": pcrb[0],
        "pcrb_pos": pcrb[1],
        "pcrb_vel": pcrb[2],
        "error_m": None if est is None else position_error_m(est, truth),
        "solve_ms": _finite(raw.get("solve_ms")),
        "latency_ms": latency if isinstance(latency, int | float) else None,
        "excluded": [int(m) for m in raw.get("excluded", []) if isinstance(m, int)],
        "tracks": tracks,
        "truths": truths,
    }


def _priorities(raw: dict[str, Any]) -> dict[int, float]:
    """Track id -> the priority its slot line records (a line without one: none; the page
    shows DEFAULT_PRIORITY, what every track was planned with before an operator set one)."""
    out: dict[int, float] = {}
    tracks = raw.get("tracks")
    for entry in tracks if isinstance(tracks, list) else []:
        if not isinstance(entry, dict):
            continue
        track_id, priority = entry.get("id"), entry.get("priority")
        if isinstance(priority, bool) or not isinstance(priority, int | float):
            continue
        if isinstance(track_id, int) and math.isfinite(priority):
            out[track_id] = float(priority)
    return out


def _lead(line: TracksLine) -> TrackLine | None:
    """The track the slot's plan followed, else the first confirmed one (None: none)."""
    confirmed = [t for t in line.tracks if t.confirmed]
    followed = [t for t in confirmed if t.track_id == line.planned_for]
    chosen = followed or confirmed
    return chosen[0] if chosen else None


def _nearest(line: TracksLine, x: np.ndarray) -> np.ndarray | None:
    """The state [4] of the target nearest to x [4] in the slot (None: no truth)."""
    if not line.truth:
        return None
    return min(line.truth.values(), key=lambda s: float(np.linalg.norm(s[:2] - x[:2])))


def _label(trace: Trace, path: Path, taken: set[str]) -> str:
    label = trace.method
    if label in taken:
        label = path.stem
    taken.add(label)
    return label


def load_replay(paths: Sequence[Path]) -> dict[str, Any]:
    """`{"runs": [{"label", "path", "config", "frames"}]}` for the page; MessageError naming
    the file when a trace cannot be read or does not match the first one's scenario."""
    if not paths:
        raise MessageError("view: no trace given")
    runs: list[dict[str, Any]] = []
    taken: set[str] = set()
    first: dict[str, Any] | None = None
    for path in paths:
        trace = read_trace(path)
        records = {r.slot: r for r in trace.slots}
        config = trace.config
        if first is None:
            first = config
        else:
            for key in ("M", "K", "area", "bs_xy"):
                if config.get(key) != first.get(key):
                    raise MessageError(
                        f"{path}: config.{key} differs from {paths[0]}'s (one scenario per view)"
                    )
        runs.append(
            {
                "label": _label(trace, path, taken),
                "path": str(path),
                "config": config,
                "frames": [frame(line, records.get(line.slot)) for line in trace.lines],
            }
        )
    return {"runs": runs}


def replay_config(replay: dict[str, Any]) -> dict[str, Any]:
    """The config the page's map uses in a replay: the first trace's, with N the longest run."""
    runs = replay["runs"]
    config = dict(runs[0]["config"])
    config["N"] = max(len(r["frames"]) for r in runs)
    config["method"] = ", ".join(r["label"] for r in runs)
    return config
