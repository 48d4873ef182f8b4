"""Which live settings? Live missions (`run --lockstep`, in this process) with candidate settings.

For each variant of the live planner's settings (isac_mission/config/live_settings.py), method and
seed: one live mission on CONFIG (lockstep, --speed), and from its trace the mission-mean tr(PCRB),
location and velocity RMSE over slots 2..N (pooled over seeds), infeasible slots, the violations
of the *true* constraints 14a-14j at 1 m tolerance on the measured positions (the independent
checker, tests/support/independent), and the nearest UAV-target distance at the slot instants.

Variants: today (0.9 V_max, 1.05 R_th, D_s + 10 m, 0.8 a_max, paper kinematics), rule (the safety
rule of the scenario instead of the + 10 m, and the vehicle model), rule-kin (the safety rule,
the planner's 0.8 a_max reach instead of the vehicle model), rule+5 (the rule, the vehicle model
and D_s + 5 m).
Run: nice -n 10 python bench/live_settings.py [--variants today,rule] [--methods proposed]
     [--seeds 1..3] [--speed 10] [--plan-budget 1]
"""

from __future__ import annotations

import argparse
import asyncio
import math
import socket
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from seeds import parse_seeds  # noqa: E402

from isac_mission.bus import tcp_loopback  # noqa: E402
from isac_mission.cli.embedded import run_embedded  # noqa: E402
from isac_mission.config import load_scenario  # noqa: E402
from isac_mission.config.live_settings import LiveSettings  # noqa: E402
from isac_mission.experiment.trace_figures import trace_figures  # noqa: E402
from isac_mission.quiet import quiet_highs_banner  # noqa: E402
from isac_mission.records import read_trace  # noqa: E402
from isac_mission.service.assembly import LiveOptions  # noqa: E402
from tests.support.independent.constraints import check_constraints  # noqa: E402
from tests.support.ports import free_port_block, sitl_ports  # noqa: E402

VARIANTS = {
    "today": LiveSettings(),
    "rule": LiveSettings(safety_margin_m=0.0, vehicle_model=True),
    "rule-kin": LiveSettings(safety_margin_m=0.0),
    "rule+5": LiveSettings(safety_margin_m=5.0, vehicle_model=True),
}
LIVE_TOL_M = 1.0


def options(
    v: LiveSettings, method: str, seed: int, speed: float, out: Path, budget_s: float | None
) -> LiveOptions:
    return LiveOptions(
        speed=speed,
        plan_budget_s=budget_s,
        lockstep=True,
        method=method,  # type: ignore[arg-type]
        seed=seed,
        out_dir=out,
        zenoh_endpoint=tcp_loopback(free_port_block(1, socket.SOCK_STREAM)),
        **sitl_ports(3).world_kwargs(),
        plan_speed_fraction=v.speed_fraction,
        plan_rate_factor=v.rate_factor,
        plan_safety_margin_m=v.safety_margin_m,
        plan_accel_fraction=v.accel_fraction,
        plan_vehicle_model=v.vehicle_model,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--config", default=str(ROOT / "config" / "paper.yaml"))
    ap.add_argument("--variants", default="today,rule")
    ap.add_argument("--methods", default="proposed")
    ap.add_argument("--seeds", default="1..3")
    ap.add_argument("--speed", type=float, default=10.0)
    ap.add_argument(
        "--plan-budget", type=float, default=1.0, help="Wall s per plan (0: none), as `run`'s."
    )
    args = ap.parse_args()
    budget_s = args.plan_budget if args.plan_budget > 0 else None
    quiet_highs_banner()
    s = load_scenario(args.config)
    seeds = parse_seeds(args.seeds)
    rows = []
    for name in args.variants.split(","):
        v = VARIANTS[name]
        for method in args.methods.split(","):
            traces = []
            viol: Counter[str] = Counter()
            infeasible = 0
            nearest = math.inf
            t0 = time.monotonic()
            for seed in seeds:
                with tempfile.TemporaryDirectory() as tmp:
                    opts = options(v, method, seed, args.speed, Path(tmp), budget_s)
                    asyncio.run(run_embedded(s, opts, asyncio.Event()))
                    trace = read_trace(opts.trace_path)
                traces.append(trace)
                infeasible += sum(r.status == "infeasible" for r in trace.slots)
                viol.update(x.constraint for x in check_constraints(trace, tol_m=LIVE_TOL_M))
                for r in trace.slots:
                    if r.target_true is not None:
                        d = np.linalg.norm(np.asarray(r.uav_xy_m) - r.target_true[:2], axis=1)
                        nearest = min(nearest, float(d.min()))
            f = trace_figures(traces)
            row = (
                name,
                method,
                float(np.mean(f["pcrb"])),
                math.sqrt(float(np.mean(f["loc_mse"]))),
                math.sqrt(float(np.mean(f["vel_mse"]))),
                infeasible,
                sum(len(t.slots) for t in traces),
                dict(viol),
                nearest,
            )
            rows.append(row)
            print(f"{name} {method}: {time.monotonic() - t0:.0f} s", flush=True)
    print(
        f"\n{s.mission_id}, seeds {seeds}, lockstep at speed {args.speed:g}, plan budget "
        f"{'none' if budget_s is None else f'{budget_s:g} s'}"
    )
    print(
        f"{'variant':9s} {'method':9s} {'tr(PCRB)':>9s} {'RMSE loc':>9s} {'RMSE vel':>9s} "
        f"{'infeasible':>11s} {'nearest m':>9s}  violations (1 m)"
    )
    for name, method, pcrb, loc, vel, inf, n, viol_d, near in rows:
        print(
            f"{name:9s} {method:9s} {pcrb:9.4f} {loc:9.3f} {vel:9.4f} {inf:5d}/{n:<5d} "
            f"{near:9.1f}  {viol_d or 'none'}"
        )


if __name__ == "__main__":
    main()
