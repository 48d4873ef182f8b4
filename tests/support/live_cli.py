"""Launch `isac-mission serve` and `sim` as separate processes for the end-to-end tests."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import yaml

from isac_mission.errors import MessageError
from isac_mission.planning.registry import live_default_method
from isac_mission.records import Trace, read_trace
from tests.support.ports import SitlPorts

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_TRACE = f"trace_{live_default_method(multi_target=False)}.jsonl"
"""The trace file of a single-target `run` or `serve` without --method."""


def cli(*args: str) -> list[str]:
    """`python -m isac_mission.cli ARGS` with this interpreter; `run` and `serve` get
    `--no-console` unless ARGS choose a console address (parallel tests must not share the
    console's default port 8080)."""
    argv = list(args)
    wants_console = any(a == "--console" or a.startswith("--console=") for a in argv)
    if argv and argv[0] in ("run", "serve") and not wants_console and "--no-console" not in argv:
        argv.append("--no-console")
    return [sys.executable, "-m", "isac_mission.cli", *argv]


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


def wait_for_slots(path: Path, n: int, proc: subprocess.Popen[str], timeout_s: float) -> Trace:
    """Poll the trace file (a generous wall bound, not a timing assertion) until it holds n
    complete slots; AssertionError with the process's stderr if it exits first."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            err = proc.stderr.read() if proc.stderr else ""
            raise AssertionError(f"process exited with {proc.returncode}: {err[-3000:]}")
        if path.exists():
            try:
                trace = read_trace(path)
            except MessageError:  # created, its config line not written yet
                trace = None
            if trace is not None and len(trace.slots) >= n:
                return trace
        time.sleep(0.2)
    raise AssertionError(f"fewer than {n} slots in {path} after {timeout_s} s")


def short_mission(tmp_path: Path, n_slots: int, altitude_m: float = 40.0) -> Path:
    """config/paper.yaml with N = n_slots slots and H = altitude_m (take-off and landing in
    seconds), written under tmp_path; returns its path."""
    cfg = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    cfg["timing"]["duration_s"] = n_slots
    cfg["uavs"]["altitude_m"] = altitude_m
    config = tmp_path / "mission.yaml"
    config.write_text(yaml.safe_dump(cfg))
    return config
