"""ZenohBus: the one module of isac_mission that imports zenoh. A small typed pub/sub adapter.

zenoh-python's API is synchronous and subscriber callbacks run on Zenoh-owned threads. The
callback here only copies the key and the payload bytes and hands them to the asyncio loop with
``loop.call_soon_threadsafe``; everything else happens on the loop. A subscription is an async
iterator of ``(key, payload_bytes)`` and an async context manager that undeclares it on exit.

Network rule: every session is configured explicitly — mode, multicast scouting off (unless
`BusSettings.multicast_scouting` opts in), explicit listen and connect endpoints. The defaults are
loopback only (`tcp/127.0.0.1:7447`, DESIGN.md), and endpoints on other hosts are refused unless
`BusSettings.allow_non_loopback` is set (for a deployment on a container network).

Close every bus (`close()`, or use it as a context manager): a process that exits with a
callback subscriber still declared on an open session hangs at interpreter exit.

Topology note (measured with zenoh 1.10): a peer or router hub forwards between *client* sessions
connected to it, but not between *peer* sessions connected to it (peers are expected to mesh
directly). A peer that connects to the ground loop reaches the ground loop; an observer that must
see another leaf's data either runs in client mode or is the one the leaf connects to.

Security (`BusSecurity`, README "Security"; measured with zenoh 1.10.2): the listening side checks
user/password logins against a dictionary file (`transport/auth/usrpwd`) and applies an access
control list whose subjects are those usernames (`access_control`); ACL by username is enforced by
a peer hub as well as a router, on what enters it from the network (its own session is not
filtered). TLS (`transport/link/tls`) encrypts the link and lets the connecting side check the
listener's certificate against a CA. A peer with a wrong password opens without error and keeps
retrying, with nothing delivered; a client raises.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import re
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Final, Literal

import zenoh

from isac_mission.errors import ConfigError, MessageError

log = logging.getLogger(__name__)

BusMode = Literal["peer", "client", "router"]
DEFAULT_PORT: Final = 7447
DEFAULT_ENDPOINT: Final = f"tcp/127.0.0.1:{DEFAULT_PORT}"
"""Where the ground loop listens and everything else connects (DESIGN.md)."""
LOOPBACK_HOSTS: Final = frozenset({"127.0.0.1", "localhost", "[::1]"})
_ENDPOINT_RE: Final = re.compile(
    r"^(?P<proto>tcp|udp|tls|quic|ws)/(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(?P<port>\d{1,5})"
    r"(?P<rest>[?#].*)?$"
)
_MISSION_RE: Final = re.compile(r"^[A-Za-z0-9_-]+$")


def endpoint_host(endpoint: str) -> str:
    """The host part of a Zenoh endpoint `proto/host:port[?...]`; ConfigError if malformed."""
    m = _ENDPOINT_RE.match(endpoint)
    if m is None or not 0 <= int(m["port"]) <= 65535:
        raise ConfigError(
            f"zenoh endpoint {endpoint!r}: expected proto/host:port, e.g. {DEFAULT_ENDPOINT}"
        )
    return m["host"]


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


def acl_json(acl: BusAcl) -> dict[str, Any]:
    """The `access_control` section for `acl` (zenoh 1.x schema): default deny."""
    rules: list[dict[str, Any]] = [
        {
            "id": "subscribe",
            "messages": ["declare_subscriber"],
            "flows": ["ingress", "egress"],
            "permission": "allow",
            "key_exprs": [acl.subscribe],
        },
        {
            "id": "receive",
            "messages": ["put"],
            "flows": ["egress"],
            "permission": "allow",
            "key_exprs": [acl.subscribe],
        },
    ]
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    every = [f"role-{r.name}" for r in acl.roles]
    for r in acl.roles:
        subjects.append({"id": f"role-{r.name}", "usernames": list(r.users)})
        if r.publishes:
            rules.append(
                {
                    "id": f"publish-{r.name}",
                    "messages": ["put"],
                    "flows": ["ingress"],
                    "permission": "allow",
                    "key_exprs": list(r.publishes),
                }
            )
            policies.append(
                {
                    "id": f"publish-{r.name}",
                    "rules": [f"publish-{r.name}"],
                    "subjects": [f"role-{r.name}"],
                }
            )
    policies.append({"id": "everyone", "rules": ["subscribe", "receive"], "subjects": every})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


@dataclass(frozen=True)
class BusSettings:
    """How a process joins the Zenoh network.

    mode: "peer" (default; open() returns even if the connect endpoint is not up yet and keeps
    retrying), "client" (open() fails at once without a reachable router/peer; bounded by
    connect_timeout_ms) or "router". listen / connect: endpoints like `tcp/127.0.0.1:7447`.
    The default joins the ground loop at DEFAULT_ENDPOINT; `BusSettings.hub()` is the ground
    loop's side. multicast_scouting stays off unless explicitly enabled. Non-loopback endpoints
    raise ConfigError unless allow_non_loopback is set.
    """

    mode: BusMode = "peer"
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = (DEFAULT_ENDPOINT,)
    multicast_scouting: bool = False
    allow_non_loopback: bool = False
    connect_timeout_ms: int | None = None
    security: BusSecurity | None = None

    def __post_init__(self) -> None:
        if self.mode not in ("peer", "client", "router"):
            raise ConfigError(f"zenoh mode: expected peer, client or router, got {self.mode!r}")
        if isinstance(self.listen, str) or isinstance(self.connect, str):
            raise ConfigError("zenoh listen/connect: expected a sequence of endpoints, got a str")
        object.__setattr__(self, "listen", tuple(self.listen))
        object.__setattr__(self, "connect", tuple(self.connect))
        for ep in (*self.listen, *self.connect):
            host = endpoint_host(ep)
            if host not in LOOPBACK_HOSTS and not self.allow_non_loopback:
                raise ConfigError(
                    f"zenoh endpoint {ep!r}: host {host} is not loopback "
                    "(set allow_non_loopback to use other interfaces)"
                )
        if self.connect_timeout_ms is not None and self.connect_timeout_ms <= 0:
            raise ConfigError(
                f"zenoh connect_timeout_ms: must be > 0, got {self.connect_timeout_ms}"
            )
        if self.security is not None:
            self.security.check(self.listen, self.connect)
        elif any(ep.startswith("tls/") for ep in (*self.listen, *self.connect)):
            raise ConfigError("zenoh tls/ endpoints need security settings (certificates)")

    @classmethod
    def hub(cls, endpoint: str = DEFAULT_ENDPOINT, mode: BusMode = "peer") -> BusSettings:
        """The side that listens (the ground loop, or a test observer): listen, connect nowhere."""
        return cls(mode=mode, listen=(endpoint,), connect=())


def make_config(settings: BusSettings) -> zenoh.Config:
    """The zenoh.Config for `settings`, every network-relevant key set explicitly."""
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(settings.mode))
    cfg.insert_json5("scouting/multicast/enabled", json.dumps(settings.multicast_scouting))
    cfg.insert_json5("listen/endpoints", json.dumps(list(settings.listen)))
    cfg.insert_json5("connect/endpoints", json.dumps(list(settings.connect)))
    if settings.connect_timeout_ms is not None:
        cfg.insert_json5("connect/timeout_ms", json.dumps(settings.connect_timeout_ms))
    if settings.security is not None:
        _insert_security(cfg, settings.security)
    return cfg


def _insert_security(cfg: zenoh.Config, sec: BusSecurity) -> None:
    """Login, users dictionary, ACL and TLS keys of `sec` (only those that are set)."""
    entries: dict[str, Any] = {
        "transport/auth/usrpwd/user": sec.user,
        "transport/auth/usrpwd/password": sec.password,
        "transport/auth/usrpwd/dictionary_file": sec.users_file,
        "transport/link/tls/root_ca_certificate": sec.tls_ca_file,
        "transport/link/tls/listen_certificate": sec.tls_cert_file,
        "transport/link/tls/listen_private_key": sec.tls_key_file,
    }
    for key, value in entries.items():
        if value is not None:
            cfg.insert_json5(key, json.dumps(str(value)))
    if sec.tls:
        # The listener's certificate names 127.0.0.1 and localhost: check the name too.
        cfg.insert_json5("transport/link/tls/verify_name_on_connect", "true")
    if sec.acl is not None:
        cfg.insert_json5("access_control", json.dumps(acl_json(sec.acl)))


@dataclass(frozen=True)
class Keys:
    """Key expressions of one mission: `isac/<mission>/...` (DESIGN.md, "Zenoh")."""

    mission: str

    def __post_init__(self) -> None:
        if not _MISSION_RE.match(self.mission):
            raise ConfigError(f"mission id {self.mission!r}: use letters, digits, '_' or '-'")

    @property
    def prefix(self) -> str:
        """`isac/<mission>`."""
        return f"isac/{self.mission}"

    @property
    def everything(self) -> str:
        """`isac/<mission>/**`: every key of the mission."""
        return f"{self.prefix}/**"

    def detections(self, m: int) -> str:
        """`isac/<mission>/detections/<m>` (m: 0-based UAV index)."""
        return f"{self.prefix}/detections/{_index(m)}"

    @property
    def detections_all(self) -> str:
        """`isac/<mission>/detections/*`."""
        return f"{self.prefix}/detections/*"

    def telemetry(self, m: int) -> str:
        """`isac/<mission>/telemetry/<m>`."""
        return f"{self.prefix}/telemetry/{_index(m)}"

    @property
    def telemetry_all(self) -> str:
        """`isac/<mission>/telemetry/*`."""
        return f"{self.prefix}/telemetry/*"

    @property
    def plan(self) -> str:
        """`isac/<mission>/plan`."""
        return f"{self.prefix}/plan"

    @property
    def track(self) -> str:
        """`isac/<mission>/track`."""
        return f"{self.prefix}/track"

    @property
    def clock(self) -> str:
        """`isac/<mission>/clock`."""
        return f"{self.prefix}/clock"

    @property
    def truth(self) -> str:
        """`isac/<mission>/truth`."""
        return f"{self.prefix}/truth"

    @property
    def health(self) -> str:
        """`isac/<mission>/health`."""
        return f"{self.prefix}/health"

    @property
    def control(self) -> str:
        """`isac/<mission>/control`: an operator's commands to the ground loop."""
        return f"{self.prefix}/control"


def _security_summary(sec: BusSecurity | None) -> str:
    """What a log line may say about `sec`: the user name and which pieces are on, no secret."""
    if sec is None:
        return ""
    parts = [f"user {sec.user}" if sec.user else "", "users file" if sec.users_file else ""]
    parts += ["ACL" if sec.acl else "", "TLS" if sec.tls else ""]
    shown = [p for p in parts if p]
    return f" ({', '.join(shown)})" if shown else ""


def _index(m: int) -> int:
    if isinstance(m, bool) or not isinstance(m, int) or m < 0:
        raise ValueError(f"UAV index must be an int >= 0, got {m!r}")
    return m


def uav_index(key: str) -> int:
    """The 0-based UAV index at the end of `.../detections/<m>` or `.../telemetry/<m>`."""
    last = key.rsplit("/", 1)[-1]
    if not last.isdigit():
        raise MessageError(f"key {key!r}: does not end in a UAV index")
    return int(last)


_CLOSED: Final = object()


class Subscription:
    """Samples of one key expression, delivered on the asyncio loop as (key, payload bytes).

    Declared when created (by `ZenohBus.subscribe`, which must run on the loop); iterate with
    ``async for``; ``async with`` or `close()` undeclares. When the queue (maxsize samples) is
    full the oldest sample is dropped and counted in `dropped`. Iteration ends after `close()`.
    """

    def __init__(self, session: zenoh.Session, key_expr: str, maxsize: int) -> None:
        self.key_expr = key_expr
        self.dropped = 0
        self.received = 0
        self._loop = asyncio.get_running_loop()
        self._queue: asyncio.Queue[Any] = asyncio.Queue(maxsize=maxsize)
        self._closed = False
        self._sub = session.declare_subscriber(key_expr, self._on_sample)

    # Runs on a Zenoh thread: copy out and hand over, nothing else.
    def _on_sample(self, sample: zenoh.Sample) -> None:
        item = (str(sample.key_expr), sample.payload.to_bytes())
        # RuntimeError: the loop is closed, the process is shutting down.
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._deliver, item)

    def _deliver(self, item: Any) -> None:
        if self._closed and item is not _CLOSED:
            return
        if self._queue.full():
            self._queue.get_nowait()
            self.dropped += 1
        self._queue.put_nowait(item)

    @property
    def closed(self) -> bool:
        """True after close()."""
        return self._closed

    def close(self) -> None:
        """Undeclare the subscriber and end the iteration (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._sub.undeclare()  # type: ignore[no-untyped-call]
        except Exception as err:  # session already closed: undeclare is moot
            log.debug("undeclare %s: %s", self.key_expr, err)
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._loop:
            self._deliver(_CLOSED)
        else:
            with contextlib.suppress(RuntimeError):
                self._loop.call_soon_threadsafe(self._deliver, _CLOSED)

    def __aiter__(self) -> Subscription:
        return self

    async def __anext__(self) -> tuple[str, bytes]:
        if self._closed and self._queue.empty():
            raise StopAsyncIteration
        item = await self._queue.get()
        if item is _CLOSED:
            self._queue.put_nowait(_CLOSED)  # keep later __anext__ calls ending too
            raise StopAsyncIteration
        self.received += 1
        key, data = item
        return str(key), bytes(data)

    async def get(self, timeout_s: float) -> tuple[str, bytes]:
        """The next sample, or TimeoutError after timeout_s (wall seconds)."""
        return await asyncio.wait_for(self.__anext__(), timeout_s)

    async def __aenter__(self) -> Subscription:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class ZenohBus:
    """One Zenoh session with typed publish/subscribe. Create with `ZenohBus.open(settings)`."""

    def __init__(self, session: zenoh.Session, settings: BusSettings) -> None:
        self._session = session
        self.settings = settings
        self._subs: list[Subscription] = []
        self._closed = False
        self.published = 0

    @classmethod
    def open(cls, settings: BusSettings | None = None) -> ZenohBus:
        """Open a session (blocking: about 0.5 s when a connect endpoint is up).

        Raises ConfigError for invalid settings or when Zenoh refuses to open (client mode with
        no reachable endpoint, a listen port in use, ...).
        """
        s = settings if settings is not None else BusSettings()
        try:
            session = zenoh.open(make_config(s))
        except zenoh.ZError as err:
            raise ConfigError(
                f"zenoh: cannot open a {s.mode} session "
                f"(listen {list(s.listen)}, connect {list(s.connect)}): {err}"
            ) from None
        log.info(
            "zenoh %s session open: listen %s, connect %s%s",
            s.mode,
            s.listen,
            s.connect,
            _security_summary(s.security),
        )
        return cls(session, s)

    @classmethod
    async def open_async(cls, settings: BusSettings | None = None) -> ZenohBus:
        """`open` in a worker thread, so the event loop keeps running meanwhile."""
        return await asyncio.to_thread(cls.open, settings)

    @property
    def closed(self) -> bool:
        """True after close()."""
        return self._closed

    def connected_sessions(self) -> int:
        """How many peers and routers this session has a transport with now (0: not connected:
        nothing up at the endpoint yet, or the login or certificate was refused)."""
        info = self._session.info
        return len(list(info.peers_zid())) + len(list(info.routers_zid()))

    def publish(self, key: str, payload: bytes) -> None:
        """Put payload bytes on `key` (non-blocking in practice; lost if nobody is connected)."""
        if self._closed:
            raise RuntimeError("publish on a closed ZenohBus")
        self._session.put(key, payload)
        self.published += 1

    def subscribe(self, key_expr: str, *, maxsize: int = 1024) -> Subscription:
        """Declare a subscriber now (call on the event loop); see `Subscription`."""
        if self._closed:
            raise RuntimeError("subscribe on a closed ZenohBus")
        sub = Subscription(self._session, key_expr, maxsize)
        self._subs = [s for s in self._subs if not s.closed]
        self._subs.append(sub)
        return sub

    async def messages(
        self, key_expr: str, *, maxsize: int = 1024
    ) -> AsyncIterator[tuple[str, bytes]]:
        """Async generator over (key, payload); undeclares the subscriber in `finally`.

        The subscriber is declared at the first iteration: use `subscribe` when samples sent
        before that must not be missed.
        """
        sub = self.subscribe(key_expr, maxsize=maxsize)
        try:
            async for item in sub:
                yield item
        finally:
            sub.close()

    async def wait_for_subscribers(self, key: str, timeout_s: float) -> bool:
        """Wait (wall seconds) until some subscriber on the network matches `key`; True if so."""
        loop = asyncio.get_running_loop()
        matched = asyncio.Event()

        def on_status(status: Any) -> None:  # Zenoh thread
            if bool(getattr(status, "matching", False)):
                with contextlib.suppress(RuntimeError):
                    loop.call_soon_threadsafe(matched.set)

        pub = self._session.declare_publisher(key)
        listener = pub.declare_matching_listener(on_status)
        try:
            if bool(getattr(pub.matching_status, "matching", pub.matching_status)):
                return True
            try:
                await asyncio.wait_for(matched.wait(), timeout_s)
            except TimeoutError:
                return False
            return True
        finally:
            listener.undeclare()  # type: ignore[no-untyped-call]
            pub.undeclare()  # type: ignore[no-untyped-call]

    def close(self) -> None:
        """Undeclare every subscription and close the session (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for sub in self._subs:
            sub.close()
        self._subs.clear()
        try:
            self._session.close()  # type: ignore[no-untyped-call]
        except Exception as err:
            log.warning("zenoh session close: %s", err)
        log.info("zenoh session closed")

    def __enter__(self) -> ZenohBus:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    async def __aenter__(self) -> ZenohBus:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
