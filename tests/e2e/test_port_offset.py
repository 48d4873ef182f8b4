"""`--port-offset` and a busy Zenoh port, as a user meets them: `isac-mission run`, `serve` and
`sim` in their own processes.

- A Zenoh listen port held by another process: one line on stderr naming the endpoint, the
  port and the options that move it (`--zenoh-listen`; `--port-offset` too for the default
  port), exit 2.
- Two missions on one host, each moved with one option (`--port-offset`), fly side by side to
  the end; each one's console and ground-station link are on its own offset ports.
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from isac_mission.bus import tcp_loopback
from isac_mission.bus.settings import DEFAULT_PORT
from isac_mission.cli.ports import mission_ports
from isac_mission.config import load_scenario
from isac_mission.mavwire.dialect import mavlink2
from tests.support.live_cli import ROOT, cli, short_mission
from tests.support.ports import LOOPBACK, free_port_block, free_port_offsets, sitl_ports

CLI_TIMEOUT_S = 180.0
"""Wall bound for a refused start (interpreter and imports on a loaded 2-core machine)."""
MISSION_TIMEOUT_S = 600.0
"""Wall bound for two short missions flown at once on a loaded 2-core machine."""


@pytest.fixture
def held_zenoh_port() -> Iterator[int]:
    """A TCP port in the test blocks that another socket listens on for the test's duration
    (above 7447, so that `--port-offset (port - 7447)` lands Zenoh on it)."""
    for _ in range(50):
        port = free_port_block(1, socket.SOCK_STREAM)
        holder = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            holder.bind((LOOPBACK, port))
        except OSError:  # taken since the probe
            holder.close()
            continue
        holder.listen()
        with holder:
            yield port
        return
    raise RuntimeError("no free TCP port to hold")


def _mavlink_ports(command: str) -> list[str]:
    """Free MAVLink ports for `command` (its own options), so a run that went on (the bug) would
    not touch the defaults."""
    if command == "serve":
        return ["--mavlink-base-port", str(free_port_block(3))]
    return sitl_ports(3).cli_args()


@pytest.mark.parametrize(
    ("command", "how"),
    [
        ("run", "listen"),
        ("run", "offset"),
        ("serve", "listen"),
        ("serve", "offset"),
        ("sim", "listen"),
    ],
)
def test_a_busy_zenoh_port_is_one_line_naming_the_port_and_the_options(
    held_zenoh_port: int, command: str, how: str
) -> None:
    endpoint = tcp_loopback(held_zenoh_port)
    if how == "listen":
        moved = ["--zenoh-listen", endpoint]
    else:
        moved = ["--port-offset", str(held_zenoh_port - DEFAULT_PORT)]
    argv = cli(command, "paper", *moved, *_mavlink_ports(command))
    proc = subprocess.run(
        argv,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=CLI_TIMEOUT_S,
        check=False,
        env=os.environ | {"COLUMNS": "80"},
    )
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert len(lines) == 1, proc.stderr[-3000:]
    assert endpoint in lines[0] and f"port {held_zenoh_port} is in use" in lines[0]
    assert "--zenoh-listen" in lines[0]
    # The offset moves the default port only: it is named when it would move this one.
    assert ("--port-offset" in lines[0]) == (how == "offset")


def test_two_missions_with_different_port_offsets_fly_side_by_side(tmp_path: Path) -> None:
    config = short_mission(tmp_path, n_slots=3)
    s = load_scenario(config)
    table = mission_ports(s, 0).table(s.M)
    tcp = tuple(p for use, ports in table.items() if "TCP" in use for p in ports)
    udp = tuple(p for use, ports in table.items() if "UDP" in use for p in ports)
    offsets = free_port_offsets(tcp, udp, count=2, spacing=100)
    parser = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    with (
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as gcs_a,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as gcs_b,
    ):
        # A ground station per mission, on the mission's own ground-station port.
        for sock, offset in ((gcs_a, offsets[0]), (gcs_b, offsets[1])):
            sock.bind((LOOPBACK, table["ground station (UDP)"][0] + offset))
        procs = [
            subprocess.Popen(
                # Not `cli(...)`: the console stays on, at its offset default port.
                [
                    sys.executable,
                    "-m",
                    "isac_mission.cli",
                    "run",
                    str(config),
                    "--speed",
                    "10",
                    "--method",
                    "sd",
                    "--port-offset",
                    str(offset),
                    "--out",
                    str(tmp_path / f"run-{offset}"),
                ],
                cwd=ROOT,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                env=os.environ | {"COLUMNS": "160"},
            )
            for offset in offsets
        ]
        try:
            results = [p.communicate(timeout=MISSION_TIMEOUT_S) for p in procs]
        finally:
            for p in procs:
                if p.returncode is None:
                    p.kill()
                    p.wait()
        for sock in (gcs_a, gcs_b):
            sock.settimeout(0)
            heard = sock.recv(65535)  # the vehicles streamed here all mission long
            assert parser.parse_buffer(heard), heard[:40]
    for p, (out, err), offset in zip(procs, results, offsets, strict=True):
        assert p.returncode == 0, err[-3000:]
        assert "3/3" in out
        assert (tmp_path / f"run-{offset}" / "trace_sd.jsonl").is_file()
        console_port = table["console (TCP)"][0] + offset
        assert re.search(rf"console: http://127\.0\.0\.1:{console_port}/", out), out[:2000]
