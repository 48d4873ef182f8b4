"""ZenohBus over real Zenoh sessions on loopback (peer mode, explicit endpoints, no scouting)."""

from __future__ import annotations

import asyncio
import json

import pytest

from isac_mission.bus import DEFAULT_ENDPOINT, BusSettings, ZenohBus, make_config, tcp_loopback
from isac_mission.errors import ConfigError
from isac_mission.wire import Keys, uav_index
from tests.support.ports import free_tcp_port

TIMEOUT_S = 20.0


async def test_publish_subscribe_round_trip_between_two_peer_sessions() -> None:
    endpoint = tcp_loopback(free_tcp_port())
    keys = Keys("bus-test")
    async with (
        await ZenohBus.open_async(BusSettings.hub(endpoint)) as hub,
        await ZenohBus.open_async(BusSettings(connect=(endpoint,))) as leaf,
    ):
        async with leaf.subscribe(keys.detections_all) as sub:
            assert await hub.wait_for_subscribers(keys.detections(2), TIMEOUT_S)
            hub.publish(keys.detections(2), b'{"hello": 1}')
            hub.publish(keys.clock, b"not for this subscriber")
            hub.publish(keys.detections(0), b"\x00\xff binary ok")
            first = await sub.get(TIMEOUT_S)
            second = await sub.get(TIMEOUT_S)
        assert first == (keys.detections(2), b'{"hello": 1}')
        assert second == (keys.detections(0), b"\x00\xff binary ok")
        assert uav_index(first[0]) == 2
        assert sub.closed


async def test_leaf_publishes_to_hub_and_iteration_ends_on_close() -> None:
    endpoint = tcp_loopback(free_tcp_port())
    keys = Keys("bus-test")
    hub = await ZenohBus.open_async(BusSettings.hub(endpoint))
    leaf = await ZenohBus.open_async(BusSettings(connect=(endpoint,)))
    try:
        sub = hub.subscribe(keys.plan)
        assert await leaf.wait_for_subscribers(keys.plan, TIMEOUT_S)
        for i in range(3):
            leaf.publish(keys.plan, f"{i}".encode())
        got: list[bytes] = []

        async def consume() -> None:
            async for _key, data in sub:
                got.append(data)
                if len(got) == 3:
                    hub.close()  # closes the subscription too: the loop must end

        await asyncio.wait_for(consume(), TIMEOUT_S)
        assert got == [b"0", b"1", b"2"]
        assert hub.closed and sub.closed
    finally:
        leaf.close()
        hub.close()  # idempotent


def test_default_settings_are_loopback_without_multicast() -> None:
    s = BusSettings()
    assert s.mode == "peer" and s.connect == (DEFAULT_ENDPOINT,) and s.listen == ()
    cfg = make_config(s)
    assert json.loads(cfg.get_json("scouting/multicast/enabled")) is False
    assert json.loads(cfg.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(cfg.get_json("listen/endpoints")) == []
    assert json.loads(cfg.get_json("mode")) == "peer"
    hub = make_config(BusSettings.hub())
    assert json.loads(hub.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]


@pytest.mark.parametrize(
    "endpoint", ["tcp/0.0.0.0:7447", "tcp/[::]:7447", "tcp/192.168.1.5:7447", "tcp/example.org:1"]
)
def test_non_loopback_endpoints_need_an_explicit_opt_in(endpoint: str) -> None:
    with pytest.raises(ConfigError, match="not loopback"):
        BusSettings(connect=(endpoint,))
    assert BusSettings(connect=(endpoint,), allow_non_loopback=True).connect == (endpoint,)


@pytest.mark.parametrize("endpoint", ["127.0.0.1:7447", "tcp/127.0.0.1", "tcp/127.0.0.1:99999"])
def test_malformed_endpoints_are_refused(endpoint: str) -> None:
    with pytest.raises(ConfigError, match="expected proto/host:port"):
        BusSettings(listen=(endpoint,))


def test_bus_settings_refuse_wrong_types_with_config_error_naming_the_setting() -> None:
    with pytest.raises(ConfigError, match="zenoh multicast_scouting"):
        BusSettings(multicast_scouting="yes")
    with pytest.raises(ConfigError, match="zenoh mode: expected peer, client or router"):
        BusSettings(mode="mesh")
    with pytest.raises(ConfigError, match="zenoh connect_timeout_ms: must be > 0"):
        BusSettings(connect_timeout_ms=0)
    with pytest.raises(ConfigError, match="zenoh bogus"):
        BusSettings(bogus=1)
    with pytest.raises(ConfigError, match="expected a sequence of endpoints"):
        BusSettings(connect="tcp/127.0.0.1:7447")
    s = BusSettings(listen=["tcp/127.0.0.1:1"], connect=[])
    assert (s.listen, s.connect) == (("tcp/127.0.0.1:1",), ())
    assert s.with_changes(mode="client").mode == "client" and s.mode == "peer"
    with pytest.raises(ConfigError, match="not loopback"):
        s.with_changes(connect=("tcp/10.0.0.1:7447",))


def test_keys_follow_the_design() -> None:
    k = Keys("paper")
    assert k.detections(0) == "isac/paper/detections/0"
    assert k.telemetry(2) == "isac/paper/telemetry/2"
    assert (k.plan, k.track, k.clock, k.truth, k.health) == (
        "isac/paper/plan",
        "isac/paper/track",
        "isac/paper/clock",
        "isac/paper/truth",
        "isac/paper/health",
    )
    with pytest.raises(ConfigError):
        Keys("bad/id")


async def test_a_cancellation_that_arrives_with_a_sample_is_not_swallowed() -> None:
    """`get` inside an enclosing timeout: a sample handed over in the same loop iteration as the
    cancellation must not eat it (Python 3.11's wait_for did: the window of a test never closed),
    and the sample stays queued for the next `get`."""
    endpoint = tcp_loopback(free_tcp_port())
    async with (
        await ZenohBus.open_async(BusSettings.hub(endpoint)) as bus,
        bus.subscribe("bus-test/cancel/**") as sub,
    ):
        getter = asyncio.create_task(sub.get(TIMEOUT_S))
        await asyncio.sleep(0)  # the getter now waits on the queue
        sub._deliver(("bus-test/cancel/a", b"1"))  # what the Zenoh thread's callback does
        getter.cancel()
        with pytest.raises(asyncio.CancelledError):
            await getter
        assert await sub.get(TIMEOUT_S) == ("bus-test/cancel/a", b"1")
