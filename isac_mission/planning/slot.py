"""plan_slot(): one slot of the planner, dispatched over the registered methods.

One pure function per slot: (scenario via the kit, previous plan, predicted track, prior
information) -> plan. No clock state, no RNG, no I/O: the offline simulation and the live service
call the same function. The methods are in planning/registry.py (the paper's per-slot method in
planning/per_slot.py, the benchmarks in planning/benchmarks.py, the receding horizon in
planning/horizon.py); each builds its slot problem with planning/problem.py and falls back by
planning/fallback.py.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable
from typing import TypeVar, cast

import numpy as np

from isac_mission.config import Scenario
from isac_mission.planning.association import AssociationLP
from isac_mission.planning.bandwidth import BandwidthSubproblem
from isac_mission.planning.fallback import evade_target, kept_viable
from isac_mission.planning.nlp_model import IpoptFactory, SolveLock, plain_ipopt
from isac_mission.planning.positions import PositionSubproblem
from isac_mission.planning.problem import SlotInput, slot_clearance_m, with_end_velocity
from isac_mission.planning.registry import METHODS, SlotPlanner, planner
from isac_mission.tracking.pcrb import SensingParams
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
]

Method = str
"""A method's name: one of METHODS (planning/registry.py)."""

T = TypeVar("T")


class SolverKit:
    """The convex problems of one scenario, built once (DPP) and re-solved every slot."""

    def __init__(
        self,
        scenario: Scenario,
        fast: bool = True,
        n_keep_out: int = 0,
        solve_lock: SolveLock | None = None,
        ipopt: IpoptFactory = plain_ipopt,
    ) -> None:
        """fast=False is the reference path (the planner before docs/performance.md): (P1.1.2)
        through cvxpy instead of a direct Clarabel call, (P1.2.1) by the cvxpy LP instead of its
        closed-form vertex, the association LP every slot, and the per-UAV line search on full
        batches. Both paths solve the same problems; they differ by solver tolerance.
        n_keep_out: the number of keep-out points (SlotInput.keep_out_xy) each slot carries.
        solve_lock: held around every IPOPT construction and solve (planning/nlp_model.SolveLock;
        the live service shares one threading lock between its kits); None: a null context.
        ipopt: what builds the IPOPT problems (planning/nlp_model.IpoptFactory; compiled and
        cached on disk: isac_mission/nlp_cache.py)."""
        s = scenario
        self.scenario = s
        self.fast = fast
        self.n_keep_out = n_keep_out
        self.sensing = SensingParams.from_scenario(s)
        self.positions = PositionSubproblem(s, s.planner.solver, direct=fast, n_keep_out=n_keep_out)
        self.shares = BandwidthSubproblem(s.M, "closed-form" if fast else "HIGHS")
        self.association = AssociationLP(s.M, s.K, s.n_a, shortcut=fast)
        self.solve_lock: SolveLock = (
            solve_lock if solve_lock is not None else contextlib.nullcontext()
        )
        self.ipopt = ipopt
        self._built: dict[str, object] = {}

    def built(self, key: str, build: Callable[[], T]) -> T:
        """The problem `key` of this kit (an IPOPT problem of a method), built by `build` on
        first use and kept; `renewed` kits share them."""
        if key not in self._built:
            self._built[key] = build()
        return cast(T, self._built[key])

    def share_built(self, problems: dict[str, object]) -> None:
        """Keep this kit's IPOPT problems in `problems` (shared with other kits of the same
        fleet size and keep-out count: KitCache)."""
        self._built = problems

    def renewed(self, scenario: Scenario | None = None) -> SolverKit:
        """A kit with fresh convex problems (their cvxpy Parameters are per-kit state, which a
        timed-out plan's thread may still be writing) sharing this kit's IPOPT problems (built
        once: their solves are serialised by solve_lock). A horizon kit rebuilt after every
        timeout spent its next plan's budget on the build, and the timeouts cascaded.

        scenario: plan with it from now on (default: this kit's). It may differ from this
        kit's in R_th only (an operator's `set`), which the IPOPT problems take as the bound of
        their 14a rows (nlp_model.lower_at_rate); ValueError otherwise. Rebuilt instead, they made the next plans of a live mission time
        out (seconds of build, a compile in the background)."""
        s = self.scenario if scenario is None else scenario
        if s is not self.scenario and (changed := _changed_fields(self.scenario, s) - {"r_th"}):
            raise ValueError(f"a renewed kit may change R_th only, not {', '.join(changed)}")
        kit = SolverKit(
            s,
            fast=self.fast,
            n_keep_out=self.n_keep_out,
            solve_lock=self.solve_lock,
            ipopt=self.ipopt,
        )
        kit._built = self._built
        return kit

    def warm_up(self, method: Method = "proposed") -> None:
        """Build and solve once what `method` plans with (its SlotPlanner.prepare), so that the
        first real slot does not pay for compilation."""
        planner(method).prepare(self)


def _changed_fields(a: Scenario, b: Scenario) -> set[str]:
    """The names of the fields in which scenarios a and b differ (arrays by value)."""
    out = set()
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        same = x is y or (np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y)
        if not same:
            out.add(f.name)
    return out


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
