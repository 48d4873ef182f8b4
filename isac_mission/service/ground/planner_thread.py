"""The planner off the event loop: one daemon thread per slot, its result as an asyncio future,
and the wait for the threads still solving before the process exits.

Why the wait: at interpreter shutdown CPython ends a daemon thread that asks for the GIL with
pthread_exit, a forced unwind through whatever native frames the thread is in. In IPOPT (CasADi's
C++, whose catch (...) blocks swallow the unwind) that aborts the process ("FATAL: exception not
rethrown", exit 134) after a mission that had completed: a plan that outlived its budget was
still solving. `drain_planner_threads` is called before `run` and `serve` exit.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Callable
from typing import Any, TypeVar, cast

Result = TypeVar("Result")

SOLVE_LOCK = threading.RLock()
"""The service's SolverKit.solve_lock, shared by every kit it builds: a plan that outlives its
budget keeps its thread (and its kit), and its IPOPT solve must not run beside the next slot's
(MUMPS keeps global state: a 3600-slot soak with `horizon` aborted with "malloc(): unaligned
fastbin chunk detected" after a run of timed-out plans). Only IPOPT is serialised; the rest of a
late plan runs beside the next."""


_RUNNING: set[threading.Thread] = set()
_RUNNING_LOCK = threading.Lock()


def in_daemon_thread(fn: Callable[[], Result], name: str) -> asyncio.Future[Result]:
    """Run fn on a new daemon thread; its result as a future of the running loop. A daemon
    thread, so that a planner that never returns cannot keep the process from exiting (see
    `drain_planner_threads` for how it exits then)."""
    loop = asyncio.get_running_loop()
    future: asyncio.Future[Result] = loop.create_future()

    def settle(result: Result | None, error: BaseException | None) -> None:
        if future.done():
            return
        if error is not None:
            future.set_exception(error)
        else:
            future.set_result(cast(Result, result))

    def target() -> None:
        try:
            result = fn()
        except BaseException as err:  # delivered to the loop, which decides
            with contextlib.suppress(RuntimeError):  # the loop may be closed by now
                loop.call_soon_threadsafe(settle, None, err)
            return
        finally:
            with _RUNNING_LOCK:
                _RUNNING.discard(threading.current_thread())
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(settle, result, None)

    thread = threading.Thread(target=target, name=name, daemon=True)
    with _RUNNING_LOCK:
        _RUNNING.add(thread)
    thread.start()
    return future


def planner_threads() -> list[threading.Thread]:
    """The planner threads still running (a plan being made, or a timed-out one's late solve)."""
    with _RUNNING_LOCK:
        return [t for t in _RUNNING if t.is_alive()]


def drain_planner_threads(timeout_s: float) -> bool:
    """Wait up to timeout_s (wall seconds) for every planner thread to end; True if none is
    left. The caller that gets False must leave with os._exit (module docstring)."""
    deadline = time.monotonic() + timeout_s
    for thread in planner_threads():
        thread.join(max(0.0, deadline - time.monotonic()))
    return not planner_threads()


def consume_result(future: asyncio.Future[Any]) -> None:
    """Retrieve a timed-out plan's late result or error, so that asyncio does not log it."""
    if not future.cancelled():
        future.exception()
