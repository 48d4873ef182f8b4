"""SolverKit: a scenario's planning problems, built once and re-solved every slot.

The convex subproblems (positions, shares, association: cvxpy with DPP, or their direct forms),
the sensing parameters, the IPOPT problems each method builds on first use (`built`, shared by
`renewed` kits and, per fleet size, by planning/fleet.KitCache), the lock around every IPOPT
construction and solve, and what builds those solvers (planning/nlp_model.IpoptFactory). What
a method does with them is the method's (planning/registry.py); warming a kit up for a method is
the dispatcher's (planning/slot.warm_up).
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
from isac_mission.planning.nlp_model import IpoptFactory, SolveLock, plain_ipopt
from isac_mission.planning.positions import PositionSubproblem
from isac_mission.tracking.pcrb import SensingParams

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
        """fast=False is the reference path (the planner before its fast paths,
        docs/decisions/0004-planner-fast-paths.md): (P1.1.2)
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
        if s is not self.scenario and (changed := changed_fields(self.scenario, s) - {"r_th"}):
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


def changed_fields(a: Scenario, b: Scenario) -> set[str]:
    """The names of the fields in which scenarios a and b differ (arrays by value)."""
    out = set()
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        same = x is y or (np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y)
        if not same:
            out.add(f.name)
    return out
