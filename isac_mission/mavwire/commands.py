"""The MAVLink command protocol of a ground station's link: COMMAND_LONG out, COMMAND_ACK back.

One command at a time. Each attempt waits `timeout_s` wall seconds for the matching COMMAND_ACK;
IN_PROGRESS restarts the wait without resending; a retry bumps the `confirmation` field as the
MAVLink command protocol asks. A final result other than ACCEPTED, or no answer after the last
attempt, raises `LinkError` naming the command and the result.
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from isac_mission.errors import LinkError
from isac_mission.mavwire.builders import command_name, result_name
from isac_mission.mavwire.dialect import mavlink2

log = logging.getLogger(__name__)


@dataclass
class _PendingCommand:
    command: int
    future: asyncio.Future[int]
    progress_wall_s: float | None = None
    """Loop time of the last IN_PROGRESS answer."""


class CommandProtocol:
    """The command exchange of one link.

    Args:
        name: The link's name, for log messages and errors.
        send: Sends one message on the link; False when nothing could be sent.
        ignored: The link's counter of benign drops (an unexpected ACK is one).
    """

    def __init__(self, name: str, send: Callable[[Any], bool], ignored: Counter[str]) -> None:
        self._name = name
        self._send = send
        self._ignored = ignored
        self._pending: _PendingCommand | None = None
        self._lock = asyncio.Lock()

    def on_ack(self, msg: Any) -> None:
        """COMMAND_ACK handler: completes the pending command (IN_PROGRESS extends its wait)."""
        pending = self._pending
        if pending is None or int(msg.command) != pending.command or pending.future.done():
            self._ignored["unexpected_ack"] += 1
            return
        result = int(msg.result)
        if result == mavlink2.MAV_RESULT_IN_PROGRESS:
            pending.progress_wall_s = pending.future.get_loop().time()
            return
        pending.future.set_result(result)

    def fail_pending(self) -> None:
        """The link closed: a pending command fails with LinkError."""
        pending = self._pending
        if pending is not None and not pending.future.done():
            pending.future.set_exception(
                LinkError(f"{self._name}: link closed during {command_name(pending.command)}")
            )

    async def run(self, msg: Any, timeout_s: float, attempts: int) -> None:
        """Send COMMAND_LONG `msg` and wait for ACCEPTED (see the module docstring)."""
        if msg.get_type() != "COMMAND_LONG":
            raise ValueError(f"command() takes COMMAND_LONG, got {msg.get_type()}")
        cmd = int(msg.command)
        name = command_name(cmd)
        async with self._lock:
            loop = asyncio.get_running_loop()
            for attempt in range(max(1, attempts)):
                pending = _PendingCommand(cmd, loop.create_future())
                self._pending = pending
                msg.confirmation = attempt
                try:
                    if not self._send(msg):
                        raise LinkError(f"{self._name}: {name}: no link to the vehicle")
                    wait_s = timeout_s
                    while True:
                        try:
                            async with asyncio.timeout(wait_s):
                                result = await asyncio.shield(pending.future)
                        except TimeoutError:
                            progress = pending.progress_wall_s
                            if progress is None or loop.time() - progress >= timeout_s:
                                break  # no answer: resend
                            wait_s = timeout_s - (loop.time() - progress)  # IN_PROGRESS
                            continue
                        if result == mavlink2.MAV_RESULT_ACCEPTED:
                            log.info("%s: %s accepted", self._name, name)
                            return
                        raise LinkError(f"{self._name}: {name} refused: {result_name(result)}")
                finally:
                    self._pending = None
                log.warning("%s: no COMMAND_ACK for %s (attempt %d)", self._name, name, attempt + 1)
        raise LinkError(
            f"{self._name}: {name}: no COMMAND_ACK after {max(1, attempts)} attempts "
            f"of {timeout_s:g} s (result: timeout)"
        )
