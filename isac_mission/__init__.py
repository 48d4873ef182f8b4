"""ISAC multi-UAV collaborative target tracking: PCRB-optimal trajectories and bandwidth.

The public API, for scripts and notebooks::

    import isac_mission as im
    scenario = im.load_scenario("paper")       # a shipped scenario by name, or a YAML path
    plan = im.plan_slot(scenario)              # slot 1 from the start points: a SlotPlan
    run = im.run_closed_loop(scenario, seed=1)  # one offline mission; run.trace its records
    fig = im.plot_trajectories(run.trace, ax=ax)

Also `im.build_kit` (the solver kit, built once per scenario), `im.run_monte_carlo` and
`im.summarize` (many seeds, common random numbers), `im.read_trace` (a trace file,
docs/trace.md), `im.scenario_names()`. Names are imported on first use, so `import isac_mission`
(and `isac-mission --version`) stays fast.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__version__ = "0.4.0"
"""The package version; pyproject.toml reads it from here (one source of truth)."""

_EXPORTS: dict[str, str] = {
    "ConfigError": "isac_mission.errors",
    "IsacError": "isac_mission.errors",
    "MessageError": "isac_mission.errors",
    "Scenario": "isac_mission.config",
    "load_scenario": "isac_mission.config",
    "parse_scenario": "isac_mission.config",
    "scenario_names": "isac_mission.config",
    "SlotInput": "isac_mission.planning.slot",
    "SolverKit": "isac_mission.planning.kit",
    "SlotPlan": "isac_mission.types",
    "ClosedLoopRun": "isac_mission.api",
    "build_kit": "isac_mission.api",
    "first_slot_input": "isac_mission.api",
    "plan_slot": "isac_mission.api",
    "run_closed_loop": "isac_mission.api",
    "run_monte_carlo": "isac_mission.experiment.montecarlo",
    "summarize": "isac_mission.experiment.montecarlo",
    "Trace": "isac_mission.records",
    "read_trace": "isac_mission.records",
    "plot_bandwidth": "isac_mission.experiment.plots",
    "plot_performance": "isac_mission.experiment.plots",
    "plot_trajectories": "isac_mission.experiment.plots",
}

__all__ = [
    "ClosedLoopRun",
    "ConfigError",
    "IsacError",
    "MessageError",
    "Scenario",
    "SlotInput",
    "SlotPlan",
    "SolverKit",
    "Trace",
    "__version__",
    "build_kit",
    "first_slot_input",
    "load_scenario",
    "parse_scenario",
    "plan_slot",
    "plot_bandwidth",
    "plot_performance",
    "plot_trajectories",
    "read_trace",
    "run_closed_loop",
    "run_monte_carlo",
    "scenario_names",
    "summarize",
]

if TYPE_CHECKING:
    from isac_mission.api import (
        ClosedLoopRun,
        build_kit,
        first_slot_input,
        plan_slot,
        run_closed_loop,
    )
    from isac_mission.config import Scenario, load_scenario, parse_scenario, scenario_names
    from isac_mission.errors import ConfigError, IsacError, MessageError
    from isac_mission.experiment.montecarlo import run_monte_carlo, summarize
    from isac_mission.experiment.plots import plot_bandwidth, plot_performance, plot_trajectories
    from isac_mission.planning.kit import SolverKit
    from isac_mission.planning.slot import SlotInput
    from isac_mission.records import Trace, read_trace
    from isac_mission.types import SlotPlan


def __getattr__(name: str) -> object:
    """Import a public name on first use (PEP 562)."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'isac_mission' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
