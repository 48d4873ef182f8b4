"""Run a function on an asyncio loop that lives in another thread, from a test's thread."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from concurrent.futures import Future
from typing import TypeVar

T = TypeVar("T")


def call_on_loop(loop: asyncio.AbstractEventLoop, fn: Callable[[], T], timeout_s: float) -> T:
    """fn() on `loop`'s thread; its result (or its exception), waiting at most timeout_s."""
    fut: Future[T] = Future()

    def run() -> None:
        try:
            fut.set_result(fn())
        except BaseException as exc:
            fut.set_exception(exc)

    loop.call_soon_threadsafe(run)
    return fut.result(timeout=timeout_s)
