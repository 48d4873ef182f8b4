"""How a process joins the Zenoh network: `BusSettings` (pydantic, frozen) and its security.

Network rule: every session is configured explicitly — mode, multicast scouting off (unless
`BusSettings.multicast_scouting` opts in), explicit listen and connect endpoints. The defaults are
loopback only (`tcp/127.0.0.1:7447`, docs/bus.md), and endpoints on other hosts are refused unless
`BusSettings.allow_non_loopback` is set (for a deployment on a container network). Every problem
is a `ConfigError` naming the setting at fault.

Security (`BusSecurity`, docs/deployment.md, "Security"; measured with zenoh 1.10.2): the
listening side checks user/password logins against a dictionary file (`transport/auth/usrpwd`) and applies an access
control list whose subjects are those usernames (`access_control`); ACL by username is enforced by
a peer hub as well as a router, on what enters it from the network (its own session is not
filtered). TLS (`transport/link/tls`) encrypts the link and lets the connecting side check the
listener's certificate against a CA. A peer with a wrong password opens without error and keeps
retrying, with nothing delivered; a client raises.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, Literal

from pydantic import BaseModel, ConfigDict, InstanceOf, ValidationError, model_validator

from isac_mission.errors import ConfigError

BusMode = Literal["peer", "client", "router"]
DEFAULT_PORT: Final = 7447
DEFAULT_ENDPOINT: Final = f"tcp/127.0.0.1:{DEFAULT_PORT}"
"""Where the ground loop listens and everything else connects (docs/bus.md)."""
LOOPBACK_HOSTS: Final = frozenset({"127.0.0.1", "localhost", "[::1]"})
_ENDPOINT_RE: Final = re.compile(
    r"^(?P<proto>tcp|udp|tls|quic|ws)/(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(?P<port>\d{1,5})"
    r"(?P<rest>[?#].*)?$"
)


def endpoint_host(endpoint: str) -> str:
    """The host part of a Zenoh endpoint `proto/host:port[?...]`; ConfigError if malformed."""
    m = _ENDPOINT_RE.match(endpoint)
    if m is None or not 0 <= int(m["port"]) <= 65535:
        raise ConfigError(
            f"zenoh endpoint {endpoint!r}: expected proto/host:port, e.g. {DEFAULT_ENDPOINT}"
        )
    return m["host"]


@dataclass(frozen=True)
class EndpointParts:
    """A Zenoh endpoint `proto/host:port[?...]` taken apart: rest is what follows the port
    (`?...` options, or "")."""

    proto: str
    host: str
    port: int
    rest: str = ""


def endpoint_parts(endpoint: str) -> EndpointParts:
    """`endpoint` taken apart; ConfigError if malformed (as `endpoint_host`)."""
    endpoint_host(endpoint)
    m = _ENDPOINT_RE.match(endpoint)
    assert m is not None  # endpoint_host checked it
    return EndpointParts(m["proto"], m["host"], int(m["port"]), m["rest"] or "")


def endpoint_port(endpoint: str) -> int:
    """The port of a Zenoh endpoint `proto/host:port[?...]`; ConfigError if malformed."""
    return endpoint_parts(endpoint).port


def endpoint_with_port(endpoint: str, port: int) -> str:
    """`endpoint` with its port replaced by `port` (protocol, host and options kept);
    ConfigError if the endpoint is malformed or the port outside 0-65535."""
    p = endpoint_parts(endpoint)
    out = f"{p.proto}/{p.host}:{int(port)}{p.rest}"
    endpoint_host(out)
    return out


def tcp_loopback(port: int) -> str:
    """`tcp/127.0.0.1:<port>`."""
    return f"tcp/127.0.0.1:{int(port)}"


@dataclass(frozen=True)
class BusRole:
    """One ACL role: the usernames that hold it and the keys (or key expressions) they may put."""

    name: str
    users: tuple[str, ...]
    publishes: tuple[str, ...]


@dataclass(frozen=True)
class BusAcl:
    """Access control of the listening side: default deny; every role may subscribe to and
    receive `subscribe` (e.g. `isac/<mission>/**`); a role may put only on its own keys."""

    subscribe: str
    roles: tuple[BusRole, ...]


@dataclass(frozen=True)
class BusSecurity:
    """Authentication, access control and TLS of one session (all optional, all files).

    user / password: this session's login when it connects (the password is never shown in
    repr or logs). users_file: the zenoh dictionary (`user:password` lines) that the listening
    side checks logins against. acl: the listening side's access control. tls: endpoints are
    `tls/...`; tls_ca_file: the CA a connecting side trusts (None: the system's public roots);
    tls_cert_file / tls_key_file: the listening side's certificate and key.
    """

    user: str | None = None
    password: str | None = field(default=None, repr=False)
    users_file: Path | None = None
    acl: BusAcl | None = None
    tls_ca_file: Path | None = None
    tls_cert_file: Path | None = None
    tls_key_file: Path | None = None
    tls: bool = False

    def check(self, listen: tuple[str, ...], connect: tuple[str, ...]) -> None:
        """ConfigError if the pieces do not fit the endpoints (names the missing piece)."""
        if (self.user is None) != (self.password is None):
            raise ConfigError("zenoh security: a login needs both a user and a password")
        if (self.tls_cert_file is None) != (self.tls_key_file is None):
            raise ConfigError("zenoh security: TLS needs both a certificate and its private key")
        for ep in (*listen, *connect):
            if ep.startswith("tls/") != self.tls:
                want = "tls/" if self.tls else "tcp/"
                raise ConfigError(
                    f"zenoh endpoint {ep!r}: with TLS {'on' if self.tls else 'off'} use {want}"
                    f"127.0.0.1:PORT endpoints"
                )
        if listen and self.tls and self.tls_cert_file is None:
            raise ConfigError("zenoh security: a TLS listener needs a certificate and key")
        if self.acl is not None and self.users_file is None:
            raise ConfigError("zenoh security: access control by username needs a users file")


_MODES: Final = ("peer", "client", "router")


class BusSettings(BaseModel):
    """How a process joins the Zenoh network.

    mode: "peer" (default; open() returns even if the connect endpoint is not up yet and keeps
    retrying), "client" (open() fails at once without a reachable router/peer; bounded by
    connect_timeout_ms) or "router". listen / connect: endpoints like `tcp/127.0.0.1:7447`
    (any sequence; stored as tuples). The default joins the ground loop at DEFAULT_ENDPOINT;
    `BusSettings.hub()` is the ground loop's side. multicast_scouting stays off unless
    explicitly enabled. Non-loopback endpoints raise ConfigError unless allow_non_loopback is
    set. Every invalid setting raises ConfigError (never pydantic's ValidationError).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)

    mode: BusMode = "peer"
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = (DEFAULT_ENDPOINT,)
    multicast_scouting: bool = False
    allow_non_loopback: bool = False
    connect_timeout_ms: int | None = None
    security: InstanceOf[BusSecurity] | None = None

    def __init__(self, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as err:
            first = err.errors(include_url=False)[0]
            where = ".".join(str(p) for p in first["loc"])
            raise ConfigError(
                f"zenoh {where}: {first['msg']} (got {first.get('input')!r})"
            ) from None

    @model_validator(mode="before")
    @classmethod
    def _words(cls, data: Any) -> Any:
        """The checks whose texts name the setting in the project's words, and sequences of
        endpoints as tuples."""
        if not isinstance(data, dict):
            return data
        mode = data.get("mode", "peer")
        if mode not in _MODES:
            raise ConfigError(f"zenoh mode: expected peer, client or router, got {mode!r}")
        out = dict(data)
        for name in ("listen", "connect"):
            value = out.get(name)
            if isinstance(value, str):
                raise ConfigError(
                    "zenoh listen/connect: expected a sequence of endpoints, got a str"
                )
            if value is not None and not isinstance(value, tuple):
                out[name] = tuple(value)
        timeout = out.get("connect_timeout_ms")
        if isinstance(timeout, int) and not isinstance(timeout, bool) and timeout <= 0:
            raise ConfigError(f"zenoh connect_timeout_ms: must be > 0, got {timeout}")
        return out

    @model_validator(mode="after")
    def _network_rule(self) -> BusSettings:
        for ep in (*self.listen, *self.connect):
            host = endpoint_host(ep)
            if host not in LOOPBACK_HOSTS and not self.allow_non_loopback:
                raise ConfigError(
                    f"zenoh endpoint {ep!r}: host {host} is not loopback "
                    "(set allow_non_loopback to use other interfaces)"
                )
        if self.security is not None:
            self.security.check(self.listen, self.connect)
        elif any(ep.startswith("tls/") for ep in (*self.listen, *self.connect)):
            raise ConfigError("zenoh tls/ endpoints need security settings (certificates)")
        return self

    def with_changes(self, **changes: Any) -> BusSettings:
        """A copy with some settings replaced, validated again (ConfigError if invalid)."""
        current = {name: getattr(self, name) for name in type(self).model_fields}
        return type(self)(**{**current, **changes})

    @classmethod
    def hub(cls, endpoint: str = DEFAULT_ENDPOINT, mode: BusMode = "peer") -> BusSettings:
        """The side that listens (the ground loop, or a test observer): listen, connect nowhere."""
        return cls(mode=mode, listen=(endpoint,), connect=())
