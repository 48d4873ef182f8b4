"""Method `horizon` as registered (planning/registry.py): the receding horizon of one NLP for the
fleet (planning/horizon.py), or decomposed by targets (`planner.horizon.decompose: targets`,
planning/decomposed.py), and its warm-up. Pure: no clock but perf_counter, no RNG, no I/O.
"""

from __future__ import annotations

import time
from functools import partial
from typing import TYPE_CHECKING

from isac_mission.config import Scenario
from isac_mission.planning.decomposed import plan_decomposed
from isac_mission.planning.horizon import (
    horizon_nlp,
    kit_pair_bands,
    plan_horizon,
    proposed_plan,
)
from isac_mission.planning.per_slot import polish_nlp
from isac_mission.planning.problem import PlansOnceToWarmUp, SlotInput
from isac_mission.types import SlotPlan

if TYPE_CHECKING:
    from isac_mission.planning.kit import SolverKit


class Horizon(PlansOnceToWarmUp):
    """`horizon`: slots n..n+L-1 planned together on the bound's recursion, the first flown; the
    polished per-slot plan is its start and its fallback."""

    def plan(self, inp: SlotInput, kit: SolverKit) -> SlotPlan:
        started_s = time.perf_counter()
        if kit.scenario.planner.horizon.decompose == "targets":
            return plan_decomposed(inp, kit, started_s)
        return plan_horizon(inp, partial(proposed_plan, inp, kit), kit, started_s)

    def prepare(self, kit: SolverKit) -> None:
        """The polish's NLP and the horizon's built (the warm-up slot need not reach the
        polish), for every target count of `prepared_target_counts`, then one slot planned."""
        if kit.scenario.planner.polish:
            polish_nlp(kit)
        for n_targets in prepared_target_counts(kit.scenario):
            for band in kit_pair_bands(kit):
                horizon_nlp(kit, band, n_targets)
        super().prepare(kit)


def prepared_target_counts(s: Scenario) -> range:
    """The target counts whose NLPs `Horizon.prepare` builds ahead of a mission: 1, and on a
    scenario of several targets every count up to its number of targets (a slot with more
    confirmed tracks, a false one among them, builds its NLP when it first meets that count)."""
    return range(1, len(s.targets) + 1)
