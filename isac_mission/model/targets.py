"""The true paths of several intruders (config/targets.py; docs/model.md, "Several targets").

Each target is in the scene from its first slot to its last (`TargetSpec.first_slot`,
`last_slot`), starting from its x0 = [x, y, vx, vy] (m, m/s) at its first slot, and moves by one
of three models, one slot (dt) at a time:

- constant_velocity: x_{n+1} = F x_n + w_n (eq. 3-4), w_n ~ N(0, W(kappa)), the scenario's noise;
- coordinated_turn: x_{n+1} = F_ct(omega) x_n + w_n, the exact transition of a constant-speed
  turn at omega (rad/s, positive counter-clockwise), with the same noise W;
- waypoints: straight legs through its waypoints at its initial speed, no noise (once past the
  last waypoint it holds its heading and speed).

Pure: numpy only; the caller draws the noise (`TargetNoise`). Shapes: T targets, N slots.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from isac_mission.config.targets import TargetSpec
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.types import BoolArray, FloatArray, IntArray

if TYPE_CHECKING:
    from isac_mission.config import Scenario


def coordinated_turn_matrix(dt_s: float, omega_radps: float) -> FloatArray:
    """F_ct [4, 4] for [x, y, vx, vy]: the velocity rotates by omega dt, the position follows
    the arc; omega = 0 is F (eq. 3)."""
    if abs(omega_radps) < 1e-12:
        return transition_matrix(dt_s)
    wt = omega_radps * dt_s
    s, c = math.sin(wt), math.cos(wt)
    w = omega_radps
    return np.array(
        [
            [1.0, 0.0, s / w, -(1.0 - c) / w],
            [0.0, 1.0, (1.0 - c) / w, s / w],
            [0.0, 0.0, c, -s],
            [0.0, 0.0, s, c],
        ]
    )


def waypoint_states(
    x0: Sequence[float], waypoints_xy_m: Sequence[Sequence[float]], dt_s: float, n_steps: int
) -> FloatArray:
    """[n_steps + 1, 4] states at t = k dt along straight legs from x0's position through the
    waypoints [W, 2] at |x0's velocity|; past the last waypoint, on along the last leg."""
    speed = float(np.hypot(x0[2], x0[3]))
    points = np.vstack([np.asarray(x0[:2], float)[None], np.asarray(waypoints_xy_m, float)])
    legs = np.diff(points, axis=0)
    lengths = np.linalg.norm(legs, axis=1)
    keep = lengths > 1e-9
    legs, lengths, starts = legs[keep], lengths[keep], points[:-1][keep]
    out = np.empty((n_steps + 1, 4))
    if len(legs) == 0:
        out[:] = np.asarray(x0, float)
        return out
    ends = np.cumsum(lengths)
    for k in range(n_steps + 1):
        travelled = speed * k * dt_s
        i = min(int(np.searchsorted(ends, travelled, side="right")), len(legs) - 1)
        into = travelled - (ends[i] - lengths[i])
        heading = legs[i] / lengths[i]
        out[k, :2] = starts[i] + heading * into
        out[k, 2:] = heading * speed
    return out


@dataclass(frozen=True)
class TargetPaths:
    """states [N + 1, T, 4] (NaN where a target is not in the scene), present [N + 1, T]."""

    states: FloatArray
    present: BoolArray

    def at(self, n: int) -> tuple[FloatArray, IntArray]:
        """(states [T', 4], indices [T']) of the targets in the scene at slot n."""
        idx = np.flatnonzero(self.present[n])
        return self.states[n, idx], idx


def target_paths(
    targets: Sequence[TargetSpec], dt_s: float, kappa: float, n_slots: int, normals: FloatArray
) -> TargetPaths:
    """Every target's path over slots 0..n_slots. normals [T, N, 4]: standard normals, scaled
    by chol(W(kappa)) into the process noise of the noisy models."""
    T = len(targets)
    states = np.full((n_slots + 1, T, 4), np.nan)
    present = np.zeros((n_slots + 1, T), dtype=bool)
    W = process_noise(dt_s, kappa)
    chol = np.linalg.cholesky(W) if kappa > 0 else np.zeros((4, 4))
    for t, spec in enumerate(targets):
        first, last = spec.first_slot, min(spec.last_slot, n_slots)
        if first > last:
            continue
        present[first : last + 1, t] = True
        if spec.motion == "waypoints":
            states[first : last + 1, t] = waypoint_states(
                spec.x0, spec.waypoints_xy_m, dt_s, last - first
            )
            continue
        F = (
            coordinated_turn_matrix(dt_s, spec.turn_rate_radps)
            if spec.motion == "coordinated_turn"
            else transition_matrix(dt_s)
        )
        x = np.asarray(spec.x0, dtype=float)
        states[first, t] = x
        for n in range(first + 1, last + 1):
            x = F @ x + chol @ normals[t, n - 1]
            states[n, t] = x
    return TargetPaths(states, present)


def target_radar_gains(s: Scenario) -> FloatArray:
    """[T] each target's SNR^s d^4 (m^4) from its RCS (the scenario's radar gain at that RCS)."""
    return np.array([s.with_changes(rcs_m2=t.rcs_m2).radar_gain for t in s.targets])
