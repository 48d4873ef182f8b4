"""The true paths of several intruders (config/targets.py; docs/model.md, "Several targets").

Each target is in the scene from its first slot to its last (`TargetSpec.first_slot`,
`last_slot`), starting from its x0 = [x, y, vx, vy] (m, m/s) at its first slot, and moves by one
of four models, one slot (dt) at a time:

- constant_velocity: x_{n+1} = F x_n + w_n (eq. 3-4), w_n ~ N(0, W(kappa)), the scenario's noise;
- coordinated_turn: x_{n+1} = F_ct(omega) x_n + w_n, the exact transition of a constant-speed
  turn at omega (rad/s, positive counter-clockwise), with the same noise W;
- waypoints: straight legs through its waypoints at its initial speed, no noise (once past the
  last waypoint it holds its heading and speed);
- legs: its `Leg`s flown one after another from x0, no noise: straight (constant velocity), turn
  (F_ct(omega): a circular arc of radius speed / omega at constant speed) or accelerate (a
  along the track, heading constant: distance v t + a t^2 / 2, speed v + a t); straight on
  after the last. Exact at any time (`legs_state_at`), a leg boundary inside a slot included:
  each state is the closed form from the start of the leg it falls in.

Pure: numpy only; the caller draws the noise (`TargetNoise`). Shapes: T targets, N slots.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from isac_mission.config.targets import Leg, TargetSpec
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


def leg_advance(x: FloatArray, leg: Leg, tau_s: float) -> FloatArray:
    """[4] the state tau_s (0 <= tau_s, within the leg or past it as if it went on) after
    starting `leg` at x [4], in closed form: straight x + v tau; turn F_ct(omega, tau) x;
    accelerate, with speed v and heading u = v / |v|, position + u (v tau + a tau^2 / 2) and
    velocity u (v + a tau). Raises ValueError for an accelerate leg from speed 0 (no heading)."""
    if leg.kind == "turn":
        return coordinated_turn_matrix(tau_s, leg.turn_rate_radps) @ x
    if leg.kind == "accelerate":
        speed = math.hypot(x[2], x[3])
        if not speed > 0:
            raise ValueError(f"an accelerate leg needs a speed > 0 at its start (got {speed})")
        heading = x[2:] / speed
        along = speed * tau_s + 0.5 * leg.accel_mps2 * tau_s**2
        return np.concatenate([x[:2] + heading * along, heading * (speed + leg.accel_mps2 * tau_s)])
    if leg.kind == "straight":
        return np.concatenate([x[:2] + x[2:] * tau_s, x[2:]])
    raise ValueError(f"unknown kind of leg {leg.kind!r}")


def leg_starts(x0: Sequence[float], legs: Sequence[Leg]) -> tuple[FloatArray, FloatArray]:
    """(times [L + 1] (s), states [L + 1, 4]): when each leg starts and the state there, from x0
    at time 0; entry L is the end of the last leg, where the straight tail starts."""
    times = np.concatenate([[0.0], np.cumsum([leg.duration_s for leg in legs])])
    states = np.empty((len(legs) + 1, 4))
    states[0] = np.asarray(x0, dtype=float)
    for i, leg in enumerate(legs):
        states[i + 1] = leg_advance(states[i], leg, leg.duration_s)
    return times, states


_TAIL = Leg("straight", math.inf)
"""The straight flight after the last leg."""


def _state_from_starts(
    times: FloatArray, states: FloatArray, legs: Sequence[Leg], t_s: float
) -> FloatArray:
    """[4] the state at t_s >= 0 from `leg_starts`' (times, states) of legs: the closed form
    from the start of the leg t_s falls in (a boundary is the start of the leg after it)."""
    i = int(np.searchsorted(times, t_s, side="right")) - 1
    i = min(max(i, 0), len(legs))
    leg = legs[i] if i < len(legs) else _TAIL
    return leg_advance(states[i], leg, t_s - float(times[i]))


def legs_state_at(x0: Sequence[float], legs: Sequence[Leg], t_s: float) -> FloatArray:
    """[4] the state (m, m/s) at time t_s >= 0 (s, from x0 at 0) of a target flying `legs` one
    after another from x0 and straight on after the last (exact at any time)."""
    if not t_s >= 0:
        raise ValueError(f"legs_state_at: t_s must be >= 0 (got {t_s})")
    times, states = leg_starts(x0, legs)
    return _state_from_starts(times, states, legs, t_s)


def legs_states(x0: Sequence[float], legs: Sequence[Leg], dt_s: float, n_steps: int) -> FloatArray:
    """[n_steps + 1, 4] the states at t = k dt_s (k = 0..n_steps) of a target flying `legs` from
    x0 (`legs_state_at` at each instant: exact, a leg boundary inside a slot included)."""
    times, states = leg_starts(x0, legs)
    return np.array([_state_from_starts(times, states, legs, k * dt_s) for k in range(n_steps + 1)])


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
    by chol(W(kappa)) into the process noise of the noisy models (drawn for every target, used
    by constant_velocity and coordinated_turn only)."""
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
        if spec.motion == "legs":
            states[first : last + 1, t] = legs_states(spec.x0, spec.legs, dt_s, last - first)
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
