"""AUTO.MISSION: flying the uploaded plan item by item (pure: no I/O).

`MissionRunner` holds the plan (`mission_plan.MissionItem`s), the current item and what the
ground must hear: `events` collects ("current", seq) when the current item changes and
("reached", seq) when one is reached, which the endpoint turns into MISSION_CURRENT and
MISSION_ITEM_REACHED. How each item is flown: `mission_plan`'s docstring. After the last item the
vehicle holds where it is (still in MISSION, the mission complete), unless the last was a LAND.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from isac_mission.mavwire.modes import FlightMode
from isac_mission.types import FloatArray
from sim.autopilot.guidance import Guidance, goto, horizontal_distance_m
from sim.autopilot.mission_plan import (
    CMD_CHANGE_SPEED,
    CMD_LAND,
    CMD_RTL,
    CMD_TAKEOFF,
    RELATIVE_FRAMES,
    MissionItem,
)

if TYPE_CHECKING:
    from sim.autopilot.flight import FlightLogic

logger = logging.getLogger(__name__)

LAND_OVER_M = 1.0
"""A LAND item descends once within this of its position horizontally, m."""


class MissionRunner:
    """The plan and its progress; `guidance` flies the current item."""

    def __init__(self) -> None:
        self.items: list[MissionItem] = []
        self.current = 0
        self.finished = False
        """The last item was reached (MISSION_CURRENT reports the mission complete)."""
        self.landing = False
        """Descending in a LAND item."""
        self.events: list[tuple[str, int]] = []
        """("current", seq) and ("reached", seq) not yet told to the ground."""
        self._speed_mps: float | None = None
        self._item_start_ned = np.zeros(3)
        self._hold_ned: FloatArray | None = None
        self._wait_until_s: float | None = None

    def set_plan(self, items: list[MissionItem]) -> None:
        """A new plan (an upload, or [] to clear): current item 0, not started."""
        self.items = list(items)
        self.set_current(0)

    def set_current(self, seq: int) -> None:
        """Make item `seq` current (MISSION_SET_CURRENT); the caller checked the range."""
        self.current = seq
        self.finished = False
        self.landing = False
        self._wait_until_s = None
        self._hold_ned = None
        self.events.append(("current", seq))

    def resume(self, f: FlightLogic, stop_ned_m: FloatArray) -> None:
        """Entering MISSION at the stopping point `stop_ned_m` (3,): a complete mission starts
        again from item 0, otherwise the current item resumes."""
        if self.finished:
            self.set_current(0)
        self._item_start_ned = np.array(stop_ned_m, dtype=float)
        self._speed_mps = None
        self._hold_ned = None

    def target_ned(self, f: FlightLogic, item: MissionItem) -> FloatArray:
        """(3,) local NED of a NAV item: its lat/lon (or where the item began, without one) at
        its altitude (above home in the relative frames, AMSL otherwise)."""
        if item.has_position:
            xy_ned = f.geodetic_to_ned(item.lat_deg, item.lon_deg, f.home_amsl_m())[:2]
        else:
            xy_ned = self._item_start_ned[:2]
        if item.frame in RELATIVE_FRAMES:
            down = float(f.home_ned[2]) - item.z
        else:
            down = float(f.limits.ground_down_m) - (item.z - f.settings.geo_origin.alt_amsl_m)
        return np.array([xy_ned[0], xy_ned[1], down])

    def _advance(self, f: FlightLogic) -> None:
        self.events.append(("reached", self.current))
        logger.info("vehicle %d: mission item %d reached", f.system_id, self.current)
        self._wait_until_s = None
        self._item_start_ned = f.vehicle.position_ned_m.copy()
        if self.current + 1 < len(self.items):
            self.current += 1
            self.events.append(("current", self.current))
        else:
            self.finished = True
            self._hold_ned = f.vehicle.position_ned_m.copy()
            logger.info("vehicle %d: mission complete", f.system_id)

    def touched_down(self, f: FlightLogic) -> None:
        """The land detector saw a touchdown in MISSION: a LAND item is reached."""
        if self.landing and not self.finished:
            self.landing = False
            self._advance(f)
            self.finished = True
            self._hold_ned = None

    def guidance(self, f: FlightLogic) -> Guidance | None:
        """This step's guidance for the armed vehicle in MISSION (None: motors idle)."""
        for _ in range(len(self.items) + 1):
            if self.finished or not self.items:
                if f.landed or self._hold_ned is None:
                    return None
                return goto(self._hold_ned, None)
            item = self.items[self.current]
            if item.command == CMD_CHANGE_SPEED:
                self._speed_mps = item.param2 if item.param2 > 0 else self._speed_mps
                self._advance(f)
                continue
            if item.command == CMD_RTL:
                self._advance(f)
                f.set_mode(FlightMode.RTL, "mission: return to launch")
                return None
            guidance = self._fly(f, item)
            if guidance is not None:
                return guidance
        return None

    def _fly(self, f: FlightLogic, item: MissionItem) -> Guidance | None:
        """Guidance for NAV item `item`, or None once it is reached (the caller moves on)."""
        target = self.target_ned(f, item)
        p = f.vehicle.position_ned_m
        speed = self._speed_mps or f.cruise_mps()
        alt_ok = abs(float(p[2] - target[2])) < f.param("NAV_MC_ALT_RAD")
        if item.command == CMD_TAKEOFF:
            if alt_ok and not f.landed:
                self._advance(f)
                return None
            return goto(target, None)
        if item.command == CMD_LAND:
            if self.landing or horizontal_distance_m(p, target) < LAND_OVER_M:
                self.landing = True
                return f.land_here(target[:2]) if not f.landed else None
            return goto(np.array([target[0], target[1], p[2]]), speed)
        radius = item.param2 if item.param2 > 0 else f.param("NAV_ACC_RAD")
        if alt_ok and horizontal_distance_m(p, target) < radius:
            if self._wait_until_s is None:
                self._wait_until_s = f.now_s + item.param1
            if f.now_s >= self._wait_until_s:
                self._advance(f)
                return None
        yaw = math.radians(item.param4) if math.isfinite(item.param4) else math.nan
        return goto(target, speed, yaw)
