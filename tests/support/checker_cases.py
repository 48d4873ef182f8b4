"""A small hand-built trace for the independent checker's own tests (tests/unit): 2 BSs on the
x axis, 2 UAVs between them, one target to the north; every constraint holds with a clear
margin, and `mutate` breaks one at a time."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from isac_mission.records import SlotRecord, Trace
from tests.support.independent.constraints import check_constraints

BETA0 = 7.26e-7
NOISE_W = 1e-16
GAMMA_TH = 12.59
DH = 100.0 - 15.0


def base_config(**changes: Any) -> dict[str, Any]:
    cfg: dict[str, Any] = {
        "M": 2,
        "K": 2,
        "dt": 1.0,
        "B": 20e6,
        "Pu": 0.1,
        "P_bs": 1.0,  # d_th about 24 km
        "noise_w": NOISE_W,
        "beta0": BETA0,
        "H": 100.0,
        "H_bs": 15.0,
        "gamma_th": GAMMA_TH,
        "r_th": 10e6,
        "n_a": 1,
        "v_max": 25.0,
        "d_safe": 30.0,
        "kappa": 0.5,
        "bs_xy": [[0.0, 0.0], [1000.0, 0.0]],
        "uav_start_xy": [[390.0, 300.0], [470.0, 300.0]],
        "P0": np.diag([100.0, 100.0, 4.0, 4.0]).tolist(),
    }
    cfg.update(changes)
    return cfg


def p_bs_for_range(d_th: float) -> float:
    """The BS power that makes the control range exactly d_th (14b)."""
    return (d_th**2 + DH**2) * NOISE_W * GAMMA_TH / BETA0


def record(slot: int, uav_xy: list[list[float]], target_pred: list[float], **kw: Any) -> SlotRecord:
    fields: dict[str, Any] = {
        "slot": slot,
        "method": "proposed",
        "status": "ok",
        "uav_xy_m": np.array(uav_xy),
        "bandwidth_share": np.array([0.5, 0.5]),
        "assoc": np.array([0, 1]),
        "target_true": np.array(target_pred) + 1.0,
        "target_est": np.array(target_pred) + 0.5,
        "target_pred": np.array(target_pred),
        "r_diag": np.array([4.0, 9.0, 0.01, 0.04]),
        "pcrb_trace": 1.0,
        "solve_ms": 1.0,
        "P": np.eye(4),
        "J": np.eye(4),
    }
    fields.update(kw)
    return SlotRecord(**fields)  # type: ignore[arg-type]


def valid_trace(config: dict[str, Any] | None = None) -> Trace:
    slots = [
        # each UAV moves 10 m per slot (limit 25 m); UAVs 60 m then 40 m apart (D_s = 30 m)
        record(1, [[400.0, 300.0], [460.0, 300.0]], [430.0, 600.0, 20.0, 0.0]),
        record(2, [[410.0, 300.0], [450.0, 300.0]], [450.0, 600.0, 20.0, 0.0]),
    ]
    return Trace(config=config or base_config(), slots=slots)


def mutate(trace: Trace, index: int, **changes: Any) -> Trace:
    slots = list(trace.slots)
    slots[index] = replace(slots[index], **changes)
    return Trace(config=trace.config, slots=slots)


def flagged(trace: Trace, **kw: Any) -> set[tuple[str, int, tuple[int, ...]]]:
    return {(v.constraint, v.slot, v.uavs) for v in check_constraints(trace, **kw)}
