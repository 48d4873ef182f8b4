"""Launch `isac-mission serve` and `sim` as separate processes for the end-to-end tests."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from tests.support.ports import SitlPorts

ROOT = Path(__file__).resolve().parents[2]


def cli(*args: str) -> list[str]:
    """`python -m isac_mission.cli ARGS` with this interpreter."""
    return [sys.executable, "-m", "isac_mission.cli", *args]


def start(argv: list[str], stdout: int = subprocess.PIPE) -> subprocess.Popen[str]:
    """Start argv in the repository root (text pipes, a wide console for the summary table)."""
    return subprocess.Popen(
        argv,
        cwd=ROOT,
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
        env=os.environ | {"COLUMNS": "160"},
    )


def serve_argv(config: Path, out: Path, endpoint: str, mav: int, *extra: str) -> list[str]:
    """`serve CONFIG` listening on `endpoint`, bridges on 127.0.0.1:mav + m, trace in `out`."""
    return cli(
        "serve",
        str(config),
        "--out",
        str(out),
        "--zenoh-listen",
        endpoint,
        "--mavlink-base-port",
        str(mav),
        *extra,
    )


def sim_argv(config: Path, endpoint: str, ports: SitlPorts, *extra: str) -> list[str]:
    """`sim CONFIG --speed 10 --start offboard` connecting to `endpoint`, its vehicles on the
    MAVLink ports `ports` (PX4 SITL's layout on free ports)."""
    return cli(
        "sim",
        str(config),
        "--speed",
        "10",
        "--start",
        "offboard",
        "--zenoh-connect",
        endpoint,
        *ports.cli_args(),
        *extra,
    )
