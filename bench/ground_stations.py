"""How soon a ground station hears the fleet: the wall-clock figures that
tests/e2e/test_ground_stations.py prints (a test waits for the fleet; this bench times it).

Starts `isac-mission sim config/paper.yaml --speed 10 --start offboard` with a real MAVProxy on
the ground-station port (free loopback ports, PX4 SITL's layout) and a pymavlink listener on
MAVProxy's `--out`, --repeats times, and prints per run and as medians:
- first heartbeat: from the process start to the first system id heard through MAVProxy (s);
- spread: from the first system id's first heartbeat to the last one's (s; target <= 5 s).
Run: python bench/ground_stations.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from isac_mission.bus import tcp_loopback  # noqa: E402
from tests.support.browser import stop  # noqa: E402
from tests.support.live_cli import sim_argv, start  # noqa: E402
from tests.support.mavproxy import MavlinkListener, MavProxy  # noqa: E402
from tests.support.ports import free_port_block, sitl_ports  # noqa: E402

SPREAD_TARGET_S = 5.0
WAIT_S = 120.0


def one_run(m: int) -> tuple[float, float]:
    """(first heartbeat after process start, spread of the first heartbeats), wall seconds."""
    ports = sitl_ports(m)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    with (
        MavlinkListener() as seen,
        MavProxy(f"udpin:127.0.0.1:{ports.gcs}", [seen.out]),
    ):
        started = time.monotonic()
        sim = start(
            sim_argv(ROOT / "config" / "paper.yaml", endpoint, ports), stdout=subprocess.DEVNULL
        )
        try:
            seen.wait_for_systems(set(range(1, m + 1)), timeout_s=WAIT_S)
        finally:
            stop(sim, 60.0)  # SIGINT: the vehicles land; SIGKILL after a minute
        first = seen.first_heard_s
        return min(first.values()) - started, max(first.values()) - min(first.values())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    rows = [one_run(3) for _ in range(args.repeats)]
    print(f"{'run':>4} {'first heartbeat s':>18} {'spread s':>9}")
    for i, (first, spread) in enumerate(rows):
        print(f"{i:>4} {first:>18.2f} {spread:>9.2f}")
    firsts, spreads = np.array(rows).T
    print(
        f"median first heartbeat {np.median(firsts):.2f} s, median spread {np.median(spreads):.2f} s,"
        f" max spread {spreads.max():.2f} s (target <= {SPREAD_TARGET_S:g} s:"
        f" {'met' if spreads.max() <= SPREAD_TARGET_S else 'missed'})"
    )


if __name__ == "__main__":
    main()
