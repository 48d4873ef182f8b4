"""AUTO.RTL as PX4's navigator flies it for a multirotor (pure: no I/O).

PX4's direct return (src/modules/navigator/rtl_direct.cpp): climb to the return altitude
(RTL_RETURN_ALT above home, or stay at the current altitude when already higher), fly home at
the cruise speed (MPC_XY_CRUISE) at that altitude, descend to RTL_DESCEND_ALT, wait
RTL_LAND_DELAY seconds, land at home. The vehicle then disarms after COM_DISARM_LAND (the flight
logic's auto-disarm). Heights are above home (the arming position); frames local NED, m.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from enum import Enum

import numpy as np

from isac_mission.types import FloatArray
from sim.autopilot.guidance import Guidance, goto, horizontal_distance_m
from sim.vehicle import VehicleState

logger = logging.getLogger(__name__)

ALT_REACHED_M = 0.5
"""An altitude is reached within this, m (PX4 NAV_MC_ALT_RAD is 0.8)."""
HOME_REACHED_M = 1.0
"""Home is reached horizontally within this, m."""


class RtlPhase(Enum):
    """The legs of a return, in order."""

    CLIMB = "climb"
    RETURN = "return"
    DESCEND = "descend"
    LOITER = "loiter"
    LAND = "land"


@dataclass
class Rtl:
    """One return in progress.

    Attributes:
        home_ned_m: (3,) home (where the vehicle armed), NED m.
        start_xy_ned_m: (2,) where the climb happens (the stopping point at entry), NED m.
        return_down_m: NED down of the return altitude, m.
        descend_down_m: NED down of RTL_DESCEND_ALT over home, m.
        land_delay_s: RTL_LAND_DELAY, s (< 0: hover over home for ever).
        cruise_mps: Horizontal speed of the return leg, m/s.
        phase: The current leg.
        loiter_since_s: Simulation time the LOITER leg began, s.
    """

    home_ned_m: FloatArray
    start_xy_ned_m: FloatArray
    return_down_m: float
    descend_down_m: float
    land_delay_s: float
    cruise_mps: float
    phase: RtlPhase = RtlPhase.CLIMB
    loiter_since_s: float = 0.0

    @classmethod
    def start(
        cls,
        stop_ned_m: FloatArray,
        home_ned_m: FloatArray,
        return_alt_m: float,
        descend_alt_m: float,
        land_delay_s: float,
        cruise_mps: float,
    ) -> Rtl:
        """A return from the stopping point `stop_ned_m` (3,) to `home_ned_m` (3,): return
        altitude max(RTL_RETURN_ALT, current height above home), descent to
        min(RTL_DESCEND_ALT, return altitude)."""
        home_down = float(home_ned_m[2])
        height_m = home_down - float(stop_ned_m[2])
        return_h = max(return_alt_m, height_m)
        descend_h = min(descend_alt_m, return_h)
        return cls(
            home_ned_m=np.array(home_ned_m, dtype=float),
            start_xy_ned_m=np.array(stop_ned_m[:2], dtype=float),
            return_down_m=home_down - return_h,
            descend_down_m=home_down - descend_h,
            land_delay_s=land_delay_s,
            cruise_mps=cruise_mps,
        )

    def guidance(self, v: VehicleState, now_s: float) -> Guidance | None:
        """This step's guidance, advancing the legs; None in the LAND leg (the caller lands
        over `home_ned_m`)."""
        p = v.position_ned_m
        if self.phase is RtlPhase.CLIMB:
            if abs(p[2] - self.return_down_m) < ALT_REACHED_M:
                self._next(RtlPhase.RETURN)
            else:
                xy = self.start_xy_ned_m
                return goto(np.array([xy[0], xy[1], self.return_down_m]), None)
        if self.phase is RtlPhase.RETURN:
            if horizontal_distance_m(p, self.home_ned_m) < HOME_REACHED_M:
                self._next(RtlPhase.DESCEND)
            else:
                h = self.home_ned_m
                return goto(np.array([h[0], h[1], self.return_down_m]), self.cruise_mps)
        if self.phase is RtlPhase.DESCEND:
            if p[2] > self.descend_down_m - ALT_REACHED_M:
                self._next(RtlPhase.LOITER)
                self.loiter_since_s = now_s
            else:
                h = self.home_ned_m
                return goto(np.array([h[0], h[1], self.descend_down_m]), None)
        if self.phase is RtlPhase.LOITER:
            if self.land_delay_s >= 0 and now_s - self.loiter_since_s >= self.land_delay_s:
                self._next(RtlPhase.LAND)
            else:
                h = self.home_ned_m
                return goto(np.array([h[0], h[1], self.descend_down_m]), None)
        return None

    def _next(self, phase: RtlPhase) -> None:
        logger.info("RTL: %s -> %s", self.phase.value, phase.value)
        self.phase = phase
