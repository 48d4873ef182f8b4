"""Live against `simulate --live-settings`, over seeds: does the offline study predict the service?

For each method and seed: `isac-mission run CONFIG --lockstep --speed 10 --method M --seed S`
(or free-running with --free-running, e.g. at --speed 2; free loopback ports, no console; one
mission at a time) and `isac-mission simulate CONFIG --live-settings --runs 1 --seed S --methods M`
(the offline twin, same settings as the live planner). From the traces
(isac_mission/experiment/trace_figures.py), per seed: tr(PCRB) over the mission and over slots
11..N (the tracking phase; the first ten slots, bound about 6-7 for every method, dominate the
mission mean), location RMSE over 2..N and 11..N, the mean step per UAV per slot over 2..N and
11..N, and the slots whose method's answer was not flown (the traces' `fallback`).

Prints (and writes to --out/live_compare.json):
1. per method, live and simulate side by side (means over seeds, RMSEs pooled), and live's %
   deviation from simulate on tr(PCRB) 11..N (target: within 20 %) and the step 11..N (within
   10 %), with paired bootstrap 95 % intervals over seeds; the fallbacks by kind;
2. per method, its % reduction against `sd` and against `proposed`, live and simulate, over the
   mission and over 11..N, with paired bootstrap 95 % intervals over seeds;
3. how many live missions exited with status 0.

Run: nice -n 10 python bench/live_compare.py [--seeds 1..10] [--methods proposed,sd,aba,horizon]
     [--config config/paper.yaml] [--speed 10] [--free-running] [--plan-budget 1]
     [--out out/live-compare] [--reuse]
(default methods: proposed, sd, aba, and horizon when planning.slot.METHODS has it). A live
mission takes 25-60 s in lockstep at speed 10 and about 90 s free-running at speed 2 (take-off
and the flight to the start points included). --plan-budget is `run`'s (default 1 s): on a
loaded machine a plan that takes longer is a hold, which the live figures then include (the
traces count them: fallback "timeout"). --reuse keeps traces already in --out (a re-run only
flies what is missing). To see why one live mission differs from its twin, replay its trace:
`isac-mission replay CONFIG TRACE` (docs/performance.md, "Live against offline").
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from seeds import parse_seeds  # noqa: E402

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

FIGS = {
    "pcrb": reduction_of_means,
    "pcrb_from11": reduction_of_means,
    "loc_mse": reduction_of_rms,
    "loc_mse_from11": reduction_of_rms,
    "vel_mse": reduction_of_rms,
    "step_m": reduction_of_means,
    "step_from11_m": reduction_of_means,
}
"""Per-seed figures (experiment/trace_figures.py) and the paired statistic of each."""
HEADS = {
    "pcrb": "tr(PCRB)",
    "pcrb_from11": "tr(PCRB) 11..N",
    "loc_mse": "RMSE loc m",
    "loc_mse_from11": "RMSE loc 11..N",
}
"""The figures of the reduction tables."""
PHASE_KEYS = (
    "pcrb", "pcrb_from11", "loc_mse", "loc_mse_from11", "step_m", "step_from11_m", "fallbacks",
)  # fmt: skip
TARGETS = {"pcrb_from11": 0.20, "step_from11_m": 0.10}
"""Live within this fraction of simulate's mean over seeds (the live service's targets)."""
TARGET_HEADS = {"pcrb_from11": "tr(PCRB) 11..N", "step_from11_m": "step 11..N"}


def default_methods() -> list[str]:
    return [m for m in ("proposed", "sd", "aba", "horizon") if m in METHODS]


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "isac_mission.cli", *args]


def _env() -> dict[str, str]:
    return os.environ | {"COLUMNS": "160", "MAVLINK20": "1", "MAVLINK_DIALECT": "common"}


def fly_live(
    config: str,
    method: str,
    seed: int,
    speed: float,
    out: Path,
    budget_s: float,
    lockstep: bool,
    exits: list[int],
) -> Path | None:
    """One live mission (its exit status appended to `exits`); its trace, or None (the error
    is printed)."""
    trace = out / f"trace_{method}.jsonl"
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    ports = sitl_ports(3)
    argv = _cli(
        "run", config, *(["--lockstep"] if lockstep else []), "--speed", f"{speed:g}",
        "--method", method,
        "--seed", str(seed), "--plan-budget", f"{budget_s:g}", "--out", str(out),
        "--zenoh-listen", endpoint,
        *ports.cli_args(), "--no-console",
    )  # fmt: skip
    proc = subprocess.run(
        argv, cwd=ROOT, capture_output=True, text=True, env=_env(), check=False, timeout=1800
    )
    exits.append(proc.returncode)
    out.mkdir(parents=True, exist_ok=True)
    (out / SUMMARY).write_text(proc.stdout)
    if proc.returncode != 0 or not trace.is_file():
        print(
            f"  live {method} seed {seed}: FAILED (exit {proc.returncode})\n{proc.stderr[-2000:]}"
        )
        return None
    return trace


SUMMARY = "summary.txt"
"""Where each live mission's printed summary is kept (beside its trace)."""


def plans_late(trace: Path) -> int | None:
    """The `plans late` counter of the summary kept beside a live trace (plans the bridges
    dropped: they arrived more than a slot after their slot ended), None if none was kept."""
    summary = trace.parent / SUMMARY
    if not summary.is_file():
        return None
    found = re.search(r"plans late\s*│\s*(\d+)", summary.read_text())
    return int(found.group(1)) if found else 0


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
        "--free-running", action="store_true", help="Fly without --lockstep (real time x speed)."
    )
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
    exits: list[int] = []
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
                        fly_live(
                            args.config,
                            method,
                            seed,
                            args.speed,
                            where,
                            args.plan_budget,
                            not args.free_running,
                            exits,
                        )
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
    mode = f"{'free-running' if args.free_running else 'lockstep'}, speed {args.speed:g}"
    report(methods, seeds, traces, out, time.monotonic() - t0, mode, exits)


def percent_off(live: float, sim: float) -> float:
    """Live's % deviation from simulate (+: live higher); inf when simulate's is 0 and live's
    is not (a method that parks its UAVs steps 0 m)."""
    if sim == 0.0:
        return 0.0 if live == 0.0 else math.inf
    return 100.0 * (live / sim - 1.0)


def deviation(sim: np.ndarray, live: np.ndarray, key: str) -> Interval | None:
    """Live's % deviation from simulate (+: live higher), paired over seeds, 95 % BCa (None
    when simulate's mean is 0)."""
    if not np.mean(sim) > 0.0:
        return None
    iv = interval(sim, live, key)
    return None if iv is None else Interval(-iv.estimate, -iv.high, -iv.low, iv.level)


def phase_rows(figs: dict[str, np.ndarray]) -> dict[str, float]:
    """Means over seeds (RMSEs pooled) of the mission (2..N) and tracking-phase (11..N) figures."""
    return {
        "pcrb": float(np.mean(figs["pcrb"])),
        "pcrb_from11": float(np.mean(figs["pcrb_from11"])),
        "loc_mse": math.sqrt(float(np.mean(figs["loc_mse"]))),
        "loc_mse_from11": math.sqrt(float(np.mean(figs["loc_mse_from11"]))),
        "step_m": float(np.mean(figs["step_m"])),
        "step_from11_m": float(np.mean(figs["step_from11_m"])),
        "fallbacks": float(np.sum(figs["fallbacks"])),
    }


def report(
    methods: list[str],
    seeds: list[int],
    traces: dict[str, dict[str, dict[int, Path]]],
    out: Path,
    wall_s: float,
    mode: str,
    exits: list[int],
) -> None:
    """The tables, and live_compare.json."""
    # Seeds where every method flew both live and offline: the pairing needs the same seeds.
    common = [s for s in seeds if all(s in traces[k].get(m, {}) for k in traces for m in methods)]
    if len(common) < len(seeds):
        print(f"\nseeds with every run complete: {common} (of {seeds})")
    read = {k: {m: [read_trace(traces[k][m][s]) for s in common] for m in methods} for k in traces}
    figs = {k: {m: trace_figures(read[k][m]) for m in methods} for k in traces}
    result: dict[str, object] = {
        "seeds": common,
        "methods": methods,
        "mode": mode,
        "wall_s": wall_s,
        "live_exit_codes": dict(Counter(exits)),
    }
    print(f"\n{len(common)} seeds {common}; live `run` ({mode}) vs `simulate --live-settings`")
    print(f"live missions flown: {len(exits)}, exit status 0: {exits.count(0)}")
    heads = ("tr(PCRB)", "11..N", "RMSE loc", "11..N", "step m", "11..N", "fallbacks")
    print(f"{'method':9s} {'':9s} " + " ".join(f"{h:>9s}" for h in heads))
    rows: dict[str, object] = {}
    for m in methods:
        live, sim = figs["live"][m], figs["simulate"][m]
        pl, ps = phase_rows(live), phase_rows(sim)
        for kind, p in (("live", pl), ("simulate", ps)):
            print(
                f"{m if kind == 'live' else '':9s} {kind:9s} "
                + " ".join(f"{p[k]:9.4g}" for k in PHASE_KEYS)
            )
        dev = {k: percent_off(pl[k], ps[k]) for k in TARGETS}
        ivs = {k: deviation(sim[k], live[k], k) for k in TARGETS}
        ok = {k: abs(dev[k]) <= 100 * TARGETS[k] for k in TARGETS}
        print(
            f"{'':9s} live vs simulate: "
            + ", ".join(
                f"{TARGET_HEADS[k]} {cell(ivs[k])} (target {TARGETS[k]:.0%}: "
                f"{'met' if ok[k] else 'MISSED'})"
                for k in TARGETS
            )
        )
        missing = int(live["truth_missing"].sum())
        if missing:
            print(f"{'':9s} (live: {missing} slots without truth left out of the errors)")
        statuses = Counter(r.status for tr in read["live"][m] for r in tr.slots)
        fallbacks = Counter(r.fallback for tr in read["live"][m] for r in tr.slots if r.fallback)
        sim_fallbacks = Counter(
            r.fallback for tr in read["simulate"][m] for r in tr.slots if r.fallback
        )
        if fallbacks or sim_fallbacks:
            print(f"{'':9s} fallbacks live {dict(fallbacks)}; simulate {dict(sim_fallbacks)}")
        late = [plans_late(traces["live"][m][s]) for s in common]
        n_slots = sum(len(tr.slots) for tr in read["live"][m])
        if all(n is not None for n in late):
            late_total = sum(n for n in late if n is not None)
            timeouts = statuses.get("timeout", 0)
            print(
                f"{'':9s} live: {timeouts} slots over the plan budget (timeout), {late_total} "
                f"plans late (dropped by the bridges) of {n_slots} slots"
            )
        rows[m] = {
            "live": pl,
            "simulate": ps,
            "live_vs_simulate_pct": dev,
            "live_vs_simulate_interval": {
                k: None if iv is None else [iv.estimate, iv.low, iv.high] for k, iv in ivs.items()
            },
            "within": ok,
            "live_statuses": dict(statuses),
            "live_fallbacks": dict(fallbacks),
            "simulate_fallbacks": dict(sim_fallbacks),
            "per_seed": {
                k: {f: v.tolist() for f, v in figs[k][m].items()} for k in ("live", "simulate")
            },
        }
    result["figures"] = rows
    reductions: dict[str, object] = {}
    for kind in ("live", "simulate"):
        print(f"\n{kind}: % reduction against sd and proposed (paired bootstrap 95 %, over seeds)")
        print(f"{'method':9s} {'against':9s} " + " ".join(f"{HEADS[k]:>26s}" for k in HEADS))
        red: dict[str, dict[str, dict[str, list[float] | None]]] = {}
        for m in methods:
            for base in ("sd", "proposed"):
                if base == m or base not in methods:
                    continue
                ivs = {k: interval(figs[kind][base][k], figs[kind][m][k], k) for k in HEADS}
                print(f"{m:9s} {base:9s} " + " ".join(f"{cell(ivs[k]):>26s}" for k in HEADS))
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
