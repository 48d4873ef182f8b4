"""Wall time of one fixed sweep: serially, on 1 local Dask worker and on 2, in the same run.

    python bench/sweep.py [--repeats 3] [--slots 10] [--runs 2]

Grid: config/paper.yaml x uavs.max_speed_mps [15, 20, 25, 30] x methods [proposed, sd] x runs.
Each timing is one full `run_serial` / `run_dask` of every task, from an empty SolverKit cache
(cleared in every process before each repeat, so each setting pays its own cvxpy compilations) on
an already started cluster whose workers have imported the package (cluster start-up is printed
separately). The three settings are interleaved within each repeat. The table shows the median
over the repeats, the minimum and maximum, and the CPU seconds our processes used (the machine
may be shared: the load average is printed before and after).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from contextlib import ExitStack, suppress
from pathlib import Path
from typing import Any

import yaml
from rich.console import Console
from rich.table import Table

from isac_mission.experiment.sweep.cluster import dask_client, run_dask
from isac_mission.experiment.sweep.grid import expand_grid, parse_grid
from isac_mission.experiment.sweep.runs import clear_kits, make_tasks, run_serial

ROOT = Path(__file__).resolve().parents[1]


def _clear_kits() -> None:
    clear_kits()


def _warm() -> str:
    import isac_mission.experiment.sweep.runs  # noqa: F401  (import cvxpy & co. before timing)

    return "ok"


def _cpu_s() -> float:
    """CPU seconds (user + system) used so far by this process and its children (the workers)."""
    import psutil

    me = psutil.Process()
    total = 0.0
    for proc in [me, *me.children(recursive=True)]:
        with suppress(psutil.Error):
            t = proc.cpu_times()
            total += t.user + t.system
    return total


def main() -> None:
    """Time the grid in each setting and print the table and the 1 -> 2 worker speed-up."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--slots", type=int, default=10)
    ap.add_argument("--runs", type=int, default=2)
    args = ap.parse_args()

    base: dict[str, Any] = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    grid = parse_grid(
        {
            "uavs.max_speed_mps": [15, 20, 25, 30],
            "methods": ["proposed", "sd"],
            "runs": args.runs,
            "slots": args.slots,
        }
    )
    points = expand_grid(base, grid)
    tasks = make_tasks(points, grid, seed=1)
    console = Console()
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    console.print(f"load average before the run (1, 5, 15 min): {load} on {os.cpu_count()} cores")
    console.print(
        f"grid: {len(points)} points x {len(grid.methods)} methods x {grid.runs} runs = "
        f"{len(tasks)} missions of {args.slots} slots; {args.repeats} repeats per setting"
    )

    _clear_kits()
    run_serial(tasks[:1])  # import and first-solve warm-up of this process
    names = ("serial (no Dask)", "Dask, 1 worker(s)", "Dask, 2 worker(s)")
    times: dict[str, list[float]] = {n: [] for n in names}
    cpu_s: dict[str, list[float]] = {n: [] for n in names}
    with ExitStack() as stack:
        clients = {}
        for workers in (1, 2):
            t0 = time.perf_counter()
            clients[workers] = stack.enter_context(dask_client(None, workers))
            clients[workers].run(_warm)
            console.print(f"{workers} worker(s): cluster start-up {time.perf_counter() - t0:.1f} s")
        # Settings interleaved within each repeat, so that drifting load from other processes on
        # the machine affects all three alike.
        for _ in range(args.repeats):
            _clear_kits()
            c0, t0 = _cpu_s(), time.perf_counter()
            reference = run_serial(tasks)
            times[names[0]].append(time.perf_counter() - t0)
            cpu_s[names[0]].append(_cpu_s() - c0)
            for workers, name in ((1, names[1]), (2, names[2])):
                client = clients[workers]
                client.run(_clear_kits)
                c0, t0 = _cpu_s(), time.perf_counter()
                rows = run_dask(client, tasks)
                times[name].append(time.perf_counter() - t0)
                cpu_s[name].append(_cpu_s() - c0)
                diff = [
                    abs(a.loc_mse - b.loc_mse) / a.loc_mse
                    for a, b in zip(reference, rows, strict=True)
                    if (a.loc_mse, a.vel_mse, a.pcrb_pos) != (b.loc_mse, b.vel_mse, b.pcrb_pos)
                ]
                if diff:
                    console.print(
                        f"[red]{len(diff)} of {len(rows)} missions differ from the serial run "
                        f"(max relative loc MSE difference {max(diff):.2e})"
                    )

    table = Table(title=f"sweep wall time, s (median of {args.repeats})")
    for col in ("setting", "median", "min", "max", "missions/s", "CPU s (ours)"):
        table.add_column(col, justify="left" if col == "setting" else "right")
    for name, ts in times.items():
        med = statistics.median(ts)
        table.add_row(
            name,
            f"{med:.2f}",
            f"{min(ts):.2f}",
            f"{max(ts):.2f}",
            f"{len(tasks) / med:.2f}",
            f"{statistics.median(cpu_s[name]):.2f}",
        )
    console.print(table)
    one = statistics.median(times["Dask, 1 worker(s)"])
    two = statistics.median(times["Dask, 2 worker(s)"])
    serial = statistics.median(times["serial (no Dask)"])
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    console.print(f"load average after the run (1, 5, 15 min): {load} on {os.cpu_count()} cores")
    console.print(
        f"speed-up 1 -> 2 workers: {one / two:.2f}x   serial -> 2 workers: {serial / two:.2f}x"
    )


if __name__ == "__main__":
    main()
