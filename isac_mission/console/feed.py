"""Per-page update feeds: what the server has not yet sent a page, coalesced and bounded.

Every update has a topic. A *state* topic (`telemetry/0`, `plan`, `track`, `health`, ...) keeps
only its latest value: a page that falls behind gets the newest state, not a backlog. An *event*
topic (`series`, `reply`, `notice`) is appended to a bounded queue whose oldest items are dropped
when it is full. `put` never blocks and never waits for a page; the page's sender task awaits
`wait()` and sends `take()` as one message. `Hub.broadcast` encodes an update once for every
page. So a slow or stalled page costs a bounded amount of
memory and never delays the bus or the other pages.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Final

log = logging.getLogger(__name__)

EVENT_TOPICS: Final = frozenset({"series", "reply", "notice"})
"""Topics whose every item is kept (up to the queue's bound) instead of the latest one."""
MAX_EVENTS: Final = 512
"""Events a feed keeps for a page that has not taken them."""


@dataclass
class FeedCounters:
    """put: updates offered; coalesced: state updates replaced before they were sent; dropped:
    events dropped from a full queue; batches: messages taken for sending."""

    put: int = 0
    coalesced: int = 0
    dropped: int = 0
    batches: int = 0


@dataclass(eq=False)
class ClientFeed:
    """The pending updates of one page (single-threaded: used on the server's event loop)."""

    max_events: int = MAX_EVENTS
    counters: FeedCounters = field(default_factory=FeedCounters)
    _latest: dict[str, str] = field(default_factory=dict)
    _events: deque[tuple[str, str]] = field(default_factory=deque)
    _ready: asyncio.Event | None = None

    def put(self, topic: str, data: str) -> None:
        """Offer an update, `data` its encoded JSON (never blocks)."""
        self.counters.put += 1
        if topic in EVENT_TOPICS:
            if len(self._events) >= self.max_events:
                self._events.popleft()
                self.counters.dropped += 1
            self._events.append((topic, data))
        else:
            if topic in self._latest:
                self.counters.coalesced += 1
                del self._latest[topic]  # re-inserted last: the dict keeps arrival order
            self._latest[topic] = data
        if self._ready is not None:
            self._ready.set()

    @property
    def pending(self) -> int:
        """Updates waiting to be taken."""
        return len(self._latest) + len(self._events)

    def take(self) -> list[str]:
        """Everything pending (encoded updates), state topics first; empty afterwards."""
        out = list(self._latest.values())
        out += [d for _, d in self._events]
        self._latest.clear()
        self._events.clear()
        if self._ready is not None:
            self._ready.clear()
        if out:
            self.counters.batches += 1
        return out

    async def wait(self) -> None:
        """Return once something is pending (at once if it already is)."""
        if self._ready is None:
            self._ready = asyncio.Event()
        if self.pending:
            return
        self._ready.clear()
        await self._ready.wait()


@dataclass
class Hub:
    """Every connected page's feed; `broadcast` offers an update to all of them."""

    feeds: set[ClientFeed] = field(default_factory=set)
    connections: int = 0
    """Pages connected since the start (for the health panel and the bench)."""

    def add(self, feed: ClientFeed) -> None:
        self.feeds.add(feed)
        self.connections += 1

    def remove(self, feed: ClientFeed) -> None:
        self.feeds.discard(feed)

    def broadcast(self, topic: str, data: Any) -> None:
        """Encode `{"topic", "data"}` once and offer it to every page (nothing if no page)."""
        if not self.feeds:
            return
        try:
            text = json.dumps(
                {"topic": topic, "data": data}, allow_nan=False, separators=(",", ":")
            )
        except (TypeError, ValueError) as err:  # a non-finite number: never sent as NaN
            log.warning("console: update %s not sent: %s", topic, err)
            return
        for feed in self.feeds:
            feed.put(topic, text)


def batch_text(items: list[str]) -> str:
    """One WebSocket message: the JSON array of encoded updates."""
    return "[" + ",".join(items) + "]"
