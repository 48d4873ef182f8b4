"""Safety counts of a live run from the bus: telemetry samples closer than D_s to the true target
or to another UAV (the issue's "Safety" target), counted online with bounded memory.

Every telemetry sample of the mission (stamped with a slot 0..N-1, at or after slot 0's truth) is
checked, in the horizontal plane (the constraints 14i and 14j are planar; the UAVs fly at H):
- against the true target at t (every target in the scene, on a multi-target mission: the
  nearest), linearly interpolated between the truths of the slots around t (the world publishes
  the truth once per slot; the interpolation is within a dt^2 / 8 of the path: 0.5 m at
  4 m/s^2), so a sample waits for the truth of the end of its slot;
- against every other UAV at t: that UAV's latest sample moved on with its velocity to t.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from isac_mission.types import FloatArray
from isac_mission.wire import TelemetryMsg, TruthMsg, TruthSetMsg


@dataclass(frozen=True)
class ProximityEvent:
    """One telemetry sample closer than D_s: UAV `uav` at simulation time t_s (s, stamped with
    `slot`) was distance_m (m) from the true target (`other` -1) or from UAV `other`, whose
    latest sample, moved on with its velocity, was age_s (s) old (0 for the target)."""

    slot: int
    t_s: float
    uav: int
    other: int
    distance_m: float
    age_s: float


EVENTS_KEPT = 500
"""Samples under D_s kept with their details (the counts go on past it)."""


@dataclass
class ProximityCounts:
    """Samples checked, those closer than D_s (m) to the true target and to another UAV, the
    nearest distances seen (m; inf before any sample) and the first EVENTS_KEPT samples under
    D_s."""

    samples: int = 0
    target_under_d_safe: int = 0
    uav_under_d_safe: int = 0
    nearest_target_m: float = math.inf
    nearest_uav_m: float = math.inf
    events: list[ProximityEvent] = field(default_factory=list)

    def record(self, event: ProximityEvent) -> None:
        if len(self.events) < EVENTS_KEPT:
            self.events.append(event)

    def render(self, d_safe_m: float) -> str:
        return (
            f"telemetry samples {self.samples}: {self.target_under_d_safe} closer than "
            f"D_s = {d_safe_m:g} m to the true target (nearest {self.nearest_target_m:.1f} m), "
            f"{self.uav_under_d_safe} closer than D_s to another UAV "
            f"(nearest {self.nearest_uav_m:.1f} m)"
        )


@dataclass
class ProximityCounter:
    """Feed it the bus's telemetry and truth messages in arrival order (copies and repeated
    instants are judged once); read `counts`.
    d_safe_m: D_s (m), the scenario's true one, not the planner's."""

    d_safe_m: float
    last_slot: int
    """N: samples stamped with slot N or later (after the mission's last slot) are not counted."""
    counts: ProximityCounts = field(default_factory=ProximityCounts)
    _first: tuple[float, FloatArray] | None = None
    _truths: list[tuple[float, FloatArray]] = field(default_factory=list)
    _waiting: list[tuple[float, int, int, FloatArray]] = field(default_factory=list)
    _latest: dict[int, tuple[float, FloatArray, FloatArray]] = field(default_factory=dict)

    def on_telemetry(self, msg: TelemetryMsg) -> None:
        last = self._latest.get(msg.uav)
        if last is not None and msg.t_s <= last[0]:
            return  # a copy (another route), or a sample of a held clock: the same instant
        if (
            msg.slot < 0
            or msg.slot >= self.last_slot
            or self._first is None
            or msg.t_s < self._first[0]
        ):
            # Before the mission (take-off, the flight to the start points) or after it: not
            # counted.
            self._latest[msg.uav] = (
                msg.t_s,
                np.asarray(msg.position_xy_m, dtype=float),
                np.asarray(msg.velocity_xy_mps, dtype=float),
            )
            return
        xy = np.asarray(msg.position_xy_m, dtype=float)
        others = [
            (float(np.linalg.norm(xy - (xy_o + v_o * (msg.t_s - t_o)))), other, msg.t_s - t_o)
            for other, (t_o, xy_o, v_o) in self._latest.items()
            if other != msg.uav
        ]
        if others:
            nearest, other, age_s = min(others)
            self.counts.nearest_uav_m = min(self.counts.nearest_uav_m, nearest)
            if nearest < self.d_safe_m:
                self.counts.uav_under_d_safe += 1  # a sample counts once
                self.counts.record(
                    ProximityEvent(msg.slot, msg.t_s, msg.uav, other, nearest, age_s)
                )
        self._latest[msg.uav] = (msg.t_s, xy, np.asarray(msg.velocity_xy_mps, dtype=float))
        self._waiting.append((msg.t_s, msg.slot, msg.uav, xy))
        self._judge()

    def on_truth(self, msg: TruthMsg | TruthSetMsg) -> None:
        if any(t == msg.t_s for t, _ in self._truths):
            return  # a copy
        states = msg.states if isinstance(msg, TruthSetMsg) else msg.target_states
        self._truths.append((msg.t_s, np.asarray(states, dtype=float)[:, :2]))
        self._truths.sort(key=lambda tp: tp[0])
        del self._truths[:-TRUTHS_KEPT]
        self._judge()

    def _judge(self) -> None:
        """Check every waiting sample that a truth at or after its time now brackets."""
        if self._first is None and self._truths:
            self._first = self._truths[0]
        if not self._truths:
            return
        t_last = self._truths[-1][0]
        keep: list[tuple[float, int, int, FloatArray]] = []
        for waiting in self._waiting:
            t, slot, uav, xy = waiting
            if t > t_last:
                keep.append(waiting)  # waits for the next truth
                continue
            in_scene = self._target_at(t)
            in_scene = in_scene[np.all(np.isfinite(in_scene), axis=1)]
            if len(in_scene) == 0:
                continue  # no target in the scene at t
            d = float(np.min(np.linalg.norm(xy - in_scene, axis=1)))
            self.counts.samples += 1
            self.counts.nearest_target_m = min(self.counts.nearest_target_m, d)
            if d < self.d_safe_m:
                self.counts.target_under_d_safe += 1
                self.counts.record(ProximityEvent(slot, t, uav, -1, d, 0.0))
        self._waiting = keep

    def _target_at(self, t: float) -> FloatArray:
        """[T, 2]: every target's true position at t (NaN: not in the scene at one of the two
        truths), linearly between the kept truths around t (the earliest kept one for a sample
        older than all of them)."""
        truths = self._truths
        for (t0, p0), (t1, p1) in itertools.pairwise(truths):
            if t <= t1:
                w = 0.0 if t1 <= t0 else min(max((t - t0) / (t1 - t0), 0.0), 1.0)
                return p0 + w * (p1 - p0)
        return truths[-1][1] if t >= truths[-1][0] else truths[0][1]


TRUTHS_KEPT = 4
"""Truths kept for the interpolation: a sample that arrives a few slots late is still judged
against the target at its own time."""
