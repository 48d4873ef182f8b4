"""A Zenoh listen port held by another process: `ZenohBus.open` says so (PortInUseError naming
the endpoint and the port), and `check_listen_endpoints` finds it before anything opens."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.bus.session import check_listen_endpoints, listen_port_in_use
from isac_mission.errors import ConfigError, PortInUseError
from tests.support.ports import LOOPBACK, free_tcp_port


@pytest.fixture
def held_port() -> Iterator[int]:
    """A TCP port on 127.0.0.1 that another socket listens on for the test's duration."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as holder:
        holder.bind((LOOPBACK, 0))
        holder.listen()
        yield int(holder.getsockname()[1])


def test_opening_a_session_on_a_held_port_raises_port_in_use(held_port: int) -> None:
    endpoint = tcp_loopback(held_port)
    with pytest.raises(PortInUseError) as caught:
        ZenohBus.open(BusSettings.hub(endpoint))
    err = caught.value
    assert isinstance(err, ConfigError)  # callers that catch ConfigError still do
    assert (err.port, err.endpoint) == (held_port, endpoint)
    assert str(err) == (
        f"zenoh: cannot listen on {endpoint}: port {held_port} is in use by another process"
    )


def test_the_check_finds_a_held_port_and_passes_a_free_one(held_port: int) -> None:
    free = tcp_loopback(free_tcp_port())
    assert listen_port_in_use(tcp_loopback(held_port))
    assert not listen_port_in_use(free)
    assert not listen_port_in_use("tcp/127.0.0.1:0")  # ephemeral: never in use
    check_listen_endpoints((free,))
    with pytest.raises(PortInUseError, match=rf"port {held_port} is in use"):
        check_listen_endpoints((free, tcp_loopback(held_port)))
    # The port is free again once the check is done (it only probed).
    with ZenohBus.open(BusSettings.hub(free)):
        pass


def test_a_failure_that_is_not_a_held_port_stays_a_config_error() -> None:
    # A client with nothing to connect to: Zenoh refuses to open, for another reason.
    settings = BusSettings(
        mode="client", connect=(tcp_loopback(free_tcp_port()),), connect_timeout_ms=500
    )
    with pytest.raises(ConfigError) as caught:
        ZenohBus.open(settings)
    assert not isinstance(caught.value, PortInUseError)
