"""The MAVLink bridge: one `VehicleBridge` per vehicle between its MAVLink link and Zenoh.

Each bridge (vehicle.py) owns a `MavlinkLink` (UDP 127.0.0.1:(base + m), PX4 SITL's offboard
port) and:

- publishes the vehicle's `TelemetryMsg` on `isac/<mission>/telemetry/<m>` at
  `telemetry_rate_hz` (default 10 Hz of simulation time), converted to the scenario plane
  (telemetry.py);
- sends the GCS HEARTBEAT at `heartbeat_rate_hz` (1 Hz simulation time);
- flies the mission start (`prepare`, offboard.py): arm, PX4 takeoff to the mission altitude,
  OFFBOARD once airborne and the setpoint stream has run, then the flight to the start point;
- follows waypoints (`set_waypoint(xy, arrive_by_s)`, `BridgeFleet.on_plan`) on legs (legs.py)
  that arrive at `arrive_by_s`, never above V_max; the setpoint is streamed as
  SET_POSITION_TARGET_LOCAL_NED at `setpoint_rate_hz` (default 20 Hz of simulation time),
  sampled `setpoint_lead_s` (0.025 s) ahead of now (setpoints.py);
- `hold()` (PX4 HOLD) and `land()` (PX4 LAND, then waits for touchdown and the disarm, and
  disarms itself if the vehicle does not);
- supervises the link (supervision.py): lost after `link_lost_after_s` without a HEARTBEAT, and
  back into OFFBOARD when the vehicle left it for its loss action; a mode change by anyone else
  while the link is up is respected.

Modules: settings.py (`BridgeSettings`), legs.py, setpoints.py, telemetry.py, supervision.py,
commanding.py (commands with ACKs, waits on the vehicle's status), offboard.py, pacing.py
(periodic loops), counters.py, clock_time.py (`ClockSimTime`, the Zenoh-fed simulation time),
vehicle.py (`VehicleBridge`), fleet.py (`BridgeFleet`: M bridges on one Zenoh session:
`start()`, `prepare_all()`, `on_plan(plan)` or `follow_plans()`, `land_all()`, `stop()`).

Frames (isac_mission/frames.py): the scenario plane is x east, y north (m); the vehicle's
MAV_FRAME_LOCAL_NED is centred on its `origin_xy_m` in the scenario plane on the ground, so
x = east + x0, y = north + y0, altitude = -down. The simulated vehicles all use the scenario
origin (0, 0), the default.

Time (isac_mission/timebase.py): everything runs on a `SimTime` (`now_s()` and `speed`, and
what the bridges need of the world's slot clock: `current_slot()`, `slot_end_s(n)`, `ready`,
`wait_ready`, `start_clock`/`stop_clock`, so no bridge asks a time for its type):
`ClockSimTime` follows the world's Zenoh `clock` messages, `WallTime` is the wall clock for real
vehicles, `FuncTime` adapts any clock function (e.g. an in-process SimClock). Command ACK
timeouts are wall seconds; every other timeout is in simulation seconds
(docs/frames-and-clocks.md, docs/service.md).
"""
