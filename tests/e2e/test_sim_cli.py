"""`isac-mission sim CONFIG` as its own process: detections on Zenoh, clean exit on SIGINT/SIGTERM;
with `--port-offset N` every port it uses moves by N."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import socket
import sys
from pathlib import Path

import pytest

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.cli.ports import mission_ports
from isac_mission.config import load_scenario
from isac_mission.wire import DetectionMsg, Keys, decode
from tests.support.ports import LOOPBACK, free_port_offsets, free_tcp_port, udp_sinks

ROOT = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 60.0  # interpreter start + imports on a loaded 2-core machine
EXIT_TIMEOUT_S = 30.0


@pytest.fixture
def config_path(tmp_path: Path) -> Path:
    """config/paper.yaml when the project has it; else the paper's defaults in a temporary file."""
    paper = ROOT / "config" / "paper.yaml"
    if paper.is_file():
        return paper
    path = tmp_path / "paper.yaml"
    path.write_text("mission_id: paper\n")
    return path


async def _start_sim(config_path: Path, *args: str) -> asyncio.subprocess.Process:
    """`isac-mission sim CONFIG --speed 10 ARGS` (stdout and stderr together, unbuffered)."""
    return await asyncio.create_subprocess_exec(
        *(sys.executable, "-m", "isac_mission.cli", "sim", str(config_path), "--speed", "10"),
        *args,
        cwd=ROOT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )


async def _stopped_cleanly(proc: asyncio.subprocess.Process, sig: signal.Signals) -> bytes:
    """Send `sig`, wait for the exit (bounded), check it is 0; the output."""
    proc.send_signal(sig)
    out, _ = await asyncio.wait_for(proc.communicate(), EXIT_TIMEOUT_S)
    assert proc.returncode == 0, out.decode(errors="replace")[-3000:]
    return out


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
async def test_sim_publishes_detections_and_exits_cleanly_on_signal(
    config_path: Path, sig: signal.Signals
) -> None:
    scenario = load_scenario(config_path)
    endpoint = tcp_loopback(free_tcp_port())
    keys = Keys(scenario.mission_id)
    with udp_sinks(scenario.M) as mav_base, udp_sinks(1) as gcs_port:
        observer = await ZenohBus.open_async(BusSettings.hub(endpoint))
        try:
            sub = observer.subscribe(keys.detections_all)
            proc = await _start_sim(
                config_path,
                *("--zenoh-connect", endpoint, "--mavlink-base-port", str(mav_base)),
                *("--mavlink-local-base-port", "0", "--gcs-port", str(gcs_port)),
                *("--gcs-local-base-port", "0"),
            )
            try:
                key, data = await sub.get(START_TIMEOUT_S)
                det = decode(DetectionMsg, data, n_uavs=scenario.M)
                assert key == keys.detections(det.uav)
                out = await _stopped_cleanly(proc, sig)
                assert b"world stopped" in out
            finally:
                if proc.returncode is None:
                    proc.kill()
                    await proc.wait()
        finally:
            observer.close()


async def test_sim_with_a_port_offset_meets_the_ground_and_the_gcs_on_the_offset_ports(
    config_path: Path,
) -> None:
    scenario = load_scenario(config_path)
    table = mission_ports(scenario, 0).table(scenario.M)
    tcp = tuple(p for use, ports in table.items() if "TCP" in use for p in ports)
    udp = tuple(p for use, ports in table.items() if "UDP" in use for p in ports)
    (offset,) = free_port_offsets(tcp, udp)
    moved = mission_ports(scenario, offset).table(scenario.M)
    keys = Keys(scenario.mission_id)
    with contextlib.ExitStack() as held:
        # Where the vehicles send: the service's offboard ports and the ground station's.
        sinks = []
        for port in (*moved["offboard (UDP)"], *moved["ground station (UDP)"]):
            sink = held.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
            sink.bind((LOOPBACK, port))
            sinks.append(sink)
        endpoint = tcp_loopback(moved["zenoh (TCP)"][0])
        observer = await ZenohBus.open_async(BusSettings.hub(endpoint))
        try:
            sub = observer.subscribe(keys.detections_all)
            proc = await _start_sim(config_path, "--port-offset", str(offset))
            try:
                key, data = await sub.get(START_TIMEOUT_S)
                assert key == keys.detections(decode(DetectionMsg, data, n_uavs=scenario.M).uav)
                gcs = sinks[-1]
                gcs.setblocking(False)
                datagram = await asyncio.wait_for(
                    asyncio.get_running_loop().sock_recv(gcs, 65535), START_TIMEOUT_S
                )
                assert datagram[:1] == b"\xfd"  # MAVLink 2 from a vehicle's GCS link
                await _stopped_cleanly(proc, signal.SIGINT)
            finally:
                if proc.returncode is None:
                    proc.kill()
                    await proc.wait()
        finally:
            observer.close()
