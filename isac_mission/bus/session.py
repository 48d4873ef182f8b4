"""ZenohBus: a Zenoh session (`isac_mission.bus` is the only package that imports zenoh). A small typed pub/sub adapter.

zenoh-python's API is synchronous and subscriber callbacks run on Zenoh-owned threads. The
callback here only copies the key and the payload bytes and hands them to the asyncio loop with
``loop.call_soon_threadsafe``; everything else happens on the loop. A subscription is an async
iterator of ``(key, payload_bytes)`` and an async context manager that undeclares it on exit.

Every session is configured explicitly (`bus.settings`, `bus.zenoh_config`): mode, multicast
scouting off, explicit loopback listen and connect endpoints unless opted out.

Close every bus (`close()`, or use it as a context manager): a process that exits with a
callback subscriber still declared on an open session hangs at interpreter exit.

Topology note (measured with zenoh 1.10): a peer or router hub forwards between *client* sessions
connected to it, but not between *peer* sessions connected to it (peers are expected to mesh
directly). A peer that connects to the ground loop reaches the ground loop; an observer that must
see another leaf's data either runs in client mode or is the one the leaf connects to.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import socket
from collections.abc import AsyncIterator
from types import TracebackType
from typing import Any, Final

import zenoh

from isac_mission.bus.settings import BusSecurity, BusSettings, endpoint_parts
from isac_mission.bus.zenoh_config import config_entries
from isac_mission.errors import ConfigError, PortInUseError

log = logging.getLogger(__name__)


def make_config(settings: BusSettings) -> zenoh.Config:
    """The zenoh.Config for `settings` (`bus.zenoh_config.config_entries`, in order)."""
    cfg = zenoh.Config()
    for key, value in config_entries(settings).items():
        cfg.insert_json5(key, value)
    return cfg


_STREAM_PROTOCOLS: Final = frozenset({"tcp", "tls", "ws"})
"""Zenoh link protocols over TCP; `udp` and `quic` are over UDP."""
_PROBED_HOSTS: Final = {"127.0.0.1": "127.0.0.1", "localhost": "127.0.0.1"}
"""Hosts whose ports `listen_port_in_use` probes (the network rule: binds on 127.0.0.1 only)."""
_IN_USE_TEXTS: Final = ("Address already in use", "AddrInUse", "os error 98")
"""How Zenoh's open error says a listener's port is taken (for hosts that are not probed)."""


def listen_port_in_use(endpoint: str) -> bool:
    """True when another socket holds the port Zenoh would listen on for `endpoint` (a probe
    bind on 127.0.0.1, TCP with SO_REUSEADDR as Zenoh's listener, or UDP for udp/quic). False
    for port 0 (ephemeral), a free port, or a host other than 127.0.0.1 / localhost (not
    probed)."""
    try:
        p = endpoint_parts(endpoint)
    except ConfigError:
        return False
    if p.host not in _PROBED_HOSTS or p.port == 0:
        return False
    kind = socket.SOCK_STREAM if p.proto in _STREAM_PROTOCOLS else socket.SOCK_DGRAM
    with socket.socket(socket.AF_INET, kind) as probe:
        if kind == socket.SOCK_STREAM:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((_PROBED_HOSTS[p.host], p.port))
        except OSError as err:
            return err.errno == errno.EADDRINUSE
    return False


def port_in_use_error(endpoint: str) -> PortInUseError:
    """The PortInUseError for a listen endpoint whose port is taken (its message names the
    endpoint and the port; the caller adds the option that moves it)."""
    try:
        port = endpoint_parts(endpoint).port
    except ConfigError:
        port = 0
    return PortInUseError(
        f"zenoh: cannot listen on {endpoint}: port {port} is in use by another process",
        port=port,
        endpoint=endpoint,
    )


def check_listen_endpoints(endpoints: tuple[str, ...]) -> None:
    """PortInUseError for the first of `endpoints` whose port another process holds
    (`listen_port_in_use`): a process checks before it starts what depends on its session."""
    for endpoint in endpoints:
        if listen_port_in_use(endpoint):
            raise port_in_use_error(endpoint)


def _busy_listen_endpoint(settings: BusSettings, message: str) -> str | None:
    """The listen endpoint of `settings` whose port is taken, after Zenoh refused to open with
    `message`: a probed endpoint whose port is held, else one that Zenoh's message names as in
    use; None when the failure is something else."""
    for endpoint in settings.listen:
        if listen_port_in_use(endpoint):
            return endpoint
    for endpoint in settings.listen:
        if endpoint in message and any(text in message for text in _IN_USE_TEXTS):
            return endpoint
    return None


def _security_summary(sec: BusSecurity | None) -> str:
    """What a log line may say about `sec`: the user name and which pieces are on, no secret."""
    if sec is None:
        return ""
    parts = [f"user {sec.user}" if sec.user else "", "users file" if sec.users_file else ""]
    parts += ["ACL" if sec.acl else "", "TLS" if sec.tls else ""]
    shown = [p for p in parts if p]
    return f" ({', '.join(shown)})" if shown else ""


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
        # asyncio.timeout, not wait_for: on Python 3.11 wait_for swallows a cancellation that
        # arrives as the sample does (an enclosing timeout then never fires).
        async with asyncio.timeout(timeout_s):
            return await self.__anext__()

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

        Raises PortInUseError (a ConfigError) when a listen endpoint's port is taken by another
        process, ConfigError for invalid settings or when Zenoh refuses to open for another
        reason (client mode with no reachable endpoint, ...).
        """
        s = settings if settings is not None else BusSettings()
        try:
            session = zenoh.open(make_config(s))
        except zenoh.ZError as err:
            busy = _busy_listen_endpoint(s, str(err))
            if busy is not None:
                raise port_in_use_error(busy) from None
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
                async with asyncio.timeout(timeout_s):
                    await matched.wait()
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
