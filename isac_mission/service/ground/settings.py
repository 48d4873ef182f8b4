"""The ground loop's settings, validated with pydantic; a bad value raises ConfigError."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

from pydantic import Field, field_validator

from isac_mission.config.validation import Settings
from isac_mission.planning.fleet import Planner
from isac_mission.planning.registry import check_method
from isac_mission.planning.slot import Method, plan_slot


class GroundSettings(Settings):
    """method: planning strategy; trace_path: JSON Lines trace (None: no trace); resume: continue
    an existing trace from its last complete slot; detection_wait_s: simulation seconds after a
    slot boundary before a partial update; detection_wall_wait_s: the same bound in wall seconds,
    counted from the first detection of the slot or from the clock reaching the slot's end,
    whichever comes first (for a held or stalled clock);
    telemetry_max_age_s: older telemetry is not used as a UAV position; telemetry_current_s:
    telemetry at most this old at the planning instant is the UAV's position, older telemetry
    yields to the slot's detection position (exclusion.py `positions`); trace_config: entries
    that override or extend the trace's config line.

    Faults (docs/reliability.md): plan_budget_s: wall seconds a slot's planning may take (None:
    no limit); past it the slot's plan is "hold" (status "timeout") and the next slot plans
    normally. vehicle_lost_after_s (simulation) and vehicle_lost_wall_s (wall): a vehicle whose
    telemetry position is older than both, or whose bridge reports its link lost, is planned
    around (planning/fleet.py) until its link is back and it is in OFFBOARD again.
    wait_for_telemetry: plan only from fresh telemetry at a start, a resume and after a stall
    (startup.py; the live service sets it: its bridges publish telemetry). False (a loop fed by
    a world without telemetry): plan from the detections' positions and the start points.
    startup_wait_s (wall): at a start or resume, slot 1 (or L+1) is planned once every vehicle
    has reported fresh telemetry, or after this long for the vehicles that have (startup.py).
    stall_gap_s (wall): a pause of the loop longer than this (SIGSTOP, an overloaded host) is a
    stall: planning waits for telemetry that arrived stall_settle_s after it woke.
    plan_rate_factor: the planner's R_th margin, applied to an operator's new R_th too.
    planner: the per-slot planning function (plan_slot; replaceable to inject faults).

    Frozen; an unknown or invalid field raises ConfigError naming it
    (`ground settings: plan_budget_s: Input should be greater than 0 (got -1.0)`)."""

    settings_name: ClassVar[str] = "ground settings"

    method: Method = "proposed"
    trace_path: Path | None = None
    resume: bool = False
    detection_wait_s: float = Field(0.5, ge=0.0)
    detection_wall_wait_s: float = Field(2.0, gt=0.0)
    telemetry_max_age_s: float = Field(1.0, gt=0.0)
    telemetry_current_s: float = Field(0.05, ge=0.0)
    trace_config: dict[str, object] = Field(default_factory=dict)
    plan_budget_s: float | None = Field(1.0, gt=0.0)
    vehicle_lost_after_s: float = Field(1.5, gt=0.0)
    vehicle_lost_wall_s: float = Field(1.0, gt=0.0)
    plan_rate_factor: float = Field(1.0, gt=0.0)
    wait_for_telemetry: bool = False
    startup_wait_s: float = Field(10.0, gt=0.0)
    stall_gap_s: float = Field(1.0, gt=0.0)
    stall_settle_s: float = Field(0.3, ge=0.0)
    planner: Planner = plan_slot

    @field_validator("method")
    @classmethod
    def _registered_method(cls, method: str) -> str:
        return check_method(method)
