"""The ground service: reports -> tracker -> plan, over the bus (docs/service.md).

`loop.GroundLoop` runs one mission, for any number of targets; `bus_loop` is its bus side;
`settings.GroundSettings` configures it; `report` holds what it counts; `assembler` gathers a
slot's reports; `exclusion` decides which vehicles a plan can use; `startup` when it may plan;
`mission.MissionState` is the slot recursion's state between network waits (on the scenario's
tracker, `isac_mission.tracking.factory`; the slot for the vehicles that can follow a plan is
planned by `isac_mission.planning.fleet`); `tracefile` writes the trace and the track message;
`planner_thread` runs the planner off the event loop.
"""
