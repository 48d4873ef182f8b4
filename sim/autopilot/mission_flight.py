"""AUTO.MISSION: flying the uploaded plan item by item (pure: no I/O).

`MissionRunner` holds the plan (`mission_plan.MissionItem`s), the current item and what the
ground must hear: `events` collects ("current", seq) when the current item changes and
("reached", seq) when one is reached, which the endpoint turns into MISSION_CURRENT and
MISSION_ITEM_REACHED. At each step `MissionRunner.fly` takes what it reads of the vehicle (a
`MissionVehicle`), advances the plan and returns a `MissionDecision`: the guidance to track,
where to land, or the mode to leave for (an RTL item); the flight logic applies it. How each
item is flown: `mission_plan`'s docstring. After the last item the vehicle holds where it is
(still in MISSION, the mission complete), unless the last was a LAND.

Frames: local NED (north, east, down), m, around the scenario-plane point `origin_xy_m`
(`isac_mission.frames`); times are simulation time, s.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from isac_mission.frames import GeoPoint, geodetic_to_scenario, scenario_to_ned
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

logger = logging.getLogger(__name__)

LAND_OVER_M = 1.0
"""A LAND item descends once within this of its position horizontally, m."""


@dataclass(frozen=True)
class MissionFrame:
    """Where a plan's coordinates are in the vehicle's local NED frame.

    Attributes:
        geo_origin: Geodetic position of the scenario-plane origin (altitude AMSL of the ground).
        origin_xy_m: (2,) scenario-plane point of the local NED origin, m.
        ground_down_m: NED down of the ground, m.
    """

    geo_origin: GeoPoint
    origin_xy_m: FloatArray
    ground_down_m: float

    def target_ned(
        self, item: MissionItem, start_ned_m: FloatArray, home_ned_m: FloatArray
    ) -> FloatArray:
        """(3,) local NED of NAV item `item`, m: its lat/lon (or, without one, `start_ned_m`
        (3,), where the item began) at its altitude (above home `home_ned_m` (3,) in the
        relative frames, AMSL otherwise)."""
        if item.has_position:
            o = self.geo_origin
            xy, _ = geodetic_to_scenario(GeoPoint(item.lat_deg, item.lon_deg, o.alt_amsl_m), o)
            xy_ned = scenario_to_ned(xy, 0.0, self.origin_xy_m)[:2]
        else:
            xy_ned = start_ned_m[:2]
        if item.frame in RELATIVE_FRAMES:
            down = float(home_ned_m[2]) - item.z
        else:
            down = float(self.ground_down_m) - (item.z - self.geo_origin.alt_amsl_m)
        return np.array([xy_ned[0], xy_ned[1], down])


@dataclass(frozen=True)
class MissionVehicle:
    """What mission flight reads of the vehicle at one step.

    Attributes:
        now_s: Simulation time, s.
        position_ned_m: (3,) local NED position, m.
        landed: On the ground (land detector).
        home_ned_m: (3,) home (where the vehicle armed last), local NED, m.
        cruise_mps: MPC_XY_CRUISE, the speed until a DO_CHANGE_SPEED, m/s.
        acceptance_radius_m: NAV_ACC_RAD, a waypoint's default acceptance radius, m.
        altitude_radius_m: NAV_MC_ALT_RAD, how near an item's altitude reaches it, m.
    """

    now_s: float
    position_ned_m: FloatArray
    landed: bool
    home_ned_m: FloatArray
    cruise_mps: float
    acceptance_radius_m: float
    altitude_radius_m: float


@dataclass(frozen=True)
class MissionDecision:
    """What MISSION asks of the flight logic this step: leave for `mode` (then nothing else),
    land over `land_xy_ned_m`, track `guidance`, or, with none of them, idle the motors.

    Attributes:
        guidance: The guidance to track, or None.
        land_xy_ned_m: (2,) local NED point to descend over (LAND's profile), m, or None.
        mode: The mode to switch to (an RTL item), or None.
        reason: Why (of the mode change, for the log).
    """

    guidance: Guidance | None = None
    land_xy_ned_m: FloatArray | None = None
    mode: FlightMode | None = None
    reason: str = ""


IDLE = MissionDecision()
"""Nothing to track: motors idle (on the ground, or a mission complete without a hold)."""


class MissionRunner:
    """The plan and its progress; `fly` flies the current item.

    Args:
        frame: Where the plan's coordinates are in the local NED frame.
        system_id: The vehicle's MAVLink system id (for the log).
    """

    def __init__(self, frame: MissionFrame, system_id: int = 0) -> None:
        self.frame = frame
        self.system_id = system_id
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

    def resume(self, stop_ned_m: FloatArray) -> None:
        """Entering MISSION at the stopping point `stop_ned_m` (3,): a complete mission starts
        again from item 0, otherwise the current item resumes."""
        if self.finished:
            self.set_current(0)
        self._item_start_ned = np.array(stop_ned_m, dtype=float)
        self._speed_mps = None
        self._hold_ned = None

    def target_ned(self, item: MissionItem, home_ned_m: FloatArray) -> FloatArray:
        """(3,) local NED of NAV item `item` begun where the current item began (`MissionFrame.
        target_ned`), with home at `home_ned_m` (3,), m."""
        return self.frame.target_ned(item, self._item_start_ned, home_ned_m)

    def _advance(self, position_ned_m: FloatArray) -> None:
        """The current item is reached at `position_ned_m` (3,): on to the next, or done."""
        self.events.append(("reached", self.current))
        logger.info("vehicle %d: mission item %d reached", self.system_id, self.current)
        self._wait_until_s = None
        self._item_start_ned = position_ned_m.copy()
        if self.current + 1 < len(self.items):
            self.current += 1
            self.events.append(("current", self.current))
        else:
            self.finished = True
            self._hold_ned = position_ned_m.copy()
            logger.info("vehicle %d: mission complete", self.system_id)

    def touched_down(self, position_ned_m: FloatArray) -> None:
        """The land detector saw a touchdown in MISSION at `position_ned_m` (3,): a LAND item
        is reached."""
        if self.landing and not self.finished:
            self.landing = False
            self._advance(position_ned_m)
            self.finished = True
            self._hold_ned = None

    def fly(self, v: MissionVehicle) -> MissionDecision:
        """This step's decision for the armed vehicle `v` in MISSION, advancing the plan past
        the items reached and the DO items."""
        for _ in range(len(self.items) + 1):
            if self.finished or not self.items:
                if v.landed or self._hold_ned is None:
                    return IDLE
                return MissionDecision(guidance=goto(self._hold_ned, None))
            item = self.items[self.current]
            if item.command == CMD_CHANGE_SPEED:
                self._speed_mps = item.param2 if item.param2 > 0 else self._speed_mps
                self._advance(v.position_ned_m)
                continue
            if item.command == CMD_RTL:
                self._advance(v.position_ned_m)
                return MissionDecision(mode=FlightMode.RTL, reason="mission: return to launch")
            decision = self._fly_item(item, v)
            if decision is not None:
                return decision
        return IDLE

    def _fly_item(self, item: MissionItem, v: MissionVehicle) -> MissionDecision | None:
        """The decision for NAV item `item`, or None once it is reached (the caller moves on)."""
        target = self.target_ned(item, v.home_ned_m)
        p = v.position_ned_m
        speed = self._speed_mps or v.cruise_mps
        alt_ok = abs(float(p[2] - target[2])) < v.altitude_radius_m
        if item.command == CMD_TAKEOFF:
            if alt_ok and not v.landed:
                self._advance(p)
                return None
            return MissionDecision(guidance=goto(target, None))
        if item.command == CMD_LAND:
            if self.landing or horizontal_distance_m(p, target) < LAND_OVER_M:
                self.landing = True
                # On the ground the LAND item waits for the land detector (`touched_down`).
                return IDLE if v.landed else MissionDecision(land_xy_ned_m=target[:2])
            return MissionDecision(guidance=goto(np.array([target[0], target[1], p[2]]), speed))
        radius = item.param2 if item.param2 > 0 else v.acceptance_radius_m
        if alt_ok and horizontal_distance_m(p, target) < radius:
            if self._wait_until_s is None:
                self._wait_until_s = v.now_s + item.param1
            if v.now_s >= self._wait_until_s:
                self._advance(p)
                return None
        yaw = math.radians(item.param4) if math.isfinite(item.param4) else math.nan
        return MissionDecision(guidance=goto(target, speed, yaw))
