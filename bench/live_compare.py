"""Live against `simulate --live-settings`, over seeds: does the offline study predict the service?

For each method and seed: `isac-mission run CONFIG --lockstep --speed 10 --method M --seed S`
(free loopback ports, no console; one mission at a time) and `isac-mission simulate CONFIG
--live-settings --runs 1 --seed S --methods M` (the offline twin, same settings as the live
planner). From the traces (isac_mission/experiment/trace_figures.py): per seed the mission-mean
tr(PCRB), and location and velocity MSE over slots 2..N (RMSE pooled over the seeds).

Prints (and writes to --out/live_compare.json):
1. per method, live and simulate side by side: means over seeds, and whether simulate is within
   10 % of live on tr(PCRB) and location RMSE (the issue's target), with a 95 % bootstrap interval
   of simulate's % deviation from live (seeds resampled; the two draw their noise differently,
   so the pairing by seed carries only the target's path);
2. per method, its % reduction against `sd` and against `proposed`, live and simulate, with paired
   bootstrap 95 % intervals over seeds (experiment/bootstrap.py).

Run: nice -n 10 python bench/live_compare.py [--seeds 1..10] [--methods proposed,sd,aba,horizon]
     [--config config/paper.yaml] [--speed 10] [--plan-budget 1] [--out out/live-compare]
     [--reuse]
(default methods: proposed, sd, aba, and horizon when planning.slot.METHODS has it). A live
mission takes 30-60 s here (take-off and the flight to the start points included). --plan-budget
is `run`'s (default 1 s): on a loaded machine a plan that takes longer is a hold, which the live
figures then include (the run's trace says how many: status "timeout").
--reuse keeps traces already in --out (a re-run only flies what is missing).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from isac_mission.bus import tcp_loopback  # noqa: E402
from isac_mission.experiment.bootstrap import (  # noqa: E402
    Interval,
    paired_bootstrap,
    reduction_of_means,
    reduction_of_rms,
)
from isac_mission.experiment.trace_figures import trace_figures  # noqa: E402
from isac_mission.planning.slot import METHODS  # noqa: E402
from isac_mission.records import read_trace  # noqa: E402
from tests.support.ports import free_port_block, sitl_ports  # noqa: E402

WITHIN = 0.10
"""simulate's mean over seeds within 10 % of live's (tr(PCRB), location RMSE)."""
FIGS = {"pcrb": reduction_of_means, "loc_mse": reduction_of_rms, "vel_mse": reduction_of_rms}
HEADS = {"pcrb": "tr(PCRB)", "loc_mse": "RMSE loc m", "vel_mse": "RMSE vel m/s"}


def parse_seeds(text: str) -> list[int]:
    """'1..10' or '1,2,5' or '3'."""
    if ".." in text:
        a, b = text.split("..", 1)
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in text.split(",") if x.strip()]


def default_methods() -> list[str]:
    return [m for m in ("proposed", "sd", "aba", "horizon") if m in METHODS]


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "isac_mission.cli", *args]


def _env() -> dict[str, str]:
    return os.environ | {"COLUMNS": "160", "MAVLINK20": "1", "MAVLINK_DIALECT": "common"}


def fly_live(
    config: str, method: str, seed: int, speed: float, out: Path, budget_s: float
) -> Path | None:
    """One live mission; its trace, or None (the error is printed)."""
    trace = out / f"trace_{method}.jsonl"
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    ports = sitl_ports(3)
    argv = _cli(
        "run", config, "--lockstep", "--speed", f"{speed:g}", "--method", method,
        "--seed", str(seed), "--plan-budget", f"{budget_s:g}", "--out", str(out),
        "--zenoh-listen", endpoint,
        *ports.cli_args(), "--no-console",
    )  # fmt: skip
    proc = subprocess.run(
        argv, cwd=ROOT, capture_output=True, text=True, env=_env(), check=False, timeout=1800
    )
    if proc.returncode != 0 or not trace.is_file():
        print(
            f"  live {method} seed {seed}: FAILED (exit {proc.returncode})\n{proc.stderr[-2000:]}"
        )
        return None
    return trace


def run_simulate(config: str, method: str, seed: int, out: Path) -> Path | None:
    """`simulate --live-settings` for one seed; its trace, or None."""
    trace = out / "traces" / f"{method}_run000.jsonl"
    argv = _cli(
        "simulate", config, "--live-settings", "--runs", "1", "--seed", str(seed),
        "--methods", method, "--workers", "1", "--no-plots", "--out", str(out),
    )  # fmt: skip
    proc = subprocess.run(
        argv, cwd=ROOT, capture_output=True, text=True, env=_env(), check=False, timeout=1800
    )
    if proc.returncode != 0 or not trace.is_file():
        print(f"  simulate {method} seed {seed}: FAILED\n{proc.stderr[-2000:]}")
        return None
    return trace


def pooled(figs: dict[str, np.ndarray]) -> dict[str, float]:
    """Means over seeds; RMSEs pooled (sqrt of the mean MSE)."""
    return {
        "pcrb": float(np.mean(figs["pcrb"])),
        "loc_mse": math.sqrt(float(np.mean(figs["loc_mse"]))),
        "vel_mse": math.sqrt(float(np.mean(figs["vel_mse"]))),
    }


def cell(iv: Interval | None) -> str:
    return "-" if iv is None else f"{iv.estimate:+6.1f} % [{iv.low:+.1f}, {iv.high:+.1f}]"


def interval(base: np.ndarray, other: np.ndarray, key: str) -> Interval | None:
    ok = base.size >= 2 and np.all(np.isfinite(base)) and np.all(np.isfinite(other))
    return paired_bootstrap(base, other, FIGS[key]) if ok else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--config", default="config/paper.yaml")
    ap.add_argument("--seeds", default="1..10")
    ap.add_argument("--methods", default=",".join(default_methods()))
    ap.add_argument("--speed", type=float, default=10.0)
    ap.add_argument(
        "--plan-budget", type=float, default=1.0, help="`run --plan-budget` (0: no budget)."
    )
    ap.add_argument("--out", type=Path, default=Path("out/live-compare"))
    ap.add_argument("--reuse", action="store_true", help="Keep traces already in --out.")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown:
        sys.exit(f"--methods: unknown {unknown}; choose from {', '.join(METHODS)}")
    out: Path = args.out.resolve()
    t0 = time.monotonic()
    traces: dict[str, dict[str, dict[int, Path]]] = {"live": {}, "simulate": {}}
    for method in methods:
        for seed in seeds:
            for kind in ("live", "simulate"):
                where = out / kind / f"{method}_seed{seed}"
                done = (
                    where / f"trace_{method}.jsonl"
                    if kind == "live"
                    else where / "traces" / f"{method}_run000.jsonl"
                )
                if not (args.reuse and done.is_file()):
                    t1 = time.monotonic()
                    got = (
                        fly_live(args.config, method, seed, args.speed, where, args.plan_budget)
                        if kind == "live"
                        else run_simulate(args.config, method, seed, where)
                    )
                    print(
                        f"{kind:8s} {method:9s} seed {seed:3d}: "
                        f"{'ok' if got else 'failed'} in {time.monotonic() - t1:5.1f} s",
                        flush=True,
                    )
                if done.is_file():
                    traces[kind].setdefault(method, {})[seed] = done
    report(methods, seeds, traces, out, time.monotonic() - t0)


def report(
    methods: list[str],
    seeds: list[int],
    traces: dict[str, dict[str, dict[int, Path]]],
    out: Path,
    wall_s: float,
) -> None:
    """The two tables, and live_compare.json."""
    # Seeds where every method flew both live and offline: the pairing needs the same seeds.
    common = [s for s in seeds if all(s in traces[k].get(m, {}) for k in traces for m in methods)]
    if len(common) < len(seeds):
        print(f"\nseeds with every run complete: {common} (of {seeds})")
    read = {k: {m: [read_trace(traces[k][m][s]) for s in common] for m in methods} for k in traces}
    figs = {k: {m: trace_figures(read[k][m]) for m in methods} for k in traces}
    result: dict[str, object] = {"seeds": common, "methods": methods, "wall_s": wall_s}
    print(f"\n{len(common)} seeds {common}; live `run --lockstep` vs `simulate --live-settings`")
    print(
        f"{'method':9s} {'':9s} {'tr(PCRB)':>9s} {'RMSE loc':>9s} {'RMSE vel':>9s}"
        f"  simulate vs live: tr(PCRB), RMSE loc (within {WITHIN:.0%}?)"
    )
    rows: dict[str, object] = {}
    for m in methods:
        live, sim = figs["live"][m], figs["simulate"][m]
        pl, ps = pooled(live), pooled(sim)
        dev = {k: 100.0 * (ps[k] / pl[k] - 1.0) for k in ("pcrb", "loc_mse")}
        ivs = {k: interval(live[k], sim[k], k) for k in ("pcrb", "loc_mse")}
        # reduction_of_* is "% below live"; deviation = -reduction.
        dev_iv = {
            k: None if iv is None else Interval(-iv.estimate, -iv.high, -iv.low, iv.level)
            for k, iv in ivs.items()
        }
        ok = {k: abs(dev[k]) <= 100 * WITHIN for k in dev}
        for kind, p in (("live", pl), ("simulate", ps)):
            line = f"{m if kind == 'live' else '':9s} {kind:9s} {p['pcrb']:9.4f} "
            line += f"{p['loc_mse']:9.3f} {p['vel_mse']:9.4f}"
            if kind == "simulate":
                line += "  " + ", ".join(
                    f"{cell(dev_iv[k])} {'ok' if ok[k] else 'MISS'}" for k in ("pcrb", "loc_mse")
                )
            print(line)
        missing = int(live["truth_missing"].sum())
        if missing:
            print(f"{'':9s} (live: {missing} slots without truth left out of the errors)")
        statuses = Counter(r.status for tr in read["live"][m] for r in tr.slots)
        not_ok = {k: n for k, n in statuses.items() if k != "ok"}
        if not_ok:
            print(f"{'':9s} (live slots not ok: {not_ok})")
        rows[m] = {
            "live": pl,
            "simulate": ps,
            "simulate_vs_live_pct": dev,
            "within": ok,
            "live_statuses": dict(statuses),
            "per_seed": {
                k: {f: v.tolist() for f, v in figs[k][m].items()} for k in ("live", "simulate")
            },
        }
    result["figures"] = rows
    reductions: dict[str, object] = {}
    for kind in ("live", "simulate"):
        print(f"\n{kind}: % reduction against sd and proposed (paired bootstrap 95 %, over seeds)")
        print(f"{'method':9s} {'against':9s} " + " ".join(f"{HEADS[k]:>26s}" for k in FIGS))
        red: dict[str, dict[str, dict[str, list[float] | None]]] = {}
        for m in methods:
            for base in ("sd", "proposed"):
                if base == m or base not in methods:
                    continue
                ivs = {k: interval(figs[kind][base][k], figs[kind][m][k], k) for k in FIGS}
                print(f"{m:9s} {base:9s} " + " ".join(f"{cell(ivs[k]):>26s}" for k in FIGS))
                red.setdefault(m, {})[base] = {
                    k: None if iv is None else [iv.estimate, iv.low, iv.high]
                    for k, iv in ivs.items()
                }
        reductions[kind] = red
    result["reductions"] = reductions
    out.mkdir(parents=True, exist_ok=True)
    (out / "live_compare.json").write_text(json.dumps(result, indent=2))
    print(f"\n{wall_s:.0f} s wall; results: {out / 'live_compare.json'}")


if __name__ == "__main__":
    main()
