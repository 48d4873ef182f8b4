"""`serve` reaching its vehicles as deployed ones are reached: through MAVProxy used as a MAVLink
router, and over a serial link (a pseudo-terminal pair), with `sim` in another process.

Router: the fleet's ground-station links all reach one MAVProxy (`--master=udpin:...:GCS`), which
forwards everything to one `--out` per bridge (`serve --mavlink-base-port P`: bridge m on P + m)
and their commands back to every vehicle; the vehicles' own offboard links go to ports where
nobody listens, so every byte between `serve` and `sim` passes MAVProxy.

Serial: vehicle 1 also speaks MAVLink on one end of a pty pair (`sim --serial-link 1=DEV`) and
`serve --vehicle-link 1=serial:DEV2` opens the other end; vehicle 1's UDP offboard port has no
listener, so it is flown over the tty devices only.
"""

from __future__ import annotations

import re
import signal
import socket
import subprocess
from pathlib import Path

import pytest
import yaml

from isac_mission.bus import tcp_loopback
from isac_mission.records import read_trace
from tests.support.independent.constraints import check_constraints
from tests.support.live_cli import DEFAULT_TRACE, ROOT, serve_argv, sim_argv, start
from tests.support.mavproxy import MavProxy
from tests.support.ports import free_port_block, sitl_ports, sitl_ports_and_blocks
from tests.support.pty_pair import PtyCable

pytestmark = pytest.mark.timeout(600)
SLOTS = 8
LIVE_TOL_M = 1.0


def _short_config(tmp_path: Path) -> Path:
    cfg = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    cfg["timing"]["duration_s"] = SLOTS
    cfg["uavs"]["altitude_m"] = 30  # take-off and landing in seconds
    path = tmp_path / "short.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def _fly(serve: subprocess.Popen[str], sim: subprocess.Popen[str]) -> str:
    """Wait for `serve` to finish the mission, stop `sim`; serve's stdout."""
    try:
        serve_out, serve_err = serve.communicate(timeout=420)
        assert serve.returncode == 0, serve_err[-3000:]
        sim.send_signal(signal.SIGINT)
        _, sim_err = sim.communicate(timeout=60)
        assert sim.returncode == 0, sim_err[-3000:]
        return serve_out
    finally:
        for p in (serve, sim):
            if p.poll() is None:
                p.kill()
                p.communicate()


def _check_mission(serve_out: str, out: Path) -> None:
    assert f"{SLOTS}/{SLOTS}" in serve_out, serve_out[-2000:]
    assert re.search(r"vehicles landed\s*│\s*3\s*│", serve_out), serve_out[-2000:]
    trace = read_trace(out / DEFAULT_TRACE)
    assert [r.slot for r in trace.slots] == list(range(1, SLOTS + 1))
    assert check_constraints(trace, tol_m=LIVE_TOL_M) == []


def test_serve_flies_a_mission_through_mavproxy_as_a_router(tmp_path: Path) -> None:
    config = _short_config(tmp_path)
    # sim: offboard links to ports.offboard_base + m (nobody there); serve: bridge m on
    # service_base + m (a block disjoint from the vehicles' and the router's ports).
    ports, (service_base,) = sitl_ports_and_blocks(3, (3,))
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    outs = [f"udp:127.0.0.1:{service_base + m}" for m in range(3)]
    out = tmp_path / "serve"
    with MavProxy(f"udpin:127.0.0.1:{ports.gcs}", outs) as router:
        serve = start(serve_argv(config, out, endpoint, service_base))
        sim = start(sim_argv(config, endpoint, ports, "--speed", "3"))
        serve_out = _fly(serve, sim)
        router.wait_for(r"Detected vehicle 3:1", timeout_s=10)
    _check_mission(serve_out, out)


def test_serve_flies_one_vehicle_over_a_pseudo_terminal_serial_link(tmp_path: Path) -> None:
    config = _short_config(tmp_path)
    ports = sitl_ports(3)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    out = tmp_path / "serve"
    with PtyCable() as cable:
        # Vehicle 1's UDP offboard port (base + 1) has no bridge: serve uses the tty instead.
        serve = start(
            serve_argv(
                config, out, endpoint, ports.offboard_base, "--vehicle-link", f"1=serial:{cable.b}"
            )
        )
        sim = start(
            sim_argv(config, endpoint, ports, "--speed", "3", "--serial-link", f"1={cable.a}")
        )
        serve_out = _fly(serve, sim)
        relayed = cable.bytes_relayed
    _check_mission(serve_out, out)
    assert relayed > 10_000
