"""The paper's benchmarks (Section IV) and the communication-optimal plan, on the same slot
problem and the same loop as the proposed method (planning/per_slot.py):

- `sd`: static deployment, the UAVs stay where they are, the shares optimised;
- `aba`: average bandwidth (eta = 1/M), the positions by Algorithm 1;
- `crb`: the proposed optimiser with the measurement-only objective tr(J_M^-1) (no prior), never
  polished;
- `comm`: the communication-optimal plan of Section III-A (Lemma 1's shares), no sensing.

Pure: no clock but the plan's timer, no RNG, no I/O.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from isac_mission.planning.fallback import best_effort
from isac_mission.planning.per_slot import Alternation, plan_alternating
from isac_mission.planning.problem import PlansOnceToWarmUp, SlotInput, build_slot_problem
from isac_mission.types import SlotPlan, SolveReport

if TYPE_CHECKING:
    from isac_mission.planning.kit import SolverKit


class StaticDeployment(PlansOnceToWarmUp):
    """`sd`: the UAVs hold their positions; only the shares are optimised."""

    def plan(self, inp: SlotInput, kit: SolverKit) -> SlotPlan:
        return plan_alternating(inp, kit, Alternation(positions=False))


class AverageBandwidth(PlansOnceToWarmUp):
    """`aba`: equal shares 1/M; only the positions are optimised (Algorithm 1 once)."""

    def plan(self, inp: SlotInput, kit: SolverKit) -> SlotPlan:
        return plan_alternating(inp, kit, Alternation(shares=False))


class CrbCriterion(PlansOnceToWarmUp):
    """`crb`: Algorithm 2 on tr(J_M^-1), the measurement's CRB without the prior."""

    def plan(self, inp: SlotInput, kit: SolverKit) -> SlotPlan:
        return plan_alternating(inp, kit, Alternation(), crb=True)


class CommunicationOptimal(PlansOnceToWarmUp):
    """`comm`: each UAV towards its serving BS, Lemma 1's shares (status "infeasible" when the
    plan breaks a constraint, e.g. 14j)."""

    def plan(self, inp: SlotInput, kit: SolverKit) -> SlotPlan:
        problem = build_slot_problem(inp, kit)
        no_link = problem.link_infeasible_reason()
        if no_link is not None:
            return best_effort(problem, no_link)
        comm = problem.communication
        violated = problem.constraints.describe_violations(comm.uav_xy, comm.eta)
        status = "ok" if not violated else "infeasible"
        report = SolveReport(status, ", ".join(violated), solve_s=problem.elapsed_s())
        return problem.plan(comm.uav_xy, comm.eta, report)
