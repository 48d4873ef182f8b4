"""The traces of `isac-mission view` as the page draws them: one run per trace, one frame per
slot, with the same derived numbers the live console computes (the estimate's 2-sigma ellipse,
the position and velocity parts of tr(PCRB), the position error against the truth).

Offline `simulate` traces and live `run`/`serve` traces have the same format (docs/trace.md),
so both replay alike. Several traces of one scenario (the methods of one Monte Carlo run) are
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
from isac_mission.records.slot import SlotRecord, Trace


def _finite(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _xy(a: np.ndarray) -> list[list[float | None]]:
    return [[_finite(float(v)) for v in row] for row in np.asarray(a, dtype=float)]


def frame(rec: SlotRecord) -> dict[str, Any]:
    """One slot of a trace as the page draws it (JSON-ready; null for a missing number)."""
    parts = pcrb_parts(rec.J)
    truth = rec.target_true
    extra = rec.extra
    latency = extra.get("latency_ms")
    return {
        "slot": rec.slot,
        "status": rec.status,
        "reason": rec.reason or "",
        "uav_xy": _xy(rec.uav_xy_m),
        "plan_xy": _xy(rec.plan_xy) if rec.plan_xy is not None else None,
        "eta": [float(e) for e in rec.bandwidth_share],
        "assoc": [int(k) for k in rec.assoc],
        "target_est": [_finite(float(v)) for v in rec.target_est],
        "ellipse": ellipse_2sigma(rec.P),
        "target_true": [float(v) for v in truth] if truth is not None else None,
        "pcrb_trace": _finite(rec.pcrb_trace),
        "pcrb_pos": parts[0] if parts else None,
        "pcrb_vel": parts[1] if parts else None,
        "error_m": position_error_m(rec.target_est, truth),
        "solve_ms": _finite(rec.solve_ms),
        "latency_ms": latency if isinstance(latency, int | float) else None,
        "excluded": [int(m) for m in extra.get("excluded", []) if isinstance(m, int)],
    }


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
                "frames": [frame(rec) for rec in trace],
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
