"""Fly a planned trajectory through the bridge's setpoint stream and sim/vehicle.py's controller.

The planned trajectory is a chain of slots: waypoints q_0..q_N and planned velocities v_0..v_N
(scenario plane, m, m/s; v_0 the start velocity), leg n the Hermite leg (q_{n-1}, v_{n-1}) ->
(q_n, v_n) over ((n-1) dt, n dt] (model/vehicle.py). It is flown as in the live service:

- the bridge's `SetpointStream` with the live `BridgeSettings` (setpoint_rate_hz, setpoint_lead_s,
  velocity feed-forward, leg_coast_s) gets plan n at (n-1) dt + latency_s (`set_goal` with the
  waypoint, the deadline n dt and the planned velocity) and sends a setpoint at once, then one
  every 1 / setpoint_rate_hz, each held until the next;
- the bridge's clock may run ahead of the world at each slot boundary by up to `clock_ahead_s`
  (ClockSimTime's extrapolation while the world holds in lockstep) and then stands still until
  the world catches up (it never goes back);
- the vehicle is `sim.vehicle.step` at the world's physics rate (tick_hz) with the scenario's
  V_max and a_max, in local NED at a constant altitude.

Deviation = horizontal distance between the vehicle and the planned trajectory at the same world
time, at every physics tick of slots 1..N.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.frames import scenario_to_ned, scenario_to_ned_velocity
from isac_mission.model.vehicle import hermite_position
from isac_mission.service.bridge.counters import BridgeCounters
from isac_mission.service.bridge.legs import HermiteLeg
from isac_mission.service.bridge.setpoints import SetpointStream
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.timebase import FuncTime
from isac_mission.types import FloatArray
from sim.vehicle import Setpoint, VehicleLimits, VehicleState, step

ALTITUDE_M = 100.0


@dataclass(frozen=True)
class Flight:
    """What `fly` measured: t_s [S] world times of the physics ticks, vehicle_xy [S, 2] and
    plan_xy [S, 2] there (m), deviation_m [S]; boundary_m [N]: the deviation at each slot's end
    (what a live trace's plan_xy vs uav_xy shows)."""

    t_s: FloatArray
    vehicle_xy: FloatArray
    plan_xy: FloatArray
    deviation_m: FloatArray
    boundary_m: FloatArray

    @property
    def worst_m(self) -> float:
        return float(self.deviation_m.max())

    @property
    def p99_m(self) -> float:
        return float(np.percentile(self.deviation_m, 99))


def fly(
    q: FloatArray,
    v: FloatArray,
    dt_s: float,
    v_max_mps: float,
    a_max_mps2: float,
    settings: BridgeSettings | None = None,
    tick_hz: float = 50.0,
    latency_s: float = 0.0,
    clock_ahead_s: float = 0.0,
) -> Flight:
    """Fly the plan q [N + 1, 2], v [N + 1, 2] (see the module doc); the vehicle starts at q_0
    with velocity v_0."""
    settings = settings or BridgeSettings(v_max_mps=v_max_mps)
    limits = VehicleLimits(max_horizontal_speed_mps=v_max_mps, max_horizontal_accel_mps2=a_max_mps2)
    n_slots = len(q) - 1
    world = [0.0]
    bridge_floor = [0.0]  # the bridge's clock: never behind this

    def bridge_now() -> float:
        return max(world[0], bridge_floor[0])

    stream = SetpointStream(settings, FuncTime(bridge_now), None, BridgeCounters())  # type: ignore[arg-type]
    q0, v0 = np.asarray(q[0], float), np.asarray(v[0], float)
    # The slot before: a leg arriving at q_0 with v_0 at t = 0 (a vehicle already under way).
    stream.leg = HermiteLeg(q0 - v0 * dt_s, v0, q0, v0, -dt_s, 0.0, settings.leg_coast_s)
    state = VehicleState(
        position_ned_m=scenario_to_ned(q[0], ALTITUDE_M, (0.0, 0.0)),
        velocity_ned_mps=scenario_to_ned_velocity(v[0]),
    )
    tick = 1.0 / tick_hz
    period = 1.0 / settings.setpoint_rate_hz
    next_send, next_plan = 0.0, 1
    setpoint: Setpoint | None = None

    def send() -> Setpoint:
        sp = stream.setpoint()
        assert sp is not None
        xy, vel = sp
        return Setpoint(
            position_ned_m=scenario_to_ned(xy, ALTITUDE_M, (0.0, 0.0)),
            velocity_ned_mps=scenario_to_ned_velocity(vel),
        )

    ts, vehicle, planned = [], [], []
    n_ticks = round(n_slots * dt_s / tick)
    for k in range(n_ticks):
        t = k * tick
        world[0] = t
        while next_plan <= n_slots and t >= (next_plan - 1) * dt_s + latency_s - 1e-9:
            boundary = (next_plan - 1) * dt_s
            bridge_floor[0] = max(bridge_floor[0], boundary + clock_ahead_s)
            stream.set_goal(q[next_plan], next_plan * dt_s, v_max_mps, v[next_plan])
            setpoint = send()
            next_plan += 1
        if t >= next_send - 1e-9:
            setpoint = send()
            next_send += period
        assert setpoint is not None
        state = step(state, setpoint, limits, tick)
        t1 = t + tick
        n = min(int(np.floor(t1 / dt_s - 1e-9)) + 1, n_slots)  # the slot t1 lies in
        s = (t1 - (n - 1) * dt_s) / dt_s
        ts.append(t1)
        p = state.position_ned_m
        vehicle.append([p[1], p[0]])
        planned.append(hermite_position(q[n - 1], v[n - 1], q[n], v[n], dt_s, s))
    t_arr, veh, plan = np.array(ts), np.array(vehicle), np.array(planned)
    dev = np.linalg.norm(veh - plan, axis=1)
    ends = [int(np.argmin(np.abs(t_arr - n * dt_s))) for n in range(1, n_slots + 1)]
    return Flight(t_arr, veh, plan, dev, dev[ends])
