"""plan_slot(), warm_up(): one slot of the planner, and its warm-up, dispatched over the
registered methods.

One pure function per slot: (scenario via the kit, previous plan, predicted track, prior
information) -> plan. No clock state, no RNG, no I/O: the offline simulation and the live service
call the same function. The methods are in planning/registry.py (the paper's per-slot method in
planning/per_slot.py, the benchmarks in planning/benchmarks.py, the receding horizon in
planning/horizon.py); each builds its slot problem with planning/problem.py and falls back by
planning/fallback.py. The kit they plan with is planning/kit.py's SolverKit (named here too).
"""

from __future__ import annotations

from isac_mission.planning.fallback import evade_target, kept_viable
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.problem import SlotInput, slot_clearance_m, with_end_velocity
from isac_mission.planning.registry import METHODS, SlotPlanner, planner
from isac_mission.types import SlotPlan

__all__ = [
    "METHODS",
    "Method",
    "SlotInput",
    "SlotPlanner",
    "SolverKit",
    "evade_target",
    "plan_slot",
    "slot_clearance_m",
    "warm_up",
]

Method = str
"""A method's name: one of METHODS (planning/registry.py)."""


def plan_slot(inp: SlotInput, kit: SolverKit, method: Method = "proposed") -> SlotPlan:
    """Plan one slot with the registered method `method` (planning/registry.py). An infeasible
    slot returns a best-effort plan with report.status == "infeasible" (planning/fallback.py).

    With planner.vehicle_model the waypoints keep within the exact reach a_max dt^2 / 4 of the
    coasting point (model/vehicle.py) and the plan carries the mean-velocity leg's end velocity
    (q_n - q_{n-1}) / dt as uav_velocity_mps (docs/model.md, "Vehicle model"); UAVs whose end
    states could not brake apart before D_s fly evasive legs instead (fallback "evasive",
    planning/evasion.py)."""
    s = kit.scenario
    plan = with_end_velocity(planner(method).plan(inp, kit), inp, s)
    return kept_viable(plan, inp, s, kit.sensing)


def warm_up(kit: SolverKit, method: Method = "proposed") -> None:
    """Build and solve once what `method` plans with (its SlotPlanner.prepare), so that the
    first real slot does not pay for compilation."""
    planner(method).prepare(kit)
