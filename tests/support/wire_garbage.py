"""Bad Zenoh payloads for the wire tests, a GroundLoop in its own thread, and a flooder process.

`bad_payloads(M)` is a catalogue of invalid payloads for the keys the ground loop reads
(detections, telemetry, clock), each with the reason the ground must count it under
(`"rejected <reason>"`, wire.rejection_reason). `GroundThread` runs a real
GroundLoop on its own event loop and Zenoh hub, so that a synchronous test (hypothesis) can
publish and wait while the loop works. Run as a program
(`python -m tests.support.wire_garbage ENDPOINT MISSION M RATE BIG_EVERY_S`) it is a flooder: a
Zenoh peer that publishes the catalogue round-robin at RATE messages per wall second (one of the
oversized payloads every BIG_EVERY_S seconds among them) until SIGTERM or SIGINT, then prints the
number of messages it sent and exits.
"""

from __future__ import annotations

import asyncio
import json
import signal
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, NamedTuple, TypeVar

import numpy as np

from isac_mission.bus import BusSettings, ZenohBus
from isac_mission.config import Scenario
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.report import GroundReport
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.wire import MAX_PAYLOAD_BYTES, ClockMsg, DetectionMsg, Keys, TelemetryMsg, encode
from tests.support.loop_calls import call_on_loop

T = TypeVar("T")


class BadPayload(NamedTuple):
    """An invalid payload: what it is, the key kind it goes to, its bytes, the counter reason."""

    name: str
    kind: str
    """"detections", "telemetry" or "clock"."""
    payload: bytes
    reason: str


def valid_detection(slot: int = 1, uav: int = 0) -> dict[str, Any]:
    """A valid detection payload as a dict."""
    msg = DetectionMsg(slot, 1.0, uav, 812.5, -3.25, np.array([100.0, 200.0]), 0.25)
    return dict(json.loads(encode(msg)))


def valid_telemetry(uav: int = 0) -> dict[str, Any]:
    """A valid telemetry payload as a dict."""
    msg = TelemetryMsg(
        -1, 1.0, uav, np.array([10.0, 20.0]), 30.0, np.array([1.0, 0.0]), "hold", True, False, "ok"
    )
    return dict(json.loads(encode(msg)))


def valid_clock() -> dict[str, Any]:
    """A valid clock payload as a dict (before the mission: slot -1, no t0)."""
    return dict(json.loads(encode(ClockMsg(-1, 1.0, 1.0, 1.0, None))))


def _raw(obj: Any) -> bytes:
    return json.dumps(obj, allow_nan=True).encode()


def _with(base: dict[str, Any], **changes: Any) -> bytes:
    return _raw(base | changes)


def _without(base: dict[str, Any], name: str) -> bytes:
    return _raw({k: v for k, v in base.items() if k != name})


def _megabytes(n_bytes: int) -> bytes:
    """A syntactically valid detection padded to n_bytes (what a parser would chew on)."""
    head = json.dumps(valid_detection())[:-1] + ',"padding":"'
    return (head + "x" * (n_bytes - len(head) - 2) + '"}').encode()


def bad_payloads(n_uavs: int = 3) -> list[BadPayload]:
    """The catalogue of bad payloads (see the module docstring)."""
    det, tel, clk = valid_detection(), valid_telemetry(), valid_clock()
    big = 2 * 1024 * 1024
    return [
        # not JSON, not UTF-8, not an object, too large
        BadPayload("not JSON", "detections", b"{this is not json", "payload not JSON"),
        BadPayload("empty", "detections", b"", "payload not JSON"),
        BadPayload("not UTF-8", "detections", b"\xff\xfe\xfa{\x80}", "payload not UTF-8"),
        BadPayload("an array", "detections", b"[1, 2, 3]", "payload not an object"),
        BadPayload("a string", "telemetry", b'"hello"', "payload not an object"),
        BadPayload(
            "5000-digit integer",
            "detections",
            det_text_replace(det, "uav", "9" * 5000),
            "payload not JSON",
        ),
        BadPayload(
            "nesting 20000 deep", "detections", b"[" * 20_000 + b"]" * 20_000, "payload not JSON"
        ),
        BadPayload("2 MB detection", "detections", _megabytes(big), "payload too large"),
        BadPayload(
            "3 MB of junk", "telemetry", b"\x00\xff" * (3 * 512 * 1024), "payload too large"
        ),
        BadPayload(
            "just over the limit", "clock", _megabytes(MAX_PAYLOAD_BYTES + 1), "payload too large"
        ),
        # wrong schema or version, wrong type
        BadPayload("schema isac/2", "detections", _with(det, schema="isac/2"), "schema"),
        BadPayload("schema other", "telemetry", _with(tel, schema="mavlink/1"), "schema"),
        BadPayload("schema missing", "clock", _without(clk, "schema"), "schema"),
        BadPayload("type clock on detections", "detections", _with(det, type="clock"), "type"),
        # wrong types
        BadPayload("slot as string", "detections", _with(det, slot="3"), "detection.slot"),
        BadPayload("uav 1.5", "detections", _with(det, uav=1.5), "detection.uav"),
        BadPayload("uav out of range", "detections", _with(det, uav=n_uavs), "detection.uav"),
        BadPayload("range as string", "detections", _with(det, range_m="812"), "detection.range_m"),
        BadPayload("range true", "detections", _with(det, range_m=True), "detection.range_m"),
        BadPayload("armed as string", "telemetry", _with(tel, armed="yes"), "telemetry.armed"),
        BadPayload("mode unknown", "telemetry", _with(tel, mode="flying"), "telemetry.mode"),
        BadPayload("speed as list", "clock", _with(clk, speed=[1.0]), "clock.speed"),
        # NaN, infinities, huge numbers
        BadPayload(
            "range NaN token", "detections", _with(det, range_m=float("nan")), "payload non-finite"
        ),
        BadPayload("t Infinity token", "clock", _with(clk, t=float("inf")), "payload non-finite"),
        BadPayload(
            "range 'inf' string", "detections", _with(det, range_m="inf"), "detection.range_m"
        ),
        BadPayload("range 1e308", "detections", _with(det, range_m=1e308), "detection.range_m"),
        BadPayload(
            "range 1e400",
            "detections",
            det_text_replace(det, "range_m", "1e400"),
            "detection.range_m",
        ),
        BadPayload("t 1e308", "detections", _with(det, t=1e308), "detection.t"),
        BadPayload(
            "uav_xy NaN string",
            "detections",
            _with(det, uav_xy_m=["nan", 1.0]),
            "detection.uav_xy_m[0]",
        ),
        BadPayload(
            "altitude 1e308", "telemetry", _with(tel, altitude_m=1e308), "telemetry.altitude_m"
        ),
        BadPayload("speed 0", "clock", _with(clk, speed=0.0), "clock.speed"),
        BadPayload("slot_s negative", "clock", _with(clk, slot_s=-1.0), "clock.slot_s"),
        # missing fields, wrong sizes
        BadPayload("range missing", "detections", _without(det, "range_m"), "detection.range_m"),
        BadPayload("uav_xy missing", "detections", _without(det, "uav_xy_m"), "detection.uav_xy_m"),
        BadPayload(
            "uav_xy of 3", "detections", _with(det, uav_xy_m=[1.0, 2.0, 3.0]), "detection.uav_xy_m"
        ),
        BadPayload("link missing", "telemetry", _without(tel, "link"), "telemetry.link"),
        BadPayload("slot_s missing", "clock", _without(clk, "slot_s"), "clock.slot_s"),
    ]


def det_text_replace(base: dict[str, Any], name: str, literal: str) -> bytes:
    """base as JSON with field `name` written as the raw literal (e.g. 1e400, which Python's
    json would never write)."""
    text = json.dumps(base | {name: 123456.5})
    return text.replace("123456.5", literal).encode()


def _on_subscribe(bus: ZenohBus) -> asyncio.Event:
    """An event set when something subscribes on `bus` (its `subscribe` is wrapped)."""
    subscribed = asyncio.Event()
    subscribe = bus.subscribe

    def subscribe_and_tell(*args: Any, **kwargs: Any) -> Any:
        sub = subscribe(*args, **kwargs)
        subscribed.set()
        return sub

    bus.subscribe = subscribe_and_tell  # type: ignore[method-assign]
    return subscribed


class GroundThread:
    """A GroundLoop (scenario s, settings) on a Zenoh hub at `endpoint`, in its own thread and
    event loop. `start()` returns once the loop runs; `stop()` ends it and returns its report.
    `call(fn)` runs fn on the loop's thread (to read state consistently)."""

    def __init__(self, s: Scenario, endpoint: str, settings: GroundSettings | None = None) -> None:
        self.s = s
        self.endpoint = endpoint
        self.settings = settings if settings is not None else GroundSettings()
        self.keys = Keys(s.mission_id)
        self.loop: GroundLoop | None = None
        self._aio = asyncio.new_event_loop()
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._result: Future[GroundReport] = Future()
        self._thread = threading.Thread(target=self._main, name="ground", daemon=True)

    def _main(self) -> None:
        asyncio.set_event_loop(self._aio)
        try:
            self._result.set_result(self._aio.run_until_complete(self._run()))
        except BaseException as exc:
            self._result.set_exception(exc)
            self._ready.set()
        finally:
            self._aio.close()

    async def _run(self) -> GroundReport:
        self._stop = asyncio.Event()
        with ZenohBus.open(BusSettings.hub(self.endpoint)) as bus:
            subscribed = _on_subscribe(bus)
            self.loop = GroundLoop(self.s, bus, self.settings)
            task = asyncio.create_task(self.loop.run(self._stop))
            # Ready once run() has subscribed (or has ended without subscribing).
            waiting = asyncio.ensure_future(subscribed.wait())
            await asyncio.wait({task, waiting}, timeout=30.0, return_when=asyncio.FIRST_COMPLETED)
            waiting.cancel()
            self._ready.set()
            return await task

    def start(self) -> GroundThread:
        self._thread.start()
        if not self._ready.wait(30.0):
            raise RuntimeError("ground loop did not start")
        if self._result.done():
            self._result.result()
        return self

    @property
    def alive(self) -> bool:
        """True while the loop's run() has neither returned nor raised."""
        return not self._result.done()

    @property
    def counters(self) -> dict[str, int]:
        """A copy of the report's counters (read on the loop's thread while it runs)."""
        loop = self.loop
        assert loop is not None
        if self._result.done():
            return dict(self._result.result().counters)
        try:
            return self.call(lambda: dict(loop.report.counters))
        except RuntimeError:  # the loop finished meanwhile
            return dict(self._result.result(timeout=30.0).counters)

    def call(self, fn: Callable[[], T]) -> T:
        """fn() on the loop's thread; its result."""
        return call_on_loop(self._aio, fn, 30.0)

    def stop(self) -> GroundReport:
        if self._stop is not None and self.alive:
            self._aio.call_soon_threadsafe(self._stop.set)
        report = self._result.result(timeout=30.0)
        self._thread.join(timeout=30.0)
        return report


def flood(endpoint: str, mission: str, n_uavs: int, rate_hz: float, big_every_s: float) -> int:
    """Publish the small payloads of bad_payloads round-robin on detections/<m>, telemetry/<m>
    and clock at rate_hz, and one of the oversized ones (megabytes) every big_every_s, until
    SIGTERM/SIGINT; returns how many were sent (after a subscriber matched)."""
    keys = Keys(mission)
    catalogue = bad_payloads(n_uavs)
    small = [b for b in catalogue if len(b.payload) <= MAX_PAYLOAD_BYTES]
    big = [b for b in catalogue if len(b.payload) > MAX_PAYLOAD_BYTES]
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    sent = 0

    def key_of(bad: BadPayload, m: int) -> str:
        if bad.kind == "detections":
            return keys.detections(m)
        if bad.kind == "telemetry":
            return keys.telemetry(m)
        return keys.clock

    with ZenohBus.open(BusSettings(connect=(endpoint,))) as bus:
        while not stop.is_set() and not asyncio.run(bus.wait_for_subscribers(keys.clock, 1.0)):
            pass
        print("flooding", flush=True)
        period = 1.0 / rate_hz
        due = next_big = time.monotonic()
        i = 0
        while not stop.is_set():
            if time.monotonic() >= next_big:
                bad = big[(sent // len(small)) % len(big)]
                next_big += big_every_s
            else:
                bad = small[i % len(small)]
                i += 1
            bus.publish(key_of(bad, (sent // len(catalogue)) % n_uavs), bad.payload)
            sent += 1
            due += period
            stop.wait(max(0.0, due - time.monotonic()))
    return sent


if __name__ == "__main__":
    endpoint_arg, mission_arg, m_arg, rate_arg, big_arg = sys.argv[1:6]
    n_sent = flood(endpoint_arg, mission_arg, int(m_arg), float(rate_arg), float(big_arg))
    print(f"sent {n_sent}", flush=True)
