"""The horizon's IPOPT solves of one closed loop, recorded and solved again under other IPOPT
options (docs/decisions/0016-horizon-kkt-unscaled.md).

One fleet of bench/horizon_fleet.py (M UAVs, the live settings) flies `--slots` slots with the
horizon, interpreted, and every call of its IPOPT problems is recorded (start, parameters,
bounds, multipliers). Then each variant builds those problems again with its options on top of
the planner's (the warm-start instance sharing the cold one's derivatives, as the planner's
does) and solves every recorded call: the same inputs for every variant, so the time per
iteration compares the solvers alone. Per variant: the wall time of the solves, their median,
IPOPT's iterations, the time per iteration and the part of it in function evaluations, the
largest change of a solution from the first variant's (scaled variables) and the calls whose
iteration count or status changed. Variants run one after the other in one process: run on a
quiet machine, and nothing beside it.

Run: python bench/horizon_replay.py [--size 24] [--slots 30] [--seed 1]
         [--variant NAME='{"ipopt option": value, ...}' ...]
     (default variants: the planner's options, and IPOPT's default MUMPS scalings; the key
     "hess_lag": null builds the variant with CasADi's automatic Hessian instead of the
     planner's, docs/decisions/0019-hessian-through-the-information.md)
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

BENCH = Path(__file__).resolve().parent
DEFAULT_VARIANTS = {
    "planner's": {},
    "MUMPS scalings on": {"mumps_permuting_scaling": 7, "mumps_scaling": 77},
}
"""IPOPT 3.14's defaults are permuting scaling 7 and scaling 77 (both: chosen automatically)."""


@dataclass
class Recorded:
    """The horizon problems a kit built (name -> (nlp, options, name of the solver whose
    derivatives it shares)) and the calls of their solvers (name, keyword arguments)."""

    problems: dict[str, tuple[dict[str, Any], dict[str, Any], str | None]] = field(
        default_factory=dict
    )
    calls: list[tuple[str, dict[str, np.ndarray]]] = field(default_factory=list)


class _RecordingSolver:
    """An nlpsol that records its calls' arguments."""

    def __init__(self, name: str, solver: Any, recorded: Recorded) -> None:
        self.name, self.solver, self.recorded = name, solver, recorded

    def __call__(self, **kwargs: Any) -> Any:
        self.recorded.calls.append(
            (self.name, {k: np.array(v, dtype=float) for k, v in kwargs.items()})
        )
        return self.solver(**kwargs)

    def __getattr__(self, attr: str) -> Any:
        return getattr(self.solver, attr)


def record(m: int, slots: int, seed: int) -> Recorded:
    """The horizon's IPOPT calls over one closed loop of the fleet of m UAVs (noise `seed`)."""
    from horizon_fleet import fleet_scenario

    import isac_mission.planning.nlp_model as nlp_model
    from isac_mission.experiment.closed_loop import draw_run_noise, run_closed_loop
    from isac_mission.planning.registry import planner
    from isac_mission.planning.slot import SolverKit

    recorded = Recorded()

    def factory(name: str, nlp: dict[str, Any], options: dict[str, Any], like: Any = None) -> Any:
        inner = like.solver if isinstance(like, _RecordingSolver) else like
        solver = nlp_model.plain_ipopt(name, nlp, options, inner)
        if not name.startswith("horizon"):
            return solver
        recorded.problems[name] = (nlp, options, None if like is None else like.name)
        return _RecordingSolver(name, solver, recorded)

    s = fleet_scenario(m, slots)
    kit = SolverKit(s, ipopt=factory)
    planner("horizon").prepare(kit)
    recorded.calls.clear()
    run_closed_loop(s, "horizon", draw_run_noise(s, seed), kit, lambda _: None)
    return recorded


def replay(
    recorded: Recorded, variant: dict[str, Any]
) -> list[tuple[float, int, str, float, np.ndarray]]:
    """Every recorded call solved again by the problems built with `variant` on top of their
    options: per call (seconds, iterations, status, evaluation seconds, x)."""
    import isac_mission.planning.nlp_model as nlp_model

    used = {name for name, _ in recorded.calls}
    solvers: dict[str, Any] = {}
    for name, (nlp, options, like) in recorded.problems.items():
        if name not in used and not any(recorded.problems[u][2] == name for u in used):
            continue
        ipopt = {k: v for k, v in variant.items() if k != "hess_lag"}
        opts = {**options, "ipopt": {**options["ipopt"], **ipopt}}
        if "hess_lag" in variant:  # null: CasADi's automatic Hessian
            opts.pop("hess_lag", None)
        solvers[name] = nlp_model.plain_ipopt(name, nlp, opts, solvers.get(like or ""))
    rows = []
    for name, kwargs in recorded.calls:
        started = time.perf_counter()
        sol = solvers[name](**kwargs)
        spent = time.perf_counter() - started
        stats = solvers[name].stats()
        evals = sum(v for k, v in stats.items() if k.startswith("t_wall_nlp"))
        x = np.asarray(sol["x"], dtype=float).ravel()
        rows.append((spent, int(stats["iter_count"]), str(stats["return_status"]), evals, x))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=24, help="fleet size M")
    parser.add_argument("--slots", type=int, default=30, help="slots of the recorded loop")
    parser.add_argument("--seed", type=int, default=1, help="noise seed of the recorded loop")
    parser.add_argument(
        "--variant",
        action="append",
        default=[],
        metavar="NAME=JSON",
        help="IPOPT options on top of the planner's (repeatable; the first is the reference)",
    )
    args = parser.parse_args()
    os.environ["ISAC_MISSION_COMPILE"] = "off"
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    sys.path.insert(0, str(BENCH))
    variants = dict(DEFAULT_VARIANTS)
    if args.variant:
        variants = {}
        for text in args.variant:
            name, _, options = text.partition("=")
            variants[name] = json.loads(options)
    started = time.perf_counter()
    recorded = record(args.size, args.slots, args.seed)
    print(
        f"M = {args.size}, seed {args.seed}: {len(recorded.calls)} solves recorded over "
        f"{args.slots} slots in {time.perf_counter() - started:.0f} s (load "
        f"{os.getloadavg()[0]:.2f})"
    )
    header = (
        f"{'variant':<22} {'wall s':>7} {'median ms':>9} {'iters':>6} {'ms/it':>6} "
        f"{'eval ms/it':>10} {'max |dx|':>9} {'changed':>7}"
    )
    print(header)
    reference: list[Any] | None = None
    for name, variant in variants.items():
        rows = replay(recorded, variant)
        wall = sum(r[0] for r in rows)
        iters = sum(r[1] for r in rows)
        evals = sum(r[3] for r in rows)
        reference = reference or rows
        dx = max(float(np.max(np.abs(r[4] - q[4]))) for r, q in zip(rows, reference, strict=True))
        changed = sum(r[1:3] != q[1:3] for r, q in zip(rows, reference, strict=True))
        print(
            f"{name:<22} {wall:>7.2f} {1000 * np.median([r[0] for r in rows]):>9.0f} "
            f"{iters:>6} {1000 * wall / iters:>6.1f} {1000 * evals / iters:>10.1f} "
            f"{dx:>9.1e} {changed:>7}"
        )
    print(f"load at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
