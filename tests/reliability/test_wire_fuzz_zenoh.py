"""Bad Zenoh payloads to a real GroundLoop (issue 7, item 3; the MAVLink fuzz is in
test_wire_fuzz_mavlink.py, the garbage flood in test_wire_flood.py).

A catalogue of invalid payloads (not JSON, not UTF-8, wrong schema or version, wrong types, NaN
and huge numbers, missing fields, megabytes long) and hypothesis-mutated payloads are published
to a GroundLoop; each must be counted under "rejected <reason>" and dropped, quickly (an
oversized payload is refused before parsing), and the loop must go on to fly a mission.

Every socket is on 127.0.0.1; every Zenoh session has explicit loopback endpoints and no
multicast scouting (BusSettings). The hypothesis runs are derandomized (the same examples every
run) and bounded: 150 examples per property, ISAC_FUZZ_EXAMPLES=<n> for a longer fuzz.
"""

from __future__ import annotations

import asyncio
import importlib
import json
from collections import Counter
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from isac_mission import wire
from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import Scenario
from isac_mission.errors import MessageError
from isac_mission.wire import (
    ClockMsg,
    DetectionMsg,
    TelemetryMsg,
    decode,
    encode,
    rejection_reason,
)
from tests.support.fuzz import FUZZ, WAIT_S
from tests.support.sim_harness import wait_until
from tests.support.wire_garbage import (
    GroundThread,
    bad_payloads,
    valid_clock,
    valid_detection,
    valid_telemetry,
)


def _publish_and_wait(
    ground: GroundThread, world: ZenohBus, key: str, payload: bytes, not_json: bool
) -> None:
    """Publish, then publish a sentinel (not JSON) on the same key and wait until it has been
    counted: Zenoh keeps one publisher's order, so the payload has been handled too. not_json:
    the payload itself is counted as not JSON (then the count must rise by two, or the wait
    could end on the payload, before the sentinel: CI saw it with an empty payload)."""
    name = "rejected payload not JSON"
    target = ground.counters.get(name, 0) + 1 + int(not_json)
    world.publish(key, payload)
    world.publish(key, b"sentinel")
    wait_until(lambda: ground.counters.get(name, 0) >= target, WAIT_S, "the sentinel to be counted")


def _counted(g: GroundThread, name: str, count: int) -> Callable[[], bool]:
    """A condition: the ground has counted `name` at least `count` times."""
    return lambda: g.counters.get(name, 0) >= count


def _rejected(counters: dict[str, int]) -> Counter[str]:
    return Counter({k: v for k, v in counters.items() if k.startswith("rejected ")})


@pytest.fixture
def ground(paper: Scenario, free_tcp_port: int) -> Any:
    """A GroundLoop (N = 3 slots) in its own thread, and a world session connected to it."""
    s = paper.with_changes(N=3)
    endpoint = tcp_loopback(free_tcp_port)
    g = GroundThread(s, endpoint).start()
    world = ZenohBus.open(BusSettings(connect=(endpoint,)))
    try:
        assert asyncio.run(world.wait_for_subscribers(g.keys.clock, WAIT_S))
        yield g, world
    finally:
        world.close()
        if g.alive:
            g.stop()


def test_each_bad_payload_is_counted_under_its_reason_and_the_mission_still_flies(
    ground: tuple[GroundThread, ZenohBus],
) -> None:
    g, world = ground
    keys, m = g.keys, g.s.M
    catalogue = bad_payloads(m)
    expected: Counter[str] = Counter()
    for i, bad in enumerate(catalogue):
        key = {
            "detections": keys.detections(i % m),
            "telemetry": keys.telemetry(i % m),
            "clock": keys.clock,
        }[bad.kind]
        name = f"rejected {bad.reason}"
        before = g.counters.get(name, 0)
        world.publish(key, bad.payload)
        wait_until(_counted(g, name, before + 1), WAIT_S, bad.name)
        expected[name] += 1
        assert g.alive, f"the ground loop stopped after {bad.name!r}"
    assert _rejected(g.counters) == expected
    # Megabytes go over the wire (Zenoh fragments them) and are counted as too large (how soon:
    # bench/refusal.py).
    big = [b.reason for b in catalogue if len(b.payload) > wire.MAX_PAYLOAD_BYTES]
    assert big == ["payload too large"] * 3

    # Then a normal mission: clock, M detections per slot, all N slots complete.
    world.publish(keys.clock, encode(ClockMsg(0, 0.0, g.s.dt, 1.0, 0.0)))
    for n in range(1, g.s.N + 1):
        for u in range(m):
            obj = valid_detection(slot=n, uav=u) | {"uav_xy_m": list(g.s.uav_start_xy[u])}
            world.publish(keys.detections(u), json.dumps(obj).encode())
        wait_until(_counted(g, "slots", n), WAIT_S, f"slot {n}")
    report = g.stop()
    assert report.counters["slots"] == g.s.N
    assert _rejected(report.counters) == expected
    assert "slot_s" in report.last_error  # the last refusal, with its reason


def test_an_oversized_payload_is_refused_before_it_is_parsed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """4 MB of valid JSON is refused by the size check (wire.MAX_PAYLOAD_BYTES) without reaching
    the JSON parser, which would take tens of milliseconds on it (bench/refusal.py times both)."""
    body = json.dumps(valid_detection() | {"pad": [1.5] * 800_000}).encode()
    assert len(body) > 3_000_000
    parsed: list[int] = []

    def parser(text: str) -> Any:
        parsed.append(len(text))
        return json.loads(text)

    # The module (the package's `envelope` is a function of it).
    envelope_module = importlib.import_module("isac_mission.wire.envelope")
    monkeypatch.setattr(envelope_module, "loads_strict", parser)
    with pytest.raises(MessageError) as info:
        decode(DetectionMsg, body)
    assert rejection_reason(info.value) == "payload too large"
    assert parsed == []
    # The same parser sees a payload under the limit (the check above can fail).
    decode(DetectionMsg, json.dumps(valid_detection()).encode())
    assert parsed


_JSON_SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e308, -1e308, 1e9 + 1, 2**63, "NaN", "inf", "", "isac/2"]),
    st.text(max_size=20),
)
_JSON = st.recursive(
    _JSON_SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)


@st.composite
def mutated_payloads(draw: st.DrawFn) -> tuple[str, bytes]:
    """(key kind, payload): a valid payload with 1-3 fields replaced, deleted or added, or
    random bytes."""
    kind = draw(st.sampled_from(["detections", "telemetry", "clock"]))
    if draw(st.integers(0, 9)) == 0:
        return kind, draw(st.binary(max_size=200))
    makers: dict[str, Callable[[], dict[str, Any]]] = {
        "detections": valid_detection,
        "telemetry": valid_telemetry,
        "clock": valid_clock,
    }
    obj = makers[kind]()
    for _ in range(draw(st.integers(1, 3))):
        name = draw(st.one_of(st.sampled_from(sorted(obj)), st.text(max_size=8)))
        if draw(st.booleans()) and name in obj:
            del obj[name]
        else:
            obj[name] = draw(_JSON)
    return kind, json.dumps(obj, allow_nan=True).encode()


def test_mutated_payloads_are_each_counted_or_used_and_never_crash_the_loop(
    ground: tuple[GroundThread, ZenohBus],
) -> None:
    """Property: a payload the codec refuses (only ever with MessageError) is counted by the
    ground under exactly that reason; one it accepts is not counted as rejected."""
    g, world = ground
    keys, m = g.keys, g.s.M
    expected = _rejected(g.counters)
    decoders: dict[str, Callable[[bytes], object]] = {
        "detections": lambda p: decode(DetectionMsg, p, n_uavs=m),
        "telemetry": lambda p: decode(TelemetryMsg, p, n_uavs=m),
        "clock": lambda p: decode(ClockMsg, p),
    }
    seen: Counter[str] = Counter()

    @FUZZ
    @given(mutated_payloads())
    def one(case: tuple[str, bytes]) -> None:
        kind, payload = case
        try:
            decoders[kind](payload)
            reason = None
        except MessageError as err:
            reason = rejection_reason(err)
        if reason is None and kind == "clock":
            return  # a valid clock would start the mission: not what this test is about
        key = {"detections": keys.detections(0), "telemetry": keys.telemetry(1)}.get(
            kind, keys.clock
        )
        _publish_and_wait(g, world, key, payload, reason == "payload not JSON")
        expected["rejected payload not JSON"] += 1  # the sentinel
        if reason is not None:
            expected[f"rejected {reason}"] += 1
            seen[reason] += 1
        assert g.alive
        assert _rejected(g.counters) == expected

    one()
    print("mutated payloads refused, by reason:", dict(seen))
    assert len(seen) >= 5  # the fuzz reached several distinct checks
