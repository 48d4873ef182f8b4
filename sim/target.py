"""The simulated target's true trajectory (pure: numpy only, seeded).

Two kinds, both advanced one slot at a time and both giving the state [x, y, vx, vy] in the
scenario plane (x east, y north; m and m/s):

- `CvTarget`: the paper's constant-velocity model (eq. 3-4), x_{n+1} = F x_n + w_n with
  w_n ~ N(0, W(kappa)), drawn from a caller-supplied `numpy.random.Generator`.
- `ScriptedTarget`: a piecewise-linear path through waypoints at constant speed (deterministic),
  for demonstrations and tests that need a known truth.

Area bounds (`bounds_m`, the scenario's [width, height]): unless disabled with `bounds_m=None`,
a state that leaves the rectangle [0, width] x [0, height] after a step is reflected off the
boundary it crossed: the position is mirrored back inside (p -> -p below 0, p -> 2 L - p above L,
repeated for steps longer than the area) and the matching velocity component changes sign. Away
from the walls the increments are exactly the model's Gaussian ones; a step that reflects is no
longer Gaussian, which is the price of a target that never leaves the area (the tracker's model
does not know about the walls; see docs/model.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from isac_mission.model.motion import ConstantVelocity
from isac_mission.types import FloatArray


class TargetModel(Protocol):
    """What the world needs from a target: the state at the current slot and a way to advance."""

    @property
    def state(self) -> FloatArray:
        """[x, y, vx, vy] (m, m/s) at the current slot (a copy)."""
        ...

    @property
    def slot(self) -> int:
        """Index n of the current slot (0 at the start)."""
        ...

    def advance(self) -> FloatArray:
        """Move to the next slot and return its state [4]."""
        ...


def reflect_into_area(state: FloatArray, bounds_m: FloatArray) -> FloatArray:
    """Fold a state [4] back into [0, W] x [0, H], flipping the velocity once per wall hit.

    bounds_m [2] = (W, H) in metres. The fold is exact for any distance outside (a step longer than
    the area bounces several times); the returned array is a new one.
    """
    out = np.array(state, dtype=float)
    for axis in (0, 1):
        length = float(bounds_m[axis])
        p = float(out[axis])
        # Unfold onto a period of 2L: positions in [L, 2L) are mirror images.
        period = 2.0 * length
        k = math.floor(p / period)
        q = p - k * period
        flips = 2 * k  # every full period is two wall hits
        if q > length:
            q = period - q
            flips += 1
        out[axis] = q
        if flips % 2:
            out[axis + 2] = -out[axis + 2]
    return out


class CvTarget:
    """Constant-velocity target with process noise W(kappa) (eq. 3-4), reflected off the area.

    x0 [4]: state at slot 0 (m, m/s); dt_s: slot length (s); kappa: process-noise intensity
    (m^2/s^3); rng: the only source of randomness after `increments`; bounds_m [2] = (W, H) or
    None for an unbounded plane; increments [K, 4]: the process noise w_0..w_{K-1} of the first K
    steps (m, m/s; e.g. the draws of `simulate`'s run, model/run_noise.py), rng's draws after
    them. The state at slot 0 is x0 exactly (the target starts moving at slot 0).
    """

    def __init__(
        self,
        x0: FloatArray,
        dt_s: float,
        kappa: float,
        rng: np.random.Generator,
        bounds_m: FloatArray | None = None,
        increments: FloatArray | None = None,
    ) -> None:
        x0 = np.asarray(x0, dtype=float)
        self._increments = np.zeros((0, 4)) if increments is None else np.asarray(increments)
        if self._increments.ndim != 2 or self._increments.shape[1] != 4:
            raise ValueError(f"increments must be [K, 4], got shape {self._increments.shape}")
        if x0.shape != (4,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"x0 must be 4 finite numbers, got {x0!r}")
        if not dt_s > 0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        if not kappa >= 0:
            raise ValueError(f"kappa must be >= 0, got {kappa}")
        self._bounds = None if bounds_m is None else np.asarray(bounds_m, dtype=float)
        if self._bounds is not None:
            if self._bounds.shape != (2,) or not np.all(self._bounds > 0):
                raise ValueError(f"bounds_m must be two positive lengths, got {bounds_m!r}")
            if not (0 <= x0[0] <= self._bounds[0] and 0 <= x0[1] <= self._bounds[1]):
                raise ValueError(f"x0 position {x0[:2].tolist()} is outside the area")
        motion = ConstantVelocity(kappa)
        self._F = motion.transition(dt_s)
        self._W = motion.process_noise(dt_s)
        # W = kappa * kron(block, I2): factor the 2x2 block once (positive definite for dt > 0).
        block = np.array([[dt_s**3 / 3.0, dt_s**2 / 2.0], [dt_s**2 / 2.0, dt_s]])
        self._L = math.sqrt(kappa) * np.kron(np.linalg.cholesky(block), np.eye(2))
        self._rng = rng
        self._x = x0.copy()
        self._slot = 0

    @property
    def state(self) -> FloatArray:
        """[x, y, vx, vy] at the current slot (a copy)."""
        return self._x.copy()

    @property
    def slot(self) -> int:
        """Index of the current slot."""
        return self._slot

    @property
    def process_noise(self) -> FloatArray:
        """W [4, 4] of eq. 4 for this target's dt and kappa."""
        return self._W.copy()

    def advance(self) -> FloatArray:
        """x_{n+1} = F x_n + w_n, w_n ~ N(0, W) (the given increment while there is one), then
        reflected into the area. Returns x_{n+1}."""
        if self._slot < len(self._increments):
            w = np.array(self._increments[self._slot], dtype=float)
        else:
            w = self._L @ self._rng.standard_normal(4)
        x = self._F @ self._x + w
        if self._bounds is not None:
            x = reflect_into_area(x, self._bounds)
        self._x = x
        self._slot += 1
        return self._x.copy()


class ScriptedTarget:
    """A target flying a polyline through waypoints at constant speed (deterministic).

    waypoints_xy_m [P, 2] (P >= 1), the first being the position at slot 0; speed_mps > 0;
    dt_s: slot length. With loop=True the path closes back to the first waypoint and repeats;
    otherwise the target stops (velocity 0) at the last waypoint. Waypoints must lie in the area
    when bounds_m is given (the path then never leaves it).
    """

    def __init__(
        self,
        waypoints_xy_m: Sequence[Sequence[float]] | FloatArray,
        speed_mps: float,
        dt_s: float,
        *,
        loop: bool = False,
        bounds_m: FloatArray | None = None,
    ) -> None:
        wp = np.asarray(waypoints_xy_m, dtype=float)
        if wp.ndim != 2 or wp.shape[1] != 2 or wp.shape[0] < 1 or not np.all(np.isfinite(wp)):
            raise ValueError(f"waypoints_xy_m must be [P, 2] finite, got shape {wp.shape}")
        if not speed_mps > 0 or not dt_s > 0:
            raise ValueError(f"speed_mps and dt_s must be > 0, got {speed_mps}, {dt_s}")
        if bounds_m is not None:
            b = np.asarray(bounds_m, dtype=float)
            if np.any(wp < 0) or np.any(wp > b):
                raise ValueError(f"waypoints_xy_m leave the area {b.tolist()}")
        if loop and wp.shape[0] > 1:
            wp = np.vstack([wp, wp[:1]])
        self._wp = wp
        seg = np.diff(wp, axis=0)
        self._seg_len = np.linalg.norm(seg, axis=1)
        self._cum = np.concatenate([[0.0], np.cumsum(self._seg_len)])
        self._speed = float(speed_mps)
        self._dt = float(dt_s)
        self._loop = loop
        self._slot = 0

    @property
    def length_m(self) -> float:
        """Total length of the path (one lap when looping)."""
        return float(self._cum[-1])

    def state_at(self, t_s: float) -> FloatArray:
        """[x, y, vx, vy] at t_s seconds after slot 0."""
        total = self.length_m
        s = self._speed * max(t_s, 0.0)
        if total == 0.0:
            return np.array([*self._wp[0], 0.0, 0.0])
        if self._loop:
            s = math.fmod(s, total)
        elif s >= total:
            return np.array([*self._wp[-1], 0.0, 0.0])
        i = int(np.searchsorted(self._cum, s, side="right") - 1)
        i = min(max(i, 0), len(self._seg_len) - 1)
        while self._seg_len[i] == 0.0 and i + 1 < len(self._seg_len):
            i += 1
        u = (self._wp[i + 1] - self._wp[i]) / self._seg_len[i]
        p = self._wp[i] + u * (s - self._cum[i])
        return np.array([p[0], p[1], *(self._speed * u)])

    @property
    def state(self) -> FloatArray:
        """State at the current slot."""
        return self.state_at(self._slot * self._dt)

    @property
    def slot(self) -> int:
        """Index of the current slot."""
        return self._slot

    def advance(self) -> FloatArray:
        """Move one slot along the path and return the new state [4]."""
        self._slot += 1
        return self.state
