"""isac_mission/wire/strict_json.py: the strict JSON shared by the bus payloads and the trace."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from isac_mission.errors import MessageError
from isac_mission.wire.strict_json import (
    NonFiniteTokenError,
    dumps_strict,
    finite_floats,
    finite_or_none,
    loads_strict,
    to_jsonable,
)


@pytest.mark.parametrize("token", ["NaN", "Infinity", "-Infinity"])
def test_non_finite_tokens_are_refused_by_name(token: str) -> None:
    with pytest.raises(NonFiniteTokenError) as info:
        loads_strict(f'{{"a": [1, {token}]}}')
    assert info.value.token == token


def test_standard_json_reads_as_json_does() -> None:
    text = '{"a": [1, 2.5, null, true], "b": {"c": "d"}}'
    assert loads_strict(text) == json.loads(text)
    assert loads_strict(text.encode()) == json.loads(text)
    with pytest.raises(json.JSONDecodeError):
        loads_strict("{not json")


def test_writer_is_compact_and_refuses_non_finite_numbers() -> None:
    assert dumps_strict({"a": [1, 2.5], "b": "é"}) == '{"a":[1,2.5],"b":"\\u00e9"}'
    assert dumps_strict({"b": "é"}, ensure_ascii=False) == '{"b":"é"}'
    with pytest.raises(ValueError, match="JSON compliant"):
        dumps_strict({"a": math.nan})


def test_missing_numbers_become_null_and_arrays_lists() -> None:
    assert finite_or_none(math.inf) is None and finite_or_none(2.0) == 2.0
    assert finite_floats(np.array([[1.0, 2.0], [3.0, 4.0]]), "x") == [1.0, 2.0, 3.0, 4.0]
    with pytest.raises(MessageError, match=r"^x\[1\]: nan is not finite"):
        finite_floats([1.0, math.nan], "x")
    value = {"a": np.array([1.0, np.nan]), "b": (np.int64(3), np.bool_(True)), "p": Path("/x")}
    assert to_jsonable(value) == {"a": [1.0, None], "b": [3, True], "p": "/x"}
    with pytest.raises(MessageError, match=r"^v\.k: cannot write object"):
        to_jsonable({"k": object()}, "v")
    with pytest.raises(MessageError, match="keys must be strings"):
        to_jsonable({1: 2}, "v")
