"""The planning methods: one protocol, one registry.

Every place that lists or validates method names (`simulate`, `sweep`, `run`, `serve`, the
ground settings, the CLI help, the report labels) reads `REGISTRY`. A new method is one module
with a class that has the protocol's two methods, and one line in `REGISTRY`
(docs/architecture.md, "Adding a planning method"). The registry itself imports no solver: a
method's module is imported when the method is first asked for, so the CLI's help and
validation stay light.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from isac_mission.planning.kit import SolverKit
    from isac_mission.planning.problem import SlotInput
    from isac_mission.types import SlotPlan


class SlotPlanner(Protocol):
    """A planning method.

    `plan` plans one slot (pure: no clock but the plan's timer, no RNG, no I/O; an infeasible
    slot returns its best effort with report.status "infeasible", planning/fallback.py);
    `prepare` builds and solves once whatever `plan` needs, so that no real slot pays for a
    build (planning/slot.warm_up; planning/problem.PlansOnceToWarmUp plans one slot).
    """

    def plan(self, inp: SlotInput, kit: SolverKit) -> SlotPlan: ...

    def prepare(self, kit: SolverKit) -> None: ...


@dataclass(frozen=True)
class Registered:
    """One method: name (configs, the CLI, traces), label (reports), summary (help), where its
    SlotPlanner class is ("module:Class"), and how many targets it plans for at most
    (max_targets; None: any number: the weighted sum of their bounds)."""

    name: str
    label: str
    summary: str
    where: str
    max_targets: int | None = None


REGISTRY: tuple[Registered, ...] = (
    Registered(
        "proposed",
        "Proposed",
        "Algorithm 2, the exact problem polished by IPOPT, the leader screen",
        "isac_mission.planning.per_slot:Proposed",
    ),
    Registered(
        "proposed-sca",
        "Proposed (SCA only)",
        "Algorithm 2 alone, as printed",
        "isac_mission.planning.per_slot:ProposedSca",
    ),
    Registered(
        "sd",
        "SD",
        "static deployment: the UAVs stay, the shares optimised",
        "isac_mission.planning.benchmarks:StaticDeployment",
    ),
    Registered(
        "aba",
        "ABA",
        "average bandwidth: equal shares, the positions by Algorithm 1",
        "isac_mission.planning.benchmarks:AverageBandwidth",
    ),
    Registered(
        "crb",
        "CRB-criterion",
        "Algorithm 2 on the measurement-only CRB tr(J_M^-1)",
        "isac_mission.planning.benchmarks:CrbCriterion",
    ),
    Registered(
        "comm",
        "Comm-optimal",
        "the communication-optimal plan of Section III-A",
        "isac_mission.planning.benchmarks:CommunicationOptimal",
    ),
    Registered(
        "nearest",
        "Nearest",
        "pursuit: each UAV closes on its nearest track within its links, equal shares",
        "isac_mission.planning.nearest:Nearest",
    ),
    Registered(
        "horizon",
        "Horizon",
        "receding horizon: L slots planned together on the bound, the first flown",
        "isac_mission.planning.horizon_method:Horizon",
    ),
)
"""Every method, in the order reports list them."""

METHODS: tuple[str, ...] = tuple(r.name for r in REGISTRY)
"""The registered method names."""

LABELS: dict[str, str] = {r.name: r.label for r in REGISTRY}
"""Each method's name in reports."""


def methods_help() -> str:
    """The registered names, comma-separated (the CLI's help)."""
    return ", ".join(METHODS)


LIVE_DEFAULT_METHOD = "horizon"
"""What `run` and `serve` fly without --method (docs/service.md, "The method flown")."""
LIVE_DEFAULT_MULTI_TARGET_METHOD = "proposed"
"""Their default on a multi-target scenario: the paper's per-slot method. The horizon plans
several targets too, but there it is not yet better than `proposed` and takes about 3.5 times
as long with three targets (docs/performance.md, "The receding horizon for several targets")."""


def live_default_method(multi_target: bool) -> str:
    """The method `run` and `serve` fly when none is given: the receding horizon, or on a
    multi-target scenario the paper's per-slot method (LIVE_DEFAULT_MULTI_TARGET_METHOD)."""
    return LIVE_DEFAULT_MULTI_TARGET_METHOD if multi_target else LIVE_DEFAULT_METHOD


def max_targets(name: str) -> int | None:
    """How many targets method `name` plans for at most (None: any number)."""
    return REGISTRY[METHODS.index(check_method(name))].max_targets


def check_method(name: str) -> str:
    """name if it is registered; ValueError naming the choices otherwise."""
    if name not in METHODS:
        raise ValueError(f"unknown planning method {name!r}; choose from {methods_help()}")
    return name


@cache
def planner(name: str) -> SlotPlanner:
    """The registered method `name` (its module imported on first use); ValueError naming the
    choices otherwise."""
    entry = REGISTRY[METHODS.index(check_method(name))]
    module, cls = entry.where.split(":")
    planner_type = getattr(importlib.import_module(module), cls)
    found: SlotPlanner = planner_type()
    return found
