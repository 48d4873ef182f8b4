"""`isac-mission ARGS` with one plan that is still solving when the mission ends.

`python -m tests.support.slow_solve SLOT SOLVE_S ARGS...` runs the real command line (`run` or
`serve` ARGS) in this process, except that the plan of slot SLOT (`every`: of every slot) first
runs a native solve of about SOLVE_S wall seconds (long_native_solve), on the planner's thread,
then plans as usual: a machine too slow for the mission's pace.
With `--plan-budget` below SOLVE_S the ground loop holds that slot and goes on; the solve is in
native code when the mission ends: what used to abort the process at exit ("FATAL: exception not
rethrown", exit 134).
Writes "slow solve started" to stderr when it starts.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import clarabel
import numpy as np
import scipy.sparse as sp

from isac_mission.planning import fleet as fleet_plan


def long_native_solve(wall_s: float) -> None:
    """Clarabel solves of a tiny LP (the per-slot planner's conic solver; microseconds each), one
    after the other, for about wall_s seconds: the thread leaves native code thousands of times
    a second, as a planner does between its solves, so it does so while the interpreter shuts
    down."""
    P = sp.csc_matrix((2, 2))
    q, A, b = np.ones(2), sp.csc_matrix(-np.eye(2)), np.zeros(2)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    deadline = time.monotonic() + wall_s
    while time.monotonic() < deadline:
        clarabel.DefaultSolver(P, q, A, b, [clarabel.NonnegativeConeT(2)], settings).solve()


def main(argv: list[str]) -> None:
    every = argv[0] == "every"
    slow_slot, solve_s, cli_args = -1 if every else int(argv[0]), float(argv[1]), argv[2:]
    original = fleet_plan.PlanningJob.run_tracks

    def run_tracks(self: fleet_plan.PlanningJob, *args: Any, **kwargs: Any) -> Any:
        if every or self.slot == slow_slot:
            print("slow solve started", file=sys.stderr, flush=True)
            long_native_solve(solve_s)
        return original(self, *args, **kwargs)

    fleet_plan.PlanningJob.run_tracks = run_tracks  # type: ignore[method-assign]
    from isac_mission.cli import app

    sys.argv = ["isac-mission", *cli_args]
    sys.exit(app())


if __name__ == "__main__":
    main(sys.argv[1:])
