"""The planner off the event loop: one daemon thread per slot, its result as an asyncio future."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable
from typing import cast

from isac_mission.types import SlotPlan

SOLVE_LOCK = threading.RLock()
"""The service's SolverKit.solve_lock, shared by every kit it builds: a plan that outlives its
budget keeps its thread (and its kit), and its IPOPT solve must not run beside the next slot's
(MUMPS keeps global state: a 3600-slot soak with `horizon` aborted with "malloc(): unaligned
fastbin chunk detected" after a run of timed-out plans). Only IPOPT is serialised; the rest of a
late plan runs beside the next."""


def in_daemon_thread(fn: Callable[[], SlotPlan], name: str) -> asyncio.Future[SlotPlan]:
    """Run fn on a new daemon thread; its result as a future of the running loop. A daemon
    thread, so that a planner that never returns cannot keep the process from exiting."""
    loop = asyncio.get_running_loop()
    future: asyncio.Future[SlotPlan] = loop.create_future()

    def settle(result: SlotPlan | None, error: BaseException | None) -> None:
        if future.done():
            return
        if error is not None:
            future.set_exception(error)
        else:
            future.set_result(cast(SlotPlan, result))

    def target() -> None:
        try:
            result = fn()
        except BaseException as err:  # delivered to the loop, which decides
            with contextlib.suppress(RuntimeError):  # the loop may be closed by now
                loop.call_soon_threadsafe(settle, None, err)
            return
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(settle, result, None)

    threading.Thread(target=target, name=name, daemon=True).start()
    return future


def consume_result(future: asyncio.Future[SlotPlan]) -> None:
    """Retrieve a timed-out plan's late result or error, so that asyncio does not log it."""
    if not future.cancelled():
        future.exception()
