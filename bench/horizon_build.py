"""What the horizon's IPOPT problems cost to build, per fleet size and pair band
(docs/performance.md, "Convergence in the soak's tracking phase": the second instance).

For each M (the fleets of bench/horizon_fleet.py), one kit builds every horizon NLP of its bands
(`kit_pair_bands`), interpreted: each band's NLP total, and within it the nlpsol builds of the
cold instance and of the warm-start one; then the kit's warm-up plan (polish, the per-slot
problems). With --tree DIR the package in DIR is built instead (a tree from `git archive COMMIT
isac_mission | tar -x -C DIR`), for a before/after in one session; run both on a quiet machine,
one after the other.

Run: python bench/horizon_build.py [--sizes 12,24] [--tree DIR]
"""

from __future__ import annotations

import argparse
import inspect
import os
import sys
import time
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="12,24", help="fleet sizes M, comma-separated")
    parser.add_argument("--tree", type=Path, default=None, help="build this tree's package")
    args = parser.parse_args()
    os.environ["ISAC_MISSION_COMPILE"] = "off"
    sys.path.insert(0, str(BENCH))
    if args.tree is not None:
        sys.path.insert(0, str(args.tree.resolve()))
    from horizon_fleet import fleet_scenario

    import isac_mission.planning.nlp_model as nlp_model
    from isac_mission.planning.horizon import horizon_nlp, kit_pair_bands
    from isac_mission.planning.registry import planner
    from isac_mission.planning.slot import SolverKit

    shares = "like" in inspect.signature(nlp_model.plain_ipopt).parameters
    print(f"package: {Path(nlp_model.__file__).parents[2]} (warm instance shares: {shares})")
    print(f"{'M':>3} {'band':>4} {'cold s':>7} {'warm s':>7} {'NLP s':>7}")
    builds: dict[str, float] = {}

    def timed(name: str, nlp: dict[str, Any], options: dict[str, Any], **kw: Any) -> Any:
        started = time.perf_counter()
        solver = nlp_model.plain_ipopt(name, nlp, options, **kw)
        builds[name] = time.perf_counter() - started
        return solver

    for m in (int(x) for x in args.sizes.split(",")):
        kit = SolverKit(fleet_scenario(m, 60), ipopt=timed)
        total = 0.0
        for band in kit_pair_bands(kit):
            builds.clear()
            started = time.perf_counter()
            horizon_nlp(kit, band)
            spent = time.perf_counter() - started
            total += spent
            cold = next(v for k, v in builds.items() if not k.endswith("_warm"))
            warm = next(v for k, v in builds.items() if k.endswith("_warm"))
            print(f"{m:>3} {band:>4} {cold:>7.2f} {warm:>7.2f} {spent:>7.2f}")
        started = time.perf_counter()
        planner("horizon").prepare(kit)
        warm_up_s = time.perf_counter() - started
        print(f"{m:>3}  all {'':>7} {'':>7} {total:>7.2f}  + warm-up {warm_up_s:.2f} s")


if __name__ == "__main__":
    main()
