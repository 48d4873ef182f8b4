"""Trace lines as strict JSON (docs/trace.md), on the shared `isac_mission.wire.strict_json`.

A trace file holds no NaN or Infinity token: every non-finite number is written as `null`
(`to_jsonable`), and a reader refuses those tokens with a MessageError naming them.
"""

from __future__ import annotations

import json
from typing import Any

from isac_mission.errors import MessageError
from isac_mission.wire.strict_json import (
    NonFiniteTokenError,
    dumps_strict,
    loads_strict,
    to_jsonable,
)


def dumps_line(obj: Any) -> str:
    """One compact strict-JSON line (no newline) of a JSON-ready object; UTF-8 kept as is."""
    return dumps_strict(obj, ensure_ascii=False)


def loads_line(text: str) -> Any:
    """Parse one line; raises MessageError for invalid JSON or a NaN/Infinity token."""
    try:
        return loads_strict(text)
    except NonFiniteTokenError as err:
        raise MessageError(
            f"non-standard JSON constant {err.token} (non-finite numbers are written null)"
        ) from None
    except json.JSONDecodeError as err:
        raise MessageError(f"not valid JSON: {err.msg} at column {err.colno}") from None


__all__ = ["dumps_line", "loads_line", "to_jsonable"]
