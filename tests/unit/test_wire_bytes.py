"""The bytes on the bus do not change: `wire.encode` of every sample message equals a frozen copy.

tests/unit/data/wire_bytes.json (sample name -> payload text) was written once, by a one-off
script run before the per-type encoders (`encode_detection`, `encode_plan`, ...) gave way to the
one generic `wire.encode`: it encoded `tests/support/wire_samples.samples()` with those old
encoders. The script is not kept (it needed the old encoders). A deliberate change of a bus
format (docs/bus.md) regenerates the file and says so in docs/bus.md.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from isac_mission.wire import decode, decode_any, encode
from isac_mission.wire.models import MODELS
from tests.support.wire_samples import samples

FROZEN: dict[str, str] = json.loads(
    (Path(__file__).parent / "data" / "wire_bytes.json").read_text(encoding="utf-8")
)


def test_every_message_type_has_a_sample_with_frozen_bytes() -> None:
    msgs = samples()
    assert sorted(msgs) == sorted(FROZEN)
    assert {msg.kind() for msg in msgs.values()} == set(MODELS)


@pytest.mark.parametrize("name", sorted(FROZEN))
def test_the_encoder_writes_the_frozen_bytes(name: str) -> None:
    assert encode(samples()[name]).decode() == FROZEN[name]


@pytest.mark.parametrize("name", sorted(FROZEN))
def test_the_frozen_bytes_decode_and_encode_back_unchanged(name: str) -> None:
    data = FROZEN[name].encode()
    kind = json.loads(data)["type"]
    assert encode(decode(kind, data)).decode() == FROZEN[name]
    assert encode(decode_any(data)).decode() == FROZEN[name]
