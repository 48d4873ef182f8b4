"""A real MAVProxy on the ground-station port sees the whole fleet (PX4 SITL's port layout).

Every vehicle sends its ground-station link to one port (14550 by default, a free port here) from
its own local port (18570 + m): one MAVProxy `--master=udpin:127.0.0.1:PORT` hears system ids
1..M, and its commands, sent back from that port, reach the vehicle they name. MAVProxy forwards
what it hears to `--out=udp:127.0.0.1:X`, where a pymavlink listener records the heartbeats.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import time
from pathlib import Path

import yaml

from isac_mission.bus import tcp_loopback
from isac_mission.config import load_scenario
from tests.support.live_cli import ROOT, cli, sim_argv, start
from tests.support.mavproxy import MavlinkListener, MavProxy
from tests.support.ports import free_port_block, sitl_ports

START_TIMEOUT_S = 120.0
"""Interpreter start, imports and Zenoh on a loaded 2-core machine (wall seconds): a bound on
the wait, not a timing claim (how soon the fleet is heard is measured by
bench/ground_stations.py, target every system id within 5 s of the first)."""


def _stop(proc: subprocess.Popen[str]) -> None:
    """SIGINT (the vehicles land, the process exits), then SIGKILL after a minute."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()


def _wait_for_fleet(seen: MavlinkListener, n: int, proc: subprocess.Popen[str]) -> float:
    """Wait for the first vehicle, then for all n system ids (generous bounds: process start on a
    loaded machine); the spread between the first and the last first heartbeat, wall seconds
    (printed; its target is a benchmark's)."""
    started = time.monotonic()
    deadline = started + START_TIMEOUT_S
    while not seen.systems():
        assert proc.poll() is None, proc.communicate()[1][-3000:]
        assert time.monotonic() < deadline, "no heartbeat through MAVProxy"
        time.sleep(0.05)
    seen.wait_for_systems(set(range(1, n + 1)), timeout_s=START_TIMEOUT_S)
    first = seen.first_heard_s
    print(f"first heartbeat {min(first.values()) - started:.2f} s after the wait began")
    return max(first.values()) - min(first.values())


def test_one_mavproxy_on_the_gcs_port_sees_every_vehicle_of_sim_and_commands_one() -> None:
    scenario = load_scenario(ROOT / "config" / "paper.yaml")
    ports = sitl_ports(scenario.M)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    with (
        MavlinkListener() as seen,
        MavProxy(f"udpin:127.0.0.1:{ports.gcs}", [seen.out]) as mavproxy,
    ):
        sim = start(sim_argv(ROOT / "config" / "paper.yaml", endpoint, ports))
        try:
            spread_s = _wait_for_fleet(seen, scenario.M, sim)
            print(f"all {scenario.M} system ids through MAVProxy within {spread_s:.2f} s")
            mavproxy.wait_for(r"Detected vehicle 3:1", timeout_s=30)
            # A command typed into MAVProxy goes back on the GCS link to the vehicle it names.
            mark = mavproxy.mark()
            mavproxy.send("vehicle 2")
            mavproxy.send("arm throttle")
            mavproxy.wait_for(r"COMPONENT_ARM_DISARM: ACCEPTED", timeout_s=30, since=mark)
            deadline = time.monotonic() + 30
            while not seen.heartbeats[2].base_mode & 128:  # MAV_MODE_FLAG_SAFETY_ARMED
                assert time.monotonic() < deadline, "vehicle 2 never reported armed"
                time.sleep(0.05)
            assert not seen.heartbeats[1].base_mode & 128
            assert not seen.heartbeats[3].base_mode & 128
        finally:
            _stop(sim)


def test_mavproxy_on_the_gcs_port_sees_every_vehicle_of_run(tmp_path: Path) -> None:
    cfg = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    cfg["timing"]["duration_s"] = 5
    cfg["uavs"]["altitude_m"] = 30
    config = tmp_path / "short.yaml"
    config.write_text(yaml.safe_dump(cfg))
    ports = sitl_ports(3)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    with MavlinkListener() as seen, MavProxy(f"udpin:127.0.0.1:{ports.gcs}", [seen.out]):
        run = start(
            cli(
                "run",
                str(config),
                "--speed",
                "4",
                "--out",
                str(tmp_path / "run"),
                "--zenoh-listen",
                endpoint,
                *ports.cli_args(),
            )
        )
        try:
            spread_s = _wait_for_fleet(seen, 3, run)
            print(f"all 3 system ids of run through MAVProxy within {spread_s:.2f} s")
            # The embedded bridges fly them: MAVProxy sees OFFBOARD on every vehicle.
            for sysid in (1, 2, 3):
                seen.wait_for_mode(sysid, "offboard", timeout_s=START_TIMEOUT_S)
        finally:
            _stop(run)


def test_vehicle_m_sends_its_gcs_link_from_gcs_local_base_plus_m() -> None:
    """Vehicle m's GCS packets come from gcs_local_base + m (PX4 SITL's 18570 + m)."""
    ports = sitl_ports(3)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", ports.gcs))
    sock.settimeout(1.0)
    sim = start(sim_argv(ROOT / "config" / "paper.yaml", endpoint, ports))
    try:
        senders: set[int] = set()
        deadline = time.monotonic() + START_TIMEOUT_S
        while len(senders) < 3 and time.monotonic() < deadline:
            try:
                _, (host, port) = sock.recvfrom(4096)
            except TimeoutError:
                continue
            assert host == "127.0.0.1"
            senders.add(port)
        assert senders == {ports.gcs_local_base + m for m in range(3)}
    finally:
        sock.close()
        _stop(sim)
