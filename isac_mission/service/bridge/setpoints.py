"""A vehicle's setpoint stream: the leg being flown and SET_POSITION_TARGET_LOCAL_NED out.

The setpoint is the current leg (legs.py) sampled `setpoint_lead_s` ahead of now, to make up for
the setpoint's hold time and the link latency, and sent in the vehicle's local NED frame with
the leg's velocity as feed-forward. A new goal starts its leg where the setpoint is, so the
velocity feed-forward is continuous across slots when the plan is. The stream only sends while
started (`start`/`stop`), once the vehicle's address is known and a mission altitude is set.
While `follow_vehicle` is on (the vehicle is not the service's: an operator's mode, its own
failsafe, an operator's hold), the setpoint is the vehicle's own position, altitude included, at
rest, so that a plain switch back to OFFBOARD leaves it where it is; goals are still kept.

The stream notes its own gaps (the uplink side of link supervision, supervision.py): how long it
has been silent while started (`silent_s`) and the longest gap between two setpoints sent since
the last look (`take_gap_s`), in simulation seconds as the vehicle counts them (the larger of the
simulation time and the wall time x speed that passed: a stalled process, or a simulation that
catches up after a pause, runs the vehicle's clock on while no setpoint goes out).
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Final

import numpy as np

from isac_mission.frames import scenario_to_ned, scenario_to_ned_velocity
from isac_mission.mavwire.builders import position_target_local_ned
from isac_mission.mavwire.link import MavlinkLink
from isac_mission.mavwire.status import VehicleStatus
from isac_mission.service.bridge.counters import BridgeCounters
from isac_mission.service.bridge.legs import CarrotLeg, HermiteLeg, hermite_leg, plan_leg
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.telemetry import vehicle_xy
from isac_mission.timebase import SimTime
from isac_mission.types import FloatArray

TIMESTAMPS_KEPT: Final = 1024
"""How many setpoint wall times, and first-setpoint times of plans, a bridge keeps for the
timing figures: the latest ones, so that a long mission's memory does not grow with it
(docs/reliability.md, "Soak")."""


@dataclass
class Goal:
    """Where the setpoint is heading (scenario plane, m), by when (simulation s), how fast, and
    the plan's velocity there (m/s; None: not planned)."""

    xy_m: FloatArray
    arrive_by_s: float | None
    max_speed_mps: float
    v_mps: FloatArray | None = None


class SetpointStream:
    """The leg, the goal and the setpoint stream of one vehicle's bridge.

    Args:
        settings: The bridge's settings (origin, V_max, lead, feed-forward, yaw).
        time: Simulation time.
        link: The vehicle's MAVLink link (status for the vehicle's position, send).
        counters: The bridge's counters (setpoints_sent).
    """

    def __init__(
        self, settings: BridgeSettings, time: SimTime, link: MavlinkLink, counters: BridgeCounters
    ) -> None:
        self.settings = settings
        self.time = time
        self.link = link
        self.counters = counters
        self.leg: CarrotLeg | HermiteLeg | None = None
        self.goal: Goal | None = None
        self.altitude_m: float | None = None
        """The mission altitude the setpoints fly at, m (None: no setpoint is sent)."""
        self.since_s = 0.0
        """Simulation time at which the stream (last) started, s."""
        self.plan_slot = -1
        """The latest plan slot fed to the bridge (-1: none)."""
        self.setpoint_wall_s: deque[float] = deque(maxlen=TIMESTAMPS_KEPT)
        """Wall times (time.monotonic) of the stream's latest periodic setpoints (at most
        TIMESTAMPS_KEPT), for jitter figures."""
        self.first_setpoint_wall_s: dict[int, float] = {}
        """Plan slot -> wall time of the first setpoint sent for it, for the latest
        TIMESTAMPS_KEPT plans (latency figures)."""
        self._origin = np.array(settings.origin_xy_m, dtype=float)
        self._streaming = False
        self.follow_vehicle = False
        """Send the vehicle's own position instead of the leg (see the module doc)."""
        self._sent_s: float | None = None
        """Simulation time of the latest setpoint sent since the stream started (None: none)."""
        self._sent_wall_s = 0.0
        self._longest_gap_s = 0.0

    @property
    def streaming(self) -> bool:
        """True while setpoints are being streamed."""
        return self._streaming

    def carrot_time_s(self) -> float:
        """The time the carrot is sampled at: now + setpoint_lead_s (simulation s)."""
        return self.time.now_s() + self.settings.setpoint_lead_s

    def setpoint(self) -> tuple[FloatArray, FloatArray] | None:
        """The setpoint now (the carrot `setpoint_lead_s` ahead): scenario-plane position
        [2], m, and velocity [2], m/s."""
        return None if self.leg is None else self.leg.sample(self.carrot_time_s())

    def hover(self, xy_m: FloatArray) -> None:
        """Carrot and goal at `xy_m`, at rest."""
        self.leg = plan_leg(xy_m, xy_m, self.carrot_time_s(), None, self.settings.v_max_mps)
        self.goal = Goal(xy_m.copy(), None, self.settings.v_max_mps)

    def set_goal(
        self,
        xy_m: FloatArray,
        arrive_by_s: float | None,
        max_speed_mps: float,
        v_mps: FloatArray | None = None,
    ) -> None:
        """A new leg to `xy_m` [2] by `arrive_by_s` from where the setpoint is (or the vehicle,
        before any leg): smooth when planned (`smooth_legs`), ending at the plan's velocity
        `v_mps` [2] when given (else at the leg's mean velocity) and coasting at it for
        `leg_coast_s` past the deadline; else a carrot.

        A smooth leg that follows one still coasting past its deadline starts at that deadline,
        from its goal and end velocity: the planned leg of the next slot, flown on the plan's
        own timeline however late in the coast the plan came (in lockstep the bridge's clock
        runs on up to ClockSimTime.max_extrapolation_s while the world holds at the boundary;
        starting the leg where the setpoint had coasted to, as earlier, put it metres ahead of
        the frozen vehicle and compressed the leg)."""
        now = self.carrot_time_s()
        start_s, here_v = now, np.zeros(2)
        here: FloatArray | None = None
        prev = self.leg
        smooth = self.settings.smooth_legs and arrive_by_s is not None
        if (
            smooth
            and isinstance(prev, HermiteLeg)
            and prev.end_s <= now <= prev.end_s + prev.coast_s
            and arrive_by_s is not None
            and arrive_by_s - prev.end_s > 0.05
        ):
            start_s, here, here_v = prev.end_s, prev.goal_xy_m, prev.goal_v_mps
        elif prev is not None:
            here, here_v = prev.sample(now)
        else:
            here = vehicle_xy(self.link.status(), self._origin)
        if here is None:
            here = xy_m
        if smooth and arrive_by_s is not None and arrive_by_s - start_s > 0.05:
            self.leg = hermite_leg(
                here,
                here_v,
                xy_m,
                start_s,
                arrive_by_s,
                max_speed_mps,
                goal_v_mps=v_mps,
                coast_s=self.settings.leg_coast_s,
            )
        else:
            self.leg = plan_leg(here, xy_m, now, arrive_by_s, max_speed_mps)
        self.goal = Goal(xy_m.copy(), arrive_by_s, max_speed_mps, v_mps)

    def reanchor(self, status: VehicleStatus) -> None:
        """Restart the carrot at the vehicle, toward the current goal; hover there instead when
        the goal's deadline has passed (a plan of before a loss or a stall is not flown after)."""
        here = vehicle_xy(status, self._origin)
        goal = self.goal
        if here is None or goal is None:
            return
        if goal.arrive_by_s is not None and goal.arrive_by_s < self.time.now_s():
            self.hover(here)
            return
        self.leg = plan_leg(
            here, goal.xy_m, self.carrot_time_s(), goal.arrive_by_s, goal.max_speed_mps
        )

    def start(self) -> None:
        """Start streaming (noting when, unless already streaming)."""
        if not self._streaming:
            self._streaming = True
            self.since_s = self.time.now_s()
            self._sent_s = None  # a new stream: no gap since the last one

    def stop(self) -> None:
        """Stop streaming."""
        self._streaming = False
        self._sent_s = None

    def _since_sent_s(self) -> float:
        """Simulation seconds since the latest setpoint sent (0 before the first): the larger of
        the simulation time and the wall time x speed that passed (see the module doc)."""
        if self._sent_s is None:
            return 0.0
        gap_s = self.time.now_s() - self._sent_s
        speed = self.time.speed
        if math.isfinite(speed):
            gap_s = max(gap_s, (time.monotonic() - self._sent_wall_s) * speed)
        return gap_s

    def silent_s(self) -> float:
        """How long the started stream has sent nothing, simulation s (0 while stopped)."""
        return self._since_sent_s() if self._streaming else 0.0

    def take_gap_s(self) -> float:
        """The longest gap between two setpoints sent since the last call, simulation s (0:
        none); resets it."""
        gap_s, self._longest_gap_s = self._longest_gap_s, 0.0
        return gap_s

    def send(self, periodic: bool = True) -> None:
        """Send the current setpoint; `periodic` marks the stream's own ticks (whose wall times
        are kept for the jitter figures) as opposed to the immediate send of a new plan."""
        if not self._streaming or self.leg is None or self.altitude_m is None:
            return
        if self.link.vehicle_address is None:
            return
        now = self.time.now_s()
        here = self.link.status().position_ned_m if self.follow_vehicle else None
        if here is not None:
            msg = position_target_local_ned(
                self.link.target, here, None, self.settings.yaw_rad, time_boot_ms=round(now * 1e3)
            )
        else:
            xy, v = self.leg.sample(self.carrot_time_s())
            msg = position_target_local_ned(
                self.link.target,
                scenario_to_ned(xy, self.altitude_m, self._origin),
                scenario_to_ned_velocity(v) if self.settings.velocity_feed_forward else None,
                self.settings.yaw_rad,
                time_boot_ms=round(now * 1000.0),
            )
        if self.link.send(msg):
            self.counters.setpoints_sent += 1
            self._longest_gap_s = max(self._longest_gap_s, self._since_sent_s())
            wall = time.monotonic()
            self._sent_s, self._sent_wall_s = now, wall
            if periodic:
                self.setpoint_wall_s.append(wall)
            firsts = self.first_setpoint_wall_s
            if self.plan_slot >= 0 and self.plan_slot not in firsts:
                firsts[self.plan_slot] = wall
                if len(firsts) > TIMESTAMPS_KEPT:
                    del firsts[next(iter(firsts))]  # the oldest plan (insertion order)
