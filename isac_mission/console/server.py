"""The console's server: uvicorn on its own thread and event loop, beside the mission.

`ConsoleServer.start()` binds the listening socket in the caller's thread, so a busy port is
reported at once (`ConsolePortBusyError`, naming the port and the flag) and the caller goes on
without a console; then the thread runs uvicorn and the `ConsoleService` on one asyncio loop
that never touches the mission's own loop or the planner's thread. `stop()` ends both.
Loopback only unless the caller allows another address (`parse_address`).
"""

from __future__ import annotations

import asyncio
import errno
import ipaddress
import logging
import socket
import threading
import time
from dataclasses import dataclass
from typing import Any, Final

import uvicorn

from isac_mission.console.app import build_app
from isac_mission.console.service import ConsoleService
from isac_mission.errors import ConfigError

log = logging.getLogger(__name__)

DEFAULT_ADDRESS: Final = "127.0.0.1:8080"
FLAG: Final = "--console HOST:PORT"


class ConsolePortBusyError(ConfigError):
    """The console's port is taken (the mission can still run without the console)."""


@dataclass(frozen=True)
class ConsoleAddress:
    """Where the console listens: host (an IP address) and TCP port."""

    host: str
    port: int

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"


def parse_address(text: str, *, allow_non_loopback: bool = False) -> ConsoleAddress:
    """`HOST:PORT` (IPv4, `[IPv6]`, or `localhost`); ConfigError naming the flag. A host that
    is not loopback is refused unless `allow_non_loopback`."""
    host, sep, port_text = text.rpartition(":")
    if not sep or not host or not port_text.isdecimal():
        raise ConfigError(f"--console: expected HOST:PORT such as {DEFAULT_ADDRESS}, got {text!r}")
    port = int(port_text)
    if not 0 <= port <= 65535:
        raise ConfigError(f"--console: port {port} is outside 0 to 65535")
    host = host.strip("[]")
    if host == "localhost":
        host = "127.0.0.1"
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        raise ConfigError(f"--console: {host!r} is not an IP address (or localhost)") from None
    if not ip.is_loopback and not allow_non_loopback:
        raise ConfigError(
            f"--console: {host} is not a loopback address; pass --console-public to serve "
            "the console (and its operator controls) beyond this host"
        )
    return ConsoleAddress(str(ip), port)


def bind(address: ConsoleAddress) -> socket.socket:
    """A listening TCP socket on `address`; ConsolePortBusyError when the port is taken."""
    family = socket.AF_INET6 if ":" in address.host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((address.host, address.port))
        sock.listen(128)
    except OSError as err:
        sock.close()
        if err.errno in (errno.EADDRINUSE, errno.EACCES):
            raise ConsolePortBusyError(
                f"console: port {address.port} on {address.host} is in use ({err.strerror}); "
                f"choose another with {FLAG}, or --no-console"
            ) from None
        raise ConfigError(f"console: cannot listen on {address.url}: {err.strerror}") from None
    sock.setblocking(False)
    return sock


class ConsoleServer:
    """uvicorn + the console service on a daemon thread (start, then stop)."""

    def __init__(
        self,
        service: ConsoleService,
        address: ConsoleAddress,
        replay: dict[str, Any] | None = None,
    ) -> None:
        self.service = service
        self.address = address
        self.replay = replay
        self._sock: socket.socket | None = None
        self._server: uvicorn.Server | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._started = threading.Event()
        self.error: BaseException | None = None
        self.cpu_s = 0.0
        """CPU time (s) the console's thread used (uvicorn, the pages, the view), once stopped."""

    @property
    def url(self) -> str:
        """The page's address (the bound port when 0 was asked for)."""
        if self._sock is not None:
            port = self._sock.getsockname()[1]
            return ConsoleAddress(self.address.host, int(port)).url
        return self.address.url

    def start(self, timeout_s: float = 30.0) -> str:
        """Bind (ConsolePortBusyError at once if taken), start the thread; the page's URL."""
        self._sock = bind(self.address)
        config = uvicorn.Config(
            build_app(self.service, self.replay),
            log_level="warning",
            access_log=False,
            lifespan="off",
            ws="websockets-sansio",
            ws_max_size=64 * 1024,
            timeout_graceful_shutdown=2,
        )
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._run, name="console", daemon=True)
        self._thread.start()
        if not self._started.wait(timeout_s):
            raise ConfigError("console: the server did not start")
        if self.error is not None:
            raise ConfigError(f"console: {self.error}")
        return self.url

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as err:  # reported to start() or logged
            self.error = err
            log.exception("console stopped")
        finally:
            self._started.set()

    async def _main(self) -> None:
        assert self._server is not None and self._sock is not None
        self._loop = asyncio.get_running_loop()
        cpu0 = time.thread_time()
        self.service.start()
        self._started.set()
        try:
            await self._server.serve(sockets=[self._sock])
        finally:
            await self.service.stop()
            self.cpu_s = time.thread_time() - cpu0

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop serving and close the console's bus sessions (idempotent)."""
        if self._server is not None:
            self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                log.warning("console: the server thread did not stop within %.0f s", timeout_s)
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> ConsoleServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
