"""The planner cluster's options, one definition for `simulate`, `run` and `serve`:
`--planner-workers N`, `--planner-scheduler ADDR`, `--planner-deadline S` (the decomposed
horizon's groups solved on Dask: isac_mission/planner_cluster.py), and their one check
(`checked_planner_cluster`): refused with one line naming the option and exit status 2, before
any cluster or mission starts, when the method is not `horizon`, the scenario's horizon is not
decomposed by targets, Dask is missing, or a deadline is given without a cluster."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Annotated

import typer

from isac_mission.cli.app import err_console, number_check

if TYPE_CHECKING:
    from isac_mission.config import Scenario
    from isac_mission.planner_cluster import PlannerCluster

PlannerWorkersOpt = Annotated[
    int,
    typer.Option(
        min=0,
        help="Solve the decomposed horizon's groups (planner.horizon.decompose: targets) in "
        "parallel on a local Dask cluster of this many single-threaded worker processes on "
        "127.0.0.1, started before and stopped after (0: in this process, one after the "
        "other; simulate then flies its runs in this process, --workers unused).",
    ),
]
PlannerSchedulerOpt = Annotated[
    str | None,
    typer.Option(
        help="Solve the decomposed horizon's groups on the Dask scheduler at this address "
        "instead, e.g. tcp://127.0.0.1:8786 (its workers need isac-mission installed; an "
        "address off this machine sends the groups' inputs and plans there, unencrypted).",
    ),
]
PlannerDeadlineOpt = Annotated[
    float | None,
    typer.Option(
        callback=number_check(above=0.0),
        help="Seconds a slot waits for its groups on the cluster before it flies the "
        "per-slot plan (fallback `horizon: decomposed worker lost`; > 0). Default: simulate "
        "120; run and serve half of --plan-budget (120 without a budget).",
    ),
]

PLANNER_OPTIONS = ("--planner-workers", "--planner-scheduler", "--planner-deadline")


def planner_cluster_problem(s: Scenario, methods: Sequence[str], hint: str) -> str | None:
    """Why a planner cluster would solve nothing for `methods` on `s` (None: it would): the
    decomposed horizon is the only planner that hands groups to it. hint: what to do when
    `horizon` is not among the methods (the command's own option)."""
    if "horizon" not in methods:
        return f"only the method `horizon` solves groups on a cluster; {hint}"
    if s.planner.horizon.decompose != "targets":
        return (
            "only the decomposed horizon solves groups on a cluster; the scenario has "
            f"planner.horizon.decompose: {s.planner.horizon.decompose} (set it to targets)"
        )
    return None


def checked_planner_cluster(
    s: Scenario,
    methods: Sequence[str],
    hint: str,
    workers: int = 0,
    scheduler: str | None = None,
    deadline_s: float | None = None,
) -> PlannerCluster | None:
    """The cluster the options ask for (None: none, the groups solved in this process), once
    checked: a refusal (`planner_cluster_problem` with `hint`, no Dask, a deadline without a
    cluster) is one line on stderr naming the options given, and exit status 2. Opens
    nothing."""
    from rich.markup import escape

    used = (workers > 0, scheduler is not None, deadline_s is not None)
    given = [name for name, on in zip(PLANNER_OPTIONS, used, strict=True) if on]
    if not given:
        return None
    named = "/".join(given)
    if workers == 0 and scheduler is None:
        err_console.print(
            f"{named}: no cluster to wait for; add --planner-workers N or --planner-scheduler ADDR",
            highlight=False,
            markup=False,
        )
        raise typer.Exit(2)
    problem = planner_cluster_problem(s, methods, hint)
    if problem is not None:
        err_console.print(f"{named}: {problem}", highlight=False, markup=False)
        raise typer.Exit(2)
    from isac_mission.errors import MissingDependencyError
    from isac_mission.planner_cluster import PlannerCluster, require_dask

    try:
        require_dask()
    except MissingDependencyError as err:
        err_console.print(f"[bold red]{named}[/]: {escape(str(err))}", highlight=False)
        raise typer.Exit(2) from None
    return PlannerCluster(workers=workers, scheduler=scheduler, deadline_s=deadline_s)
