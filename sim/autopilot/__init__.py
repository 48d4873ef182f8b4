"""A PX4-like autopilot for one simulated multirotor, on the neutral MAVLink layer
(`isac_mission.mavwire`): the vehicles that stand in for real ones in the live tests.

Modules, by job: `settings` (AutopilotSettings, pydantic), `state` (the snapshot), `flight`
(modes, land detector, arming; applies the decisions below: pure), `failsafes` (offboard,
datalink and battery failsafes, auto-disarm: status in, decision out), `guidance` (shared setpoints, the fall of a disarmed vehicle), `rtl` (AUTO.RTL),
`mission_plan` (mission items and their check), `mission_flight` (AUTO.MISSION), `battery`
(energy model, warning levels), `params` (parameter table and protocol), `mission_protocol`
(upload, download, clear, set current), `commands` (commands, mode changes, setpoints),
`telemetry` (message builders), `link` (one UDP link: peers, streams) and `endpoint`
(`Autopilot`, tying them to two links).
"""
