"""The console's work on its own event loop: watch the mission's bus keys with its own Zenoh
session, fold them into a `MissionView`, push updates to the pages' feeds, and send the
operator's fleet commands on `control`.

Security (docs/deployment.md, "Security"): with `security.zenoh` off, any page on the console's
address may command. With it on, the console watches as the `observer` role (its password from the users
file the ground side holds) and a page commands only after it has logged in with the `operator`
role's password: the console opens an operator session with it, so the Zenoh listener itself
checks the password; a page without it is read-only.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import secrets
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Final

from isac_mission.bus import BusSettings, ZenohBus
from isac_mission.bus.security import secured_settings
from isac_mission.config import ZenohSecurityConfig
from isac_mission.console.feed import Hub
from isac_mission.console.requests import ControlRequest, RequestError, control_payload
from isac_mission.console.state import MissionView
from isac_mission.errors import ConfigError
from isac_mission.wire.keys import Keys

log = logging.getLogger(__name__)

RETRY_S: Final = 0.5
"""Wait between attempts to reach the ground loop's Zenoh endpoint."""
STATS_PERIOD_S: Final = 1.0


@dataclass
class BusAccess:
    """How the console joins the bus: the mission, the ground loop's endpoint, the scenario's
    Zenoh security (off: no logins) and the environment to read logins from (tests)."""

    mission_id: str
    endpoint: str
    security: ZenohSecurityConfig = field(default_factory=ZenohSecurityConfig)

    @property
    def secured(self) -> bool:
        return self.security.enabled

    def observer_settings(self) -> BusSettings:
        """A client session that reads every key (role `observer` when security is on)."""
        if not self.secured:
            return BusSettings(mode="client", connect=(self.endpoint,), connect_timeout_ms=2000)
        return secured_settings(
            self.security,
            self.mission_id,
            "observer",
            mode="client",
            connect=(self.endpoint,),
            login_from_users_file=True,
        )

    def operator_settings(self, password: str) -> BusSettings:
        """A client session logged in as the `operator` role's first user with `password`."""
        cfg = self.security
        user = cfg.roles["operator"].users[0] if "operator" in cfg.roles else "operator"
        env = {cfg.user_env: user, cfg.password_env: password}
        return secured_settings(
            cfg, self.mission_id, "operator", mode="client", connect=(self.endpoint,), env=env
        )


class ConsoleService:
    """The live console's state and bus work (runs on the console thread's event loop)."""

    def __init__(self, view: MissionView, access: BusAccess | None) -> None:
        self.view = view
        self.access = access
        self.hub = Hub()
        self.keys = Keys(access.mission_id) if access is not None else None
        self.bus: ZenohBus | None = None
        self.operator_bus: ZenohBus | None = None
        self.tokens: set[str] = set()
        self.sent: dict[str, dict[str, Any]] = {}
        self.status = "starting" if access is not None else "replay"
        self._stop = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []

    @property
    def secured(self) -> bool:
        return self.access is not None and self.access.secured

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Start watching the bus (call on the console's loop)."""
        if self.access is not None:
            self._tasks.append(asyncio.create_task(self._watch(), name="console-bus"))
            self._tasks.append(asyncio.create_task(self._stats(), name="console-stats"))

    async def stop(self) -> None:
        self._stop.set()
        for task in self._tasks:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        for bus in (self.bus, self.operator_bus):
            if bus is not None:
                bus.close()
        self.bus = self.operator_bus = None

    async def _open(self, settings: Callable[[], BusSettings]) -> ZenohBus | None:
        """Open a session, retrying while the ground loop is not up yet (None once stopped)."""
        warned = False
        while not self._stop.is_set():
            try:
                return await ZenohBus.open_async(settings())
            except ConfigError as err:
                if not warned:
                    log.info("console: waiting for the ground loop's bus: %s", err)
                    warned = True
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(RETRY_S):
                    await self._stop.wait()
        return None

    async def _watch(self) -> None:
        assert self.access is not None and self.keys is not None
        try:
            bus = await self._open(self.access.observer_settings)
        except Exception as err:  # a login the console cannot make: say so, keep serving
            self.status = f"no bus: {err}"
            log.error("console: %s", self.status)
            return
        if bus is None:
            return
        self.bus = bus
        self.status = "watching"
        self.hub.broadcast("console", self.console_state())
        async with bus.subscribe(self.keys.everything, maxsize=4096) as sub:
            async for key, payload in sub:
                try:
                    updates = self.view.ingest(key, payload)
                except Exception:  # a bug here must not end the console
                    log.exception("console: cannot show a message on %s", key)
                    continue
                for topic, data in updates:
                    self.hub.broadcast(topic, data)

    async def _stats(self) -> None:
        while not self._stop.is_set():
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(STATS_PERIOD_S):
                    await self._stop.wait()
            self.hub.broadcast("console", self.console_state())

    def console_state(self) -> dict[str, Any]:
        """The console's own status for the page: bus status, pages, message stats."""
        return {
            "status": self.status,
            "pages": len(self.hub.feeds),
            "secured": self.secured,
            **self.view.stats(),
        }

    # ------------------------------------------------------------------ operator

    def may_command(self, token: str | None) -> bool:
        """Security off: every page; on: a page holding a token from `login`."""
        return not self.secured or (token is not None and token in self.tokens)

    async def login(self, password: str) -> str:
        """Check the operator password by opening an operator session with it; a page token.
        RequestError 403 when the Zenoh listener refuses it, 409 without security."""
        if self.access is None:
            raise RequestError(409, "password: a replay has no bus to command")
        if not self.secured:
            raise RequestError(409, "password: security is off, every page may command")
        try:
            bus = await ZenohBus.open_async(self.access.operator_settings(password))
        except ConfigError as err:
            log.warning("console: operator login refused (%s)", str(err)[:200])
            raise RequestError(403, "password: refused by the bus (not the operator's)") from None
        old, self.operator_bus = self.operator_bus, bus
        if old is not None:
            old.close()
        token = secrets.token_urlsafe(24)
        self.tokens = {token}
        return token

    def send_control(self, req: ControlRequest, token: str | None) -> dict[str, Any]:
        """Publish `req` on `control`; the request id and what was sent. RequestError 403 for a
        read-only page, 503 before the bus is up, 422 when the bus model refuses it."""
        if self.access is None or self.keys is None:
            raise RequestError(409, "command: a replay has no bus to command")
        if not self.may_command(token):
            raise RequestError(
                403, "token: this page is read-only; log in with the operator password first"
            )
        bus = self.operator_bus if self.secured else self.bus
        if bus is None:
            raise RequestError(503, "bus: not connected to the mission yet")
        clock = self.view.latest.get("clock", {})
        slot = int(clock.get("slot", -1))
        t_s = float(clock.get("t", 0.0))
        rid, payload = control_payload(req, slot=slot, t_s=t_s, n_uavs=self.view.n_uavs)
        bus.publish(self.keys.control, payload)
        entry = {
            "id": rid,
            "request": req.model_dump(exclude_none=True),
            "sent_wall_s": time.time(),
        }
        self.sent[rid] = entry
        while len(self.sent) > 100:
            self.sent.pop(next(iter(self.sent)))
        return entry
