"""The main job, `./scripts/demo.sh`, on a machine that cannot keep its pace: the planner takes
longer than two of the demo's slots for every plan (tests/support/slow_solve.py), which free-running
would fly on dropped plans. The demo's own command line (read from the script) flies every
plan, and the summary says so with its verdict."""

from __future__ import annotations

import re
import shlex
import socket
import sys
from pathlib import Path

from isac_mission.bus import tcp_loopback
from isac_mission.records import read_trace
from tests.support.live_cli import DEFAULT_TRACE, short_mission, start
from tests.support.ports import free_port_block, sitl_ports

ROOT = Path(__file__).resolve().parents[2]
SLOW_PLAN_S = 0.6
"""Wall seconds every plan takes: more than two slots at the demo's --speed 4 (0.5 s), the
point past which a free-running plan is late (timebase.plan_is_late), and within the 1 s budget."""


def demo_command() -> list[str]:
    """The `isac-mission` arguments of scripts/demo.sh's exec line, without "$@"."""
    line = next(
        ln
        for ln in (ROOT / "scripts" / "demo.sh").read_text().splitlines()
        if ln.startswith("exec isac-mission ")
    )
    return [a for a in shlex.split(line)[2:] if a != "$@"]


def test_the_demo_flies_every_plan_when_the_machine_cannot_keep_its_pace(tmp_path: Path) -> None:
    args = demo_command()
    assert args[:2] == ["run", "config/paper.yaml"], args
    n_slots = 6
    config = short_mission(tmp_path, n_slots, altitude_m=10.0)
    out = tmp_path / "demo"
    endpoint, ports = tcp_loopback(free_port_block(1, socket.SOCK_STREAM)), sitl_ports(3)
    argv = [
        *("run", str(config), *args[2:], "--out", str(out), "--no-console"),
        *("--zenoh-listen", endpoint, *ports.cli_args()),
    ]
    proc = start(
        [sys.executable, "-m", "tests.support.slow_solve", "every", str(SLOW_PLAN_S), *argv]
    )
    try:
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr[-3000:]
    assert "slow solve started" in stderr
    flat = " ".join(stdout.split())
    assert "plans late" not in flat.split("verdict:", 1)[1].split("│", 1)[0], stdout[-3000:]
    assert re.search(r"plans late\s*│\s*0\s*│", stdout) or "plans late" not in stdout
    trace = read_trace(out / DEFAULT_TRACE)
    assert [r.slot for r in trace.slots] == list(range(1, n_slots + 1))
    assert not [r.slot for r in trace.slots if r.fallback == "late"]
    assert trace.end is not None and trace.end.status == "complete"
