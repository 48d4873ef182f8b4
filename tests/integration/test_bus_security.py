"""Zenoh security over real sessions on loopback: user/password logins, the role ACL and TLS.

The ground loop's side (the hub) listens with the users file and the ACL; the other sessions log
in as the world, the observer or an intruder. A negative check ("not delivered") is bounded by a
sentinel that an authorised put sends after the refused one: over the same session when the role
may put anything at all (ordered on one link), else from another session, after which a second
round trip has to complete too.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import AsyncIterator
from dataclasses import replace
from pathlib import Path

import pytest

from isac_mission.bus import BusSettings, Subscription, ZenohBus, tcp_loopback
from isac_mission.bus.certs import CertFiles, generate_certs, generate_users_file
from isac_mission.bus.security import read_users_file, secured_settings
from isac_mission.cli.embedded import run_embedded
from isac_mission.config import Scenario, SecurityConfig, ZenohSecurityConfig, ZenohTlsConfig
from isac_mission.errors import ConfigError
from isac_mission.service.assembly import LiveOptions
from isac_mission.service.mission_result import summarize_live
from isac_mission.wire import Keys
from tests.support.ports import free_port_block, sitl_ports

TIMEOUT_S = 20.0
REFUSED_TIMEOUT_S = 3.0
"""How long a refused session gets to find a subscriber (it never does: it is not connected)."""
MISSION = "sec"
KEYS = Keys(MISSION)
USERS = ("ground", "world", "operator", "observer")


@pytest.fixture(scope="module")
def users_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A users file with random passwords for ground, world and observer."""
    path = tmp_path_factory.mktemp("users") / "zenoh-users.txt"
    generate_users_file(path, USERS)
    return path


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> CertFiles:
    """A local CA and a certificate for 127.0.0.1 / localhost."""
    return generate_certs(tmp_path_factory.mktemp("certs"))


def security(users_file: Path, certs: CertFiles | None = None) -> ZenohSecurityConfig:
    """security.zenoh on, with the default roles, and TLS when `certs` is given."""
    tls = (
        ZenohTlsConfig(ca_file=certs.ca_file, cert_file=certs.cert_file, key_file=certs.key_file)
        if certs is not None
        else None
    )
    return ZenohSecurityConfig(enabled=True, users_file=users_file, tls=tls)


def login(cfg: ZenohSecurityConfig, user: str, password: str | None = None) -> dict[str, str]:
    """The environment of a process that logs in as `user` (its real password unless given)."""
    assert cfg.users_file is not None
    real = read_users_file(cfg.users_file)[user]
    return {cfg.user_env: user, cfg.password_env: real if password is None else password}


def as_client(settings: BusSettings, **security: object) -> BusSettings:
    """`settings` in client mode (open fails at once without a link), security fields replaced."""
    assert settings.security is not None
    return settings.with_changes(
        mode="client",
        connect_timeout_ms=2000,
        security=replace(settings.security, **security),  # type: ignore[arg-type]
    )


def leaf(
    cfg: ZenohSecurityConfig, endpoint: str, role: str, env: dict[str, str], mode: str = "peer"
) -> BusSettings:
    """A session of `role` connecting to `endpoint` with the login in `env`."""
    s = secured_settings(cfg, MISSION, role, connect=(endpoint,), env=env)
    return s.with_changes(mode=mode, connect_timeout_ms=2000 if mode == "client" else None)


@contextlib.asynccontextmanager
async def hub_session(cfg: ZenohSecurityConfig, endpoint: str) -> AsyncIterator[ZenohBus]:
    """The ground loop's side: listens with the users file and the ACL."""
    bus = await ZenohBus.open_async(secured_settings(cfg, MISSION, "ground", listen=(endpoint,)))
    try:
        yield bus
    finally:
        bus.close()


async def receive_until(sub: Subscription, sentinel: bytes) -> list[tuple[str, bytes]]:
    """Everything `sub` delivers up to and including `sentinel` (TimeoutError after TIMEOUT_S)."""
    got: list[tuple[str, bytes]] = []
    while True:
        item = await sub.get(TIMEOUT_S)
        got.append(item)
        if item[1] == sentinel:
            return got


async def test_a_wrong_password_cannot_connect_and_publishes_nothing(users_file: Path) -> None:
    cfg = security(users_file)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    async with hub_session(cfg, endpoint) as hub:
        sub = hub.subscribe(KEYS.everything)
        # A client with a wrong password (or none) is refused at open.
        world = leaf(cfg, endpoint, "world", login(cfg, "world"))
        for user, password in (("world", "not-the-password"), (None, None)):
            with pytest.raises(ConfigError, match="cannot open a client session"):
                ZenohBus.open(as_client(world, user=user, password=password))
        # ... while the right password gets through (the same settings otherwise).
        with ZenohBus.open(as_client(world)) as client:
            assert client.connected_sessions() == 1
        # A peer with a wrong password opens (it keeps retrying) but never gets through.
        bad = await ZenohBus.open_async(
            leaf(cfg, endpoint, "world", login(cfg, "world", "not-the-password"))
        )
        good = await ZenohBus.open_async(leaf(cfg, endpoint, "world", login(cfg, "world")))
        with bad, good:
            assert await good.wait_for_subscribers(KEYS.detections(0), TIMEOUT_S)
            assert not await bad.wait_for_subscribers(KEYS.detections(0), REFUSED_TIMEOUT_S)
            assert bad.connected_sessions() == 0 and good.connected_sessions() == 1
            bad.publish(KEYS.plan, b"forged plan")
            bad.publish(KEYS.detections(0), b"forged detection")
            good.publish(KEYS.detections(0), b"sentinel")
            got = await receive_until(sub, b"sentinel")
    assert got == [(KEYS.detections(0), b"sentinel")]


async def test_an_authenticated_session_puts_only_on_its_roles_keys(users_file: Path) -> None:
    cfg = security(users_file)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    async with hub_session(cfg, endpoint) as hub:
        sub = hub.subscribe(KEYS.everything)
        world = await ZenohBus.open_async(leaf(cfg, endpoint, "world", login(cfg, "world")))
        observer = await ZenohBus.open_async(
            leaf(cfg, endpoint, "observer", login(cfg, "observer"))
        )
        with world, observer:
            assert await world.wait_for_subscribers(KEYS.plan, TIMEOUT_S)
            assert await observer.wait_for_subscribers(KEYS.plan, TIMEOUT_S)
            # The world may not plan, nor speak for the ground loop or the operator; the same
            # session's allowed detection comes after on the same link.
            world.publish(KEYS.plan, b"world plan")
            world.publish(KEYS.track, b"world track")
            world.publish(KEYS.health, b"world health")
            world.publish(KEYS.control, b"world control")
            world.publish(KEYS.detections(1), b"world sentinel")
            got = await receive_until(sub, b"world sentinel")
            assert got == [(KEYS.detections(1), b"world sentinel")]
            # The observer may only read: no plan, no detection.
            observer.publish(KEYS.plan, b"observer plan")
            observer.publish(KEYS.detections(0), b"observer detection")
            observer.publish(KEYS.control, b"observer control")
            world.publish(KEYS.clock, b"sentinel 1")
            got = await receive_until(sub, b"sentinel 1")
            world.publish(KEYS.clock, b"sentinel 2")
            got += await receive_until(sub, b"sentinel 2")
    assert got == [(KEYS.clock, b"sentinel 1"), (KEYS.clock, b"sentinel 2")]


async def test_every_role_publishes_its_keys_and_everyone_reads_them(users_file: Path) -> None:
    cfg = security(users_file)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    async with hub_session(cfg, endpoint) as hub:
        hub_sub = hub.subscribe(KEYS.everything)
        world = await ZenohBus.open_async(leaf(cfg, endpoint, "world", login(cfg, "world")))
        operator = await ZenohBus.open_async(
            leaf(cfg, endpoint, "operator", login(cfg, "operator"))
        )
        # A client observer is forwarded what the world puts through the hub (bus.py, topology).
        observer = await ZenohBus.open_async(
            leaf(cfg, endpoint, "observer", login(cfg, "observer"), mode="client")
        )
        with world, operator, observer:
            world_sub = world.subscribe(KEYS.everything)
            observer_sub = observer.subscribe(KEYS.everything)
            assert await hub.wait_for_subscribers(KEYS.plan, TIMEOUT_S)
            assert await world.wait_for_subscribers(KEYS.clock, TIMEOUT_S)
            assert await operator.wait_for_subscribers(KEYS.control, TIMEOUT_S)
            operator.publish(KEYS.control, b"operator control")
            assert await hub_sub.get(TIMEOUT_S) == (KEYS.control, b"operator control")
            ground_puts = [(KEYS.plan, b"plan"), (KEYS.track, b"track"), (KEYS.health, b"end")]
            world_puts = [
                (KEYS.clock, b"clock"),
                (KEYS.truth, b"truth"),
                (KEYS.detections(2), b"detection"),
                (KEYS.telemetry(2), b"end"),
            ]
            for key, data in ground_puts:
                hub.publish(key, data)
            for key, data in world_puts:
                world.publish(key, data)
            # Each session sees all 7 puts (its own locally), each publisher's in its order.
            for sub in (world_sub, hub_sub, observer_sub):
                got: list[tuple[str, bytes]] = []
                while [g[1] for g in got].count(b"end") < 2:
                    got.append(await sub.get(TIMEOUT_S))
                assert [g for g in got if g in ground_puts] == ground_puts
                assert [g for g in got if g in world_puts] == world_puts


async def test_tls_endpoint_needs_the_local_ca(
    users_file: Path, certs: CertFiles, tmp_path: Path
) -> None:
    cfg = security(users_file, certs)
    port = free_port_block(1, socket.SOCK_STREAM)
    endpoint = f"tls/127.0.0.1:{port}"
    other_ca = generate_certs(tmp_path / "other").ca_file
    async with hub_session(cfg, endpoint) as hub:
        sub = hub.subscribe(KEYS.everything)
        good = leaf(cfg, endpoint, "world", login(cfg, "world"))
        assert good.security is not None and good.security.tls_ca_file == certs.ca_file
        # A client that does not trust the local CA cannot connect: no CA, or another one.
        for ca in (None, other_ca):
            with pytest.raises(ConfigError, match="cannot open a client session"):
                ZenohBus.open(as_client(good, tls_ca_file=ca))
        # Plain tcp to the TLS port does not get through either.
        plain = BusSettings(mode="client", connect=(tcp_loopback(port),), connect_timeout_ms=2000)
        with pytest.raises(ConfigError, match="cannot open a client session"):
            ZenohBus.open(plain)
        async with await ZenohBus.open_async(as_client(good)) as world:
            assert world.connected_sessions() == 1
            world.publish(KEYS.plan, b"forged over TLS")  # the ACL still holds
            world.publish(KEYS.detections(0), b"over TLS")
            got = await receive_until(sub, b"over TLS")
    assert got == [(KEYS.detections(0), b"over TLS")]


def test_a_tls_config_refuses_tcp_endpoints_and_names_the_fix(
    users_file: Path, certs: CertFiles
) -> None:
    cfg = security(users_file, certs)
    with pytest.raises(ConfigError, match=r"with TLS on use tls/127\.0\.0\.1:PORT"):
        secured_settings(cfg, MISSION, "ground", listen=("tcp/127.0.0.1:7447",))


async def test_live_mission_flies_with_auth_acl_and_tls(
    paper: Scenario, users_file: Path, certs: CertFiles, tmp_path: Path
) -> None:
    """`run_embedded` for a few slots with security.zenoh on: the world logs in as `world` over
    TLS, the ground loop's plans reach it and its detections reach the ground loop."""
    slots = 4
    s = paper.with_changes(N=slots, security=SecurityConfig(zenoh=security(users_file, certs)))
    port = free_port_block(1, socket.SOCK_STREAM)
    opts = LiveOptions(
        speed=25.0,
        lockstep=True,
        out_dir=tmp_path / "run",
        zenoh_endpoint=f"tls/127.0.0.1:{port}",
        **sitl_ports(s.M).world_kwargs(),
    )
    result = await asyncio.wait_for(run_embedded(s, opts, asyncio.Event()), timeout=300)
    summary = summarize_live(result)
    assert summary.slots == slots, result.report.last_error
    assert result.fleet_counters["plans applied"] >= slots


def test_local_certificates_name_loopback_and_chain_to_the_local_ca(tmp_path: Path) -> None:
    """gen-certs without any external program: the listener's certificate holds 127.0.0.1 and
    localhost, is signed by the CA, is not itself a CA, and the private keys are owner-only."""
    from cryptography import x509

    files = generate_certs(tmp_path)
    ca = x509.load_pem_x509_certificate(files.ca_file.read_bytes())
    cert = x509.load_pem_x509_certificate(files.cert_file.read_bytes())
    san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert [str(ip) for ip in san.get_values_for_type(x509.IPAddress)] == ["127.0.0.1"]
    assert san.get_values_for_type(x509.DNSName) == ["localhost"]
    assert cert.issuer == ca.subject
    cert.verify_directly_issued_by(ca)
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    assert not cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    for key in (files.ca_key_file, files.key_file):
        assert key.stat().st_mode & 0o777 == 0o600
    with pytest.raises(ConfigError, match="exists"):
        generate_certs(tmp_path)
    before = files.cert_file.read_bytes()
    assert generate_certs(tmp_path, force=True).cert_file.read_bytes() != before
