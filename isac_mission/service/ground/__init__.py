"""The ground service: detections -> EKF -> plan_slot -> plan, over the bus (docs/service.md).

`loop.GroundLoop` runs one mission; `settings.GroundSettings` configures it; `report` holds what
it counts; `assembler` gathers a slot's detections; `exclusion` decides which vehicles a plan
can use; `mission.MissionState` is the slot recursion's state between network waits (on
`isac_mission.tracking.cycle`; the slot for the vehicles that can follow a plan is planned by
`isac_mission.planning.fleet`); `planner_thread` runs the planner off the event loop.
"""
