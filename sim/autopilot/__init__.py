"""A PX4-like autopilot for one simulated multirotor, on the neutral MAVLink layer
(`isac_mission.mavwire`): the vehicles that stand in for real ones in the live tests.

Modules, by job: `settings` (AutopilotSettings, pydantic), `flight` (modes, failsafes, land
detector: pure), `params` (parameter table and protocol), `mission` (mission protocol, an empty
plan), `commands` (commands, mode changes, setpoints), `telemetry` (message builders), `link`
(one UDP link: peers, streams) and `endpoint` (`Autopilot`, tying them to two links).
"""
