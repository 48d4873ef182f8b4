"""MAVLink over a real serial device: a simulated vehicle on one end of a pseudo-terminal pair and
the service's link (`SerialMavlinkLink`) on the other; every byte crosses two real tty devices
(tests/support/pty_pair.py). Waits are bounded by generous wall-clock deadlines."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from pathlib import Path

import pytest

from isac_mission.errors import LinkError
from isac_mission.mavwire.builders import Target, arm_command, gcs_heartbeat
from isac_mission.mavwire.serial_link import SerialMavlinkLink, SerialTransport, open_link
from sim.autopilot.settings import AutopilotSettings
from tests.support.ports import free_udp_ports
from tests.support.pty_pair import PtyCable
from tests.support.sim_harness import SimRunner, async_wait_until, wait_until

pytestmark = pytest.mark.timeout(120)
TIMEOUT_S = 30.0


async def test_service_link_hears_and_commands_a_vehicle_over_a_pty_pair(
    sim_runner: Callable[..., SimRunner],
) -> None:
    offboard, gcs = free_udp_ports(2)  # nobody listens there: only the serial link can carry it
    with PtyCable() as cable:
        settings = AutopilotSettings(
            index=1,
            offboard_port=offboard,
            gcs_port=gcs,
            bind_port=0,
            gcs_bind_port=0,
            serial_device=cable.a,
            serial_baud=57600,
        )
        runner = sim_runner([settings])
        vehicle = runner.autopilots[0]
        link = open_link(f"serial:{cable.b}:57600", system_id=2, name="serial vehicle 1")
        assert isinstance(link, SerialMavlinkLink)
        async with link:
            status = await link.wait_for(lambda st: not st.lost, TIMEOUT_S, "a heartbeat")
            assert status.system_id == 2
            assert link.local_address == (cable.b, 57600)
            link.send(gcs_heartbeat())
            await link.command(arm_command(Target(2, 1)), timeout_s=5.0)
            await async_wait_until(lambda: vehicle.armed, TIMEOUT_S, "the vehicle armed")
            await link.wait_for(lambda st: st.armed, TIMEOUT_S, "armed in its heartbeat")
            assert link.received["LOCAL_POSITION_NED"] > 0
            assert not link.errors, link.errors
        assert cable.bytes_relayed > 1000
        assert not vehicle.rejected, vehicle.rejected


async def test_a_missing_serial_device_is_a_link_error_naming_it() -> None:
    link = open_link("serial:/dev/nonexistent-tty:57600", name="vehicle 0")
    with pytest.raises(LinkError, match="vehicle 0: cannot open /dev/nonexistent-tty"):
        await link.open()
    assert not link.is_open
    await asyncio.sleep(0)


def test_a_vehicle_whose_serial_peer_never_reads_drops_bytes_and_flies_on(
    sim_runner: Callable[..., SimRunner],
) -> None:
    """Nobody reads the far end: the device's buffers fill, the vehicle's writes are dropped and
    counted, and its event loop (the simulation) never blocks on the device."""
    offboard, gcs = free_udp_ports(2)
    with PtyCable() as cable:
        settings = AutopilotSettings(
            offboard_port=offboard,
            gcs_port=gcs,
            bind_port=0,
            gcs_bind_port=0,
            serial_device=cable.a,
        )
        runner = sim_runner([settings])
        vehicle = runner.autopilots[0]
        serial_link = runner.call(lambda: vehicle._links[-1])  # the third link: the device
        transport = serial_link.transport
        assert isinstance(transport, SerialTransport)
        wait_until(lambda: transport.dropped_bytes > 0, TIMEOUT_S, "bytes dropped")
        t_s = vehicle.state.time_s
        wait_until(lambda: vehicle.state.time_s > t_s + 1.0, TIMEOUT_S, "simulation time on")


async def test_a_serial_link_that_goes_away_is_opened_again_when_its_device_is_back(
    sim_runner: Callable[..., SimRunner], tmp_path: Path
) -> None:
    """Both ends open a stable path (a symlink, as udev's /dev/serial/by-id/...); the "radio" is
    unplugged (the pty pair closes: reads fail) and another one plugged in at the same paths."""
    offboard, gcs = free_udp_ports(2)
    radio_vehicle, radio_service = tmp_path / "radio-vehicle", tmp_path / "radio-service"
    first = PtyCable()
    radio_vehicle.symlink_to(first.a)
    radio_service.symlink_to(first.b)
    settings = AutopilotSettings(
        offboard_port=offboard,
        gcs_port=gcs,
        bind_port=0,
        gcs_bind_port=0,
        serial_device=str(radio_vehicle),
    )
    sim_runner([settings])
    link = open_link(f"serial:{radio_service}", system_id=1, lost_after_s=1.0, lost_min_wall_s=1.0)
    try:
        async with link:
            await link.wait_for(lambda st: not st.lost, TIMEOUT_S, "a heartbeat over the first")
            first.close()
            await link.wait_for(lambda st: st.lost, TIMEOUT_S, "the link lost")
            with PtyCable() as second:
                for path, end in ((radio_vehicle, second.a), (radio_service, second.b)):
                    path.unlink()
                    path.symlink_to(end)
                await link.wait_for(lambda st: not st.lost, TIMEOUT_S, "heard over the second")
                transport = link._transport
                assert isinstance(transport, SerialTransport) and transport.reopens >= 1
                assert second.bytes_relayed > 0
    finally:
        if first._thread.is_alive():
            first.close()
