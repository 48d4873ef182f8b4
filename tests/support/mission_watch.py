"""A Zenoh observer of a live mission for the operator tests: clock, plans, telemetry, health and
control replies as they arrive, with waits on conditions (wall-clock bounded).

`MissionWatch(bus, keys)` subscribes to `isac/<mission>/**` on an observer session and keeps
everything decoded; `until(pred, timeout_s, what)` waits for a condition checked on every
message; `request(...)` publishes a `control` request and waits for its reply.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from isac_mission.bus import BusSettings, ZenohBus
from isac_mission.errors import MessageError
from isac_mission.wire import (
    ControlMsg,
    ControlReplyMsg,
    HealthMsg,
    Keys,
    PlanMsg,
    TelemetryMsg,
    decode_any,
    encode,
)


async def open_client(endpoint: str, timeout_s: float) -> ZenohBus:
    """A client session to the ground loop's `endpoint`, once it listens (client mode, so that
    the hub forwards the world's clock to it: docs/bus.md, "Sessions")."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return await ZenohBus.open_async(BusSettings(mode="client", connect=(endpoint,)))
        except Exception:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.2)  # the ground loop's session is not listening yet


@dataclass
class MissionWatch:
    """Everything an observer saw of one mission (see the module doc)."""

    bus: ZenohBus
    keys: Keys
    t_s: float = 0.0
    """The world's latest simulation time, s."""
    plans: list[tuple[float, PlanMsg]] = field(default_factory=list)
    """(simulation time when received, plan)."""
    telemetry: dict[int, list[TelemetryMsg]] = field(default_factory=dict)
    health: list[HealthMsg] = field(default_factory=list)
    replies: list[ControlReplyMsg] = field(default_factory=list)
    _changed: asyncio.Event = field(default_factory=asyncio.Event)
    _task: asyncio.Task[None] | None = None

    async def __aenter__(self) -> MissionWatch:
        self._task = asyncio.create_task(self._pump())
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

    async def _pump(self) -> None:
        async for key, payload in self.bus.messages(self.keys.everything):
            try:
                msg = decode_any(payload)
            except MessageError:
                continue  # a test's own malformed request
            if key == self.keys.clock:
                self.t_s = max(self.t_s, msg.t_s)
            elif isinstance(msg, PlanMsg):
                self.plans.append((self.t_s, msg))
            elif isinstance(msg, TelemetryMsg):
                self.telemetry.setdefault(msg.uav, []).append(msg)
            elif isinstance(msg, HealthMsg):
                self.health.append(msg)
            elif isinstance(msg, ControlReplyMsg):
                self.replies.append(msg)
            self._changed.set()

    def last_telemetry(self, m: int) -> TelemetryMsg | None:
        got = self.telemetry.get(m)
        return got[-1] if got else None

    def last_plan(self) -> PlanMsg | None:
        return self.plans[-1][1] if self.plans else None

    async def until(self, pred: Callable[[], bool], timeout_s: float, what: str) -> None:
        """Return once `pred()` holds (checked after every message); AssertionError after
        `timeout_s` wall seconds."""
        deadline = time.monotonic() + timeout_s
        while not pred():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"not within {timeout_s} s: {what}")
            self._changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._changed.wait(), min(remaining, 1.0))

    async def send_raw(
        self, payload: bytes, request_id: str | None, timeout_s: float
    ) -> ControlReplyMsg:
        """Publish `payload` on `control`; the reply whose id is `request_id` (None: the next
        reply with a null id)."""
        before = len(self.replies)
        self.bus.publish(self.keys.control, payload)

        def replied() -> bool:
            return any(r.request_id == request_id for r in self.replies[before:])

        await self.until(replied, timeout_s, f"the reply to request {request_id!r}")
        return next(r for r in self.replies[before:] if r.request_id == request_id)

    async def request(
        self,
        request_id: str,
        command: str,
        uav: int | None = None,
        timeout_s: float = 60.0,
        **params: float,
    ) -> ControlReplyMsg:
        """Publish a `control` request and wait for its reply."""
        plan = self.last_plan()
        slot = -1 if plan is None else plan.slot
        msg = ControlMsg(slot, self.t_s, request_id, command, uav, dict(params))
        return await self.send_raw(encode(msg), request_id, timeout_s)
