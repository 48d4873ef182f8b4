"""The operator console: a web page that shows a live mission (or finished traces) and sends
the operator's fleet commands (docs/console.md).

An I/O adapter beside the service: it imports the neutral layer only (wire, bus, records,
config) and watches the bus with its own Zenoh session like any observer. `server` runs
uvicorn on its own thread; `service` holds the bus work, `state` the mission as the page sees
it, `feed` the per-page coalescing queues, `requests` the validated web requests, `replay` the
traces of `isac-mission view`, and `static/` the page.
"""

from isac_mission.console.server import (
    DEFAULT_ADDRESS,
    ConsoleAddress,
    ConsolePortBusyError,
    ConsoleServer,
    parse_address,
)
from isac_mission.console.service import BusAccess, ConsoleService
from isac_mission.console.state import MissionView

__all__ = [
    "DEFAULT_ADDRESS",
    "BusAccess",
    "ConsoleAddress",
    "ConsolePortBusyError",
    "ConsoleServer",
    "ConsoleService",
    "MissionView",
    "parse_address",
]
