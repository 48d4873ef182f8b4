"""Line 1 of a trace (docs/trace.md, "Line 1"): the format, the release that wrote it, the config.

A trace written now starts
`{"format": "isac-mission trace 2", "isac_mission_version": "0.4.0", "config": {...}}`, whatever
the number of targets: the format's version says how to read the lines, the package's version
which release wrote them (traces written before 0.4.0 have no such key). Older files are read as they are: a single-target trace of version 1 starts
`{"config": {...}}` alone, a multi-target trace of version 1
`{"format": "isac-mission multi-target trace 1", "config": {...}}`.
"""

from __future__ import annotations

from typing import Any, Final

from isac_mission import __version__
from isac_mission.errors import MessageError
from isac_mission.records.jsonlines import dumps_line, to_jsonable

TRACE_FORMAT: Final = "isac-mission trace 2"
"""The first line's `format` of every trace written now."""
TRACKS_FORMAT_1: Final = "isac-mission multi-target trace 1"
"""The first line's `format` of a multi-target trace of version 1."""
LABELLED_FORMAT_1: Final = "isac-mission trace 1"
"""What a version-1 single-target trace (line 1 `{"config": ...}` alone) is read as."""
FORMATS: Final = (TRACE_FORMAT, TRACKS_FORMAT_1)
VERSION_KEY: Final = "isac_mission_version"
"""Line 1's key for the release of the package that wrote the trace (absent before 0.4.0)."""


def header_line(config: dict[str, Any]) -> str:
    """Line 1 of a trace: the format, this package's release and the resolved configuration."""
    return dumps_line(
        {
            "format": TRACE_FORMAT,
            VERSION_KEY: __version__,
            "config": to_jsonable(dict(config), "config"),
        }
    )


def parse_header(obj: Any) -> tuple[str, dict[str, Any]]:
    """(format, config) of a parsed line 1, of any version (the writer's release, if given, is
    `written_by(obj)`); MessageError naming what is wrong."""
    if isinstance(obj, dict) and set(obj) == {"config"} and isinstance(obj["config"], dict):
        return LABELLED_FORMAT_1, obj["config"]
    if (
        isinstance(obj, dict)
        and set(obj) - {VERSION_KEY} == {"format", "config"}
        and isinstance(obj["config"], dict)
    ):
        written_by(obj)
        fmt = obj["format"]
        if fmt not in FORMATS:
            known = ", ".join(repr(f) for f in FORMATS)
            raise MessageError(f"format: {fmt!r} is not a trace format this reader knows ({known})")
        return str(fmt), obj["config"]
    raise MessageError('the first line must be {"format": "isac-mission trace 2", "config": {...}}')


def written_by(obj: dict[str, Any]) -> str | None:
    """The release that wrote a parsed line 1 (None: written before 0.4.0); MessageError if
    it is not a version string."""
    version = obj.get(VERSION_KEY)
    if version is not None and not isinstance(version, str):
        raise MessageError(f"{VERSION_KEY}: {version!r} is not a version string")
    return version
