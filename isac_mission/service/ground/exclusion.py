"""Which vehicles a plan can use: telemetry per vehicle, and the vehicles planned around.

A vehicle whose bridge reports its link lost, or whose telemetry position is older than both
`vehicle_lost_after_s` (simulation) and `vehicle_lost_wall_s` (wall), is excluded: the slot is
planned for the others (planning/fleet.py) and the vehicle holds where it was last seen. So is a
vehicle its bridge reports as not flown by the service (telemetry `override`: an operator's mode
change, the vehicle's own failsafe, landed, killed; docs/service.md, "Operator override"), and one
an operator's `hold` or `land` on `control` took out (`held`, control.py). It is re-admitted once
its link is back, its telemetry fresh, no override or operator hold remains and it is in OFFBOARD
again.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from isac_mission.service.ground.report import GroundReport
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.types import FloatArray
from isac_mission.wire import TelemetryMsg

log = logging.getLogger(__name__)


class VehicleWatch:
    """The last telemetry of every vehicle and the excluded ones, with the reason."""

    def __init__(self, n_uavs: int, settings: GroundSettings, report: GroundReport) -> None:
        self.n_uavs = n_uavs
        self.settings = settings
        self.report = report
        self.telemetry: dict[int, TelemetryMsg] = {}
        self.excluded: dict[int, str] = {}
        """Vehicles planned around, with the reason."""
        self.held: dict[int, str] = {}
        """Vehicles an operator's `hold` or `land` took out of planning, with the reason."""
        self.telemetry_fresh_wall: dict[int, float] = {}
        """Vehicle -> wall time (time.monotonic) its telemetry position last advanced."""
        self.received_wall: dict[int, float] = {}
        """Vehicle -> wall time its last telemetry message arrived."""
        self.seen_ok: set[int] = set()
        """Vehicles reported with a live link at least once: before that, "lost" is no loss (a
        bridge that has not yet heard its vehicle), and the start gate waits (startup.py)."""

    def on_telemetry(self, msg: TelemetryMsg) -> None:
        """Keep a vehicle's newest telemetry (and when its position last advanced)."""
        last = self.telemetry.get(msg.uav)
        if last is None or msg.t_s > last.t_s:
            self.telemetry_fresh_wall[msg.uav] = time.monotonic()
        self.telemetry[msg.uav] = msg
        self.received_wall[msg.uav] = time.monotonic()

    def update(self, t_s: float) -> bool:
        """Exclude and re-admit vehicles at simulation time t_s (see the module doc); True when
        the set changed (each change counted and logged)."""
        now = time.monotonic()
        changed = False
        for m, tel in self.telemetry.items():
            if m not in self.seen_ok and m not in self.excluded:
                if tel.link != "ok":
                    continue
                self.seen_ok.add(m)
            age_s = t_s - tel.t_s
            stale = (
                age_s > self.settings.vehicle_lost_after_s
                and now - self.telemetry_fresh_wall.get(m, now) > self.settings.vehicle_lost_wall_s
            )
            why = self._why_out(m, tel, stale, age_s)
            if why and m not in self.excluded:
                self.excluded[m] = why
                self.report.counters["vehicle exclusions"] += 1
                self.report.last_error = f"vehicle {m}: {why}; planning around it"
                log.warning("vehicle %d: %s; planning the others around it", m, why)
                changed = True
            elif why and self.excluded[m] != why and not why.startswith("telemetry"):
                self.excluded[m] = why  # a new reason (an operator took a lost vehicle, ...)
                log.warning("vehicle %d: still planned around: %s", m, why)
                changed = True
            elif not why and m in self.excluded and tel.mode == "offboard":
                del self.excluded[m]
                self.report.counters["vehicle readmissions"] += 1
                log.warning("vehicle %d: link back and in OFFBOARD; planning it again", m)
                changed = True
        for m, why in self.held.items():  # held before any telemetry
            if m not in self.telemetry and self.excluded.get(m) != why:
                self.excluded[m] = why
                changed = True
        return changed

    def _why_out(self, m: int, tel: TelemetryMsg, stale: bool, age_s: float) -> str:
        """Why vehicle m cannot be planned now ("" when it can)."""
        if tel.link == "lost":
            return "link lost"
        if stale:
            return f"telemetry {age_s:.1f} s old"
        if m in self.held:
            return self.held[m]
        return tel.override

    def override(self, m: int) -> str:
        """Vehicle m's override as its bridge last reported it ("" when flown by the service)."""
        tel = self.telemetry.get(m)
        return "" if tel is None else tel.override

    def airborne(self, m: int) -> bool | None:
        """Vehicle m armed and not landed, as last reported (None: no telemetry yet)."""
        tel = self.telemetry.get(m)
        return None if tel is None else tel.armed and not tel.landed

    def ready(self, m: int, t_s: float, since_wall_s: float) -> bool:
        """Vehicle m can be planned from its telemetry: received after `since_wall_s` (wall),
        over a live link, at most telemetry_max_age_s old at simulation time t_s, not excluded."""
        tel = self.telemetry.get(m)
        return (
            tel is not None
            and m not in self.excluded
            and tel.link == "ok"
            and t_s - tel.t_s <= self.settings.telemetry_max_age_s
            and self.received_wall.get(m, -np.inf) >= since_wall_s
        )

    def exclude(self, m: int, why: str) -> None:
        """Plan around vehicle m (counted, logged) until the re-admission rule takes it back."""
        if m in self.excluded:
            return
        self.excluded[m] = why
        self.report.counters["vehicle exclusions"] += 1
        self.report.last_error = f"vehicle {m}: {why}; planning around it"
        log.warning("vehicle %d: %s; planning the others around it", m, why)

    def positions(self, t_s: float, det_xy: FloatArray | None = None) -> FloatArray:
        """[M, 2] positions (m) at the planning instant t_s (simulation s): telemetry at most
        `telemetry_current_s` old; else det_xy (a slot's detection positions: where each UAV was
        at the boundary), which beats late telemetry (over a radio with 100 ms of latency it is
        0.1-0.2 s old, and planning from it stalled the accelerating vehicles; docs/reliability.md,
        "Lossy, late radio links"); else fresh telemetry; else NaN. An excluded vehicle holds
        where it was last seen."""
        xy = (
            np.array(det_xy, dtype=float)
            if det_xy is not None
            else np.full((self.n_uavs, 2), np.nan)
        )
        for m in range(self.n_uavs):
            tel = self.telemetry.get(m)
            if tel is None:
                continue
            age_s = t_s - tel.t_s
            live = tel.link == "ok" and age_s <= self.settings.telemetry_max_age_s
            measured = bool(np.all(np.isfinite(xy[m])))
            current = age_s <= self.settings.telemetry_current_s
            if (live and (current or not measured)) or m in self.excluded:
                xy[m] = tel.position_xy_m  # an excluded vehicle holds where it was last seen
        return xy

    def velocities(self, t_s: float) -> FloatArray:
        """[M, 2] velocities (m/s) from fresh telemetry (zero where there is none)."""
        v = np.zeros((self.n_uavs, 2))
        for m, tel in self.telemetry.items():
            if tel.link == "ok" and t_s - tel.t_s <= self.settings.telemetry_max_age_s:
                v[m] = tel.velocity_xy_mps
        return v

    def links(self) -> dict[int, str]:
        """Vehicle -> "ok" or "lost", as last reported."""
        return {m: t.link for m, t in self.telemetry.items()}

    def operator_held(self) -> tuple[int, ...]:
        """The excluded vehicles an operator's `hold` or `land` took out (sorted)."""
        return tuple(sorted(m for m in self.excluded if m in self.held))

    def status(self) -> dict[int, str]:
        """Vehicle -> "active" or "excluded: <why>" (for the health message)."""
        return {
            m: f"excluded: {self.excluded[m]}" if m in self.excluded else "active"
            for m in range(self.n_uavs)
        }
