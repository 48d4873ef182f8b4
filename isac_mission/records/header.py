"""Line 1 of a trace (docs/trace.md, "Line 1"): the format, its version, and the config.

A trace written now starts `{"format": "isac-mission trace 2", "config": {...}}`, whatever the
number of targets. Older files are read as they are: a single-target trace of version 1 starts
`{"config": {...}}` alone, a multi-target trace of version 1
`{"format": "isac-mission multi-target trace 1", "config": {...}}`.
"""

from __future__ import annotations

from typing import Any, Final

from isac_mission.errors import MessageError
from isac_mission.records.jsonlines import dumps_line, to_jsonable

TRACE_FORMAT: Final = "isac-mission trace 2"
"""The first line's `format` of every trace written now."""
TRACKS_FORMAT_1: Final = "isac-mission multi-target trace 1"
"""The first line's `format` of a multi-target trace of version 1."""
LABELLED_FORMAT_1: Final = "isac-mission trace 1"
"""What a version-1 single-target trace (line 1 `{"config": ...}` alone) is read as."""
FORMATS: Final = (TRACE_FORMAT, TRACKS_FORMAT_1)


def header_line(config: dict[str, Any]) -> str:
    """Line 1 of a trace: the format and the resolved configuration."""
    return dumps_line({"format": TRACE_FORMAT, "config": to_jsonable(dict(config), "config")})


def parse_header(obj: Any) -> tuple[str, dict[str, Any]]:
    """(format, config) of a parsed line 1, of any version; MessageError naming what is wrong."""
    if isinstance(obj, dict) and set(obj) == {"config"} and isinstance(obj["config"], dict):
        return LABELLED_FORMAT_1, obj["config"]
    if (
        isinstance(obj, dict)
        and set(obj) == {"format", "config"}
        and isinstance(obj["config"], dict)
    ):
        fmt = obj["format"]
        if fmt not in FORMATS:
            known = ", ".join(repr(f) for f in FORMATS)
            raise MessageError(f"format: {fmt!r} is not a trace format this reader knows ({known})")
        return str(fmt), obj["config"]
    raise MessageError('the first line must be {"format": "isac-mission trace 2", "config": {...}}')
