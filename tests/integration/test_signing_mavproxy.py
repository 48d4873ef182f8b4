"""A signed fleet and real MAVProxy ground stations: one holding the key (`signing key PASSPHRASE`,
the secret being SHA-256 of the passphrase, as `key_format: passphrase` derives it) watches every
vehicle and commands one; one without the key is refused and counted, and moves nothing.

Three simulated vehicles in PX4 SITL's port layout on free ports send their ground-station links
to one port, where the signed MAVProxy listens; the unsigned MAVProxy talks straight to vehicle
3's ground-station port (18570 + 2 style), as a second ground station would.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable

import pytest

from isac_mission.config import MavlinkSigningKey
from sim.autopilot.settings import AutopilotSettings
from tests.support.mavproxy import MavlinkListener, MavProxy
from tests.support.ports import sitl_ports
from tests.support.sim_harness import SimRunner, wait_until

pytestmark = pytest.mark.timeout(180)
PASSPHRASE = "isac-ground-station-test-passphrase"
KEY = MavlinkSigningKey(hashlib.sha256(PASSPHRASE.encode()).digest(), source="test passphrase")
TIMEOUT_S = 40.0


def test_a_signed_mavproxy_commands_the_signed_fleet_and_an_unsigned_one_is_refused(
    sim_runner: Callable[..., SimRunner],
) -> None:
    ports = sitl_ports(3)
    runner = sim_runner(
        [
            AutopilotSettings(
                index=m,
                offboard_port=ports.offboard_base + m,
                bind_port=ports.offboard_local_base + m,
                gcs_port=ports.gcs,
                gcs_bind_port=ports.gcs_local_base + m,
                spawn_xy_m=(10.0 * m, 0.0),
                signing=KEY,
            )
            for m in range(3)
        ]
    )
    vehicles = runner.autopilots
    with (
        MavlinkListener() as seen,
        MavProxy(f"udpin:127.0.0.1:{ports.gcs}", [seen.out]) as signed,
    ):
        signed.send(f"signing key {PASSPHRASE}")
        seen.wait_for_systems({1, 2, 3}, TIMEOUT_S)
        assert all(hb.get_header().incompat_flags & 1 for hb in seen.heartbeats.values())  # signed
        mark = signed.mark()
        signed.send("vehicle 2")
        signed.send("arm throttle")
        signed.wait_for(r"COMPONENT_ARM_DISARM: ACCEPTED", TIMEOUT_S, since=mark)
        wait_until(lambda: vehicles[1].armed, TIMEOUT_S, "vehicle 2 armed by the signed MAVProxy")
        assert vehicles[1].signatures_ok > 0
    assert not vehicles[0].armed and not vehicles[2].armed
    assert all(v.rejected["unsigned"] == 0 for v in vehicles), [dict(v.rejected) for v in vehicles]

    # No heartbeats and no module traffic: the only packet the unsigned MAVProxy sends is the ARM.
    with MavProxy(
        f"udpout:127.0.0.1:{ports.gcs_local_base + 2}",
        modules="cmdlong,arm",
        extra=["--heartbeat-rate=0", "--target-system=3", "--target-component=1"],
    ) as unsigned:
        unsigned.wait_for(r"Connect udpout", TIMEOUT_S)
        unsigned.send("arm throttle")
        wait_until(
            lambda: vehicles[2].rejected["unsigned"] >= 1,
            TIMEOUT_S,
            "the unsigned ARM refused and counted",
        )
    assert not vehicles[2].armed
    assert not any("ACCEPTED" in line for line in unsigned.lines)
