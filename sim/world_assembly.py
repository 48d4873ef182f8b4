"""The parts of the simulated world, made from a scenario and the world's options: the scene
(its targets and their sensing, with their seeded random streams; `make_scene`, the one place
that picks it from the scenario's detection model) and the vehicles (one PX4-like autopilot per
UAV), with the few questions the world asks of the fleet (ready for an offboard start? where is
everyone?).

The vehicles' local NED frames are all centred on the scenario origin (0, 0) (north = y,
east = x).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from isac_mission.config import Scenario
from isac_mission.mavwire.modes import FlightMode
from isac_mission.model.run_noise import draw_run_noise
from isac_mission.tracking.factory import labelled
from isac_mission.types import FloatArray
from sim.autopilot.battery import BatterySettings
from sim.autopilot.endpoint import Autopilot
from sim.autopilot.settings import AutopilotSettings
from sim.multi_target_scene import MultiTargetScene
from sim.scenes import LabelledTargetScene, WorldScene
from sim.sensing import SensingModel, Sensor
from sim.target import CvTarget, ScriptedTarget, TargetModel
from sim.vehicle import VehicleLimits
from sim.world_options import WorldOptions


def world_seed(scenario: Scenario, options: WorldOptions) -> int:
    """The seed of the world's targets and sensing: options.seed, else the scenario's."""
    return scenario.seed if options.seed is None else options.seed


def make_scene(scenario: Scenario, options: WorldOptions) -> WorldScene:
    """The world's scene, of the scenario's detection model (`tracking.factory.labelled`): the
    paper's labelled target and its detections (`make_target_and_sensor`), or the targets of
    `simulate`'s run for the world's seed and their unlabelled reports (`MultiTargetScene`; the
    target options, a scripted path, the initial error and the reflection, are the labelled
    target's)."""
    if labelled(scenario):
        return LabelledTargetScene(*make_target_and_sensor(scenario, options))
    return MultiTargetScene(scenario, world_seed(scenario, options))


def make_target_and_sensor(scenario: Scenario, options: WorldOptions) -> tuple[TargetModel, Sensor]:
    """The target and the sensor, each on its own random stream spawned (in this order) from the
    world's seed (`world_seed`)."""
    seed = world_seed(scenario, options)
    target_seq, sensing_seq = np.random.SeedSequence(seed).spawn(2)
    target = make_target(scenario, options, np.random.default_rng(target_seq), seed)
    sensor = Sensor(SensingModel.from_scenario(scenario), np.random.default_rng(sensing_seq))
    return target, sensor


def make_target(
    scenario: Scenario, options: WorldOptions, rng: np.random.Generator, seed: int
) -> TargetModel:
    """The target the options ask for: scripted path, or the CV model of the scenario.

    The CV target draws what `simulate` draws for run seed `seed` (model/run_noise.py): its
    process noise over the N slots (rng's draws after them), and, with options.initial_error,
    the initial error e, as x_0 = x0 - e: the configured x0 is the tracker's cue, off the truth
    by e as simulate's estimate x0 + e is off its truth x0. Without the initial error the
    target flies simulate's true path exactly (the embedded `run` then starts its tracker at
    simulate's x0 + e: cli/embedded.py), until a wall reflects it."""
    bounds = scenario.area if options.reflect_target else None
    if options.target_waypoints_xy_m is not None:
        speed = options.target_speed_mps
        if speed is None:
            speed = float(np.hypot(scenario.x0[2], scenario.x0[3])) or 1.0
        return ScriptedTarget(
            options.target_waypoints_xy_m, speed, scenario.dt, bounds_m=scenario.area
        )
    noise = draw_run_noise(scenario, seed)
    x0 = scenario.x0
    if options.initial_error:
        # The configured x0 is the cue the tracker starts from; the truth differs from it by a
        # draw from P0, as in `simulate` (docs/model.md, "EKF start and P0").
        x0 = x0 - noise.initial_error
    return CvTarget(x0, scenario.dt, scenario.kappa, rng, bounds_m=bounds, increments=noise.process)


def autopilot_settings(scenario: Scenario, options: WorldOptions, m: int) -> AutopilotSettings:
    """Vehicle m's settings: start point, flight altitude H, V_max (also the cruise speed of
    RTL, missions and DO_REPOSITION), geofence = the area, the energy model, and the scenario's
    MAVLink signing key (None: signing off)."""
    start = scenario.uav_start_xy[m]
    serial = next((link for link in options.serial_links if link.vehicle == m), None)
    return AutopilotSettings(
        index=m,
        offboard_port=options.mavlink_base_port + m,
        bind_port=options.mavlink_local_base_port and options.mavlink_local_base_port + m,
        gcs_port=options.gcs_port,
        gcs_bind_port=options.gcs_local_base_port and options.gcs_local_base_port + m,
        geo_origin=options.geo_origin,
        local_origin_xy_m=(0.0, 0.0),
        spawn_xy_m=(float(start[0]), float(start[1])),
        takeoff_alt_m=scenario.H,
        limits=VehicleLimits(
            max_horizontal_speed_mps=scenario.v_max, max_horizontal_accel_mps2=scenario.a_max
        ),
        area_min_xy_m=(0.0, 0.0),
        area_max_xy_m=(float(scenario.area[0]), float(scenario.area[1])),
        max_altitude_m=max(500.0, 2.0 * scenario.H),
        signing=scenario.mavlink_signing_key,
        serial_device=None if serial is None else serial.device,
        serial_baud=57600 if serial is None else serial.baud,
        cruise_speed_mps=scenario.v_max,
        battery=battery_settings(scenario, m),
        battery_low_thr=scenario.battery.low_thr,
        battery_crit_thr=scenario.battery.critical_thr,
        battery_emergen_thr=scenario.battery.emergency_thr,
    )


def battery_settings(scenario: Scenario, m: int) -> BatterySettings:
    """Vehicle m's energy model from the scenario's uavs.battery (its capacity override, if
    any)."""
    b = scenario.battery
    return BatterySettings(
        capacity_wh=b.capacity_wh_by_uav.get(m, b.capacity_wh),
        start_remaining=b.start_remaining,
        min_remaining=b.min_remaining,
        hover_power_w=b.hover_power_w,
        speed_power_w_per_mps=b.speed_power_w_per_mps,
        climb_power_w_per_mps=b.climb_power_w_per_mps,
    )


def make_vehicles(scenario: Scenario, options: WorldOptions) -> list[Autopilot]:
    """One autopilot per UAV (sockets not yet open), vehicle m with `autopilot_settings(.., m)`."""
    return [Autopilot(autopilot_settings(scenario, options, m)) for m in range(scenario.M)]


def ready_for_offboard_start(
    vehicles: Sequence[Autopilot], altitude_m: float, tol_m: float
) -> bool:
    """Every vehicle armed, in the air, in OFFBOARD and within `tol_m` of `altitude_m` (m)."""
    return all(
        v.state.armed
        and not v.state.landed
        and v.state.mode is FlightMode.OFFBOARD
        and abs(v.state.altitude_m - altitude_m) <= tol_m
        for v in vehicles
    )


def positions_xy_m(vehicles: Sequence[Autopilot]) -> FloatArray:
    """[M, 2] actual horizontal positions (scenario plane, m)."""
    return np.array([v.state.position_xy_m for v in vehicles], dtype=float)
