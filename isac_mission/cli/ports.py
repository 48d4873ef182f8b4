"""Every port of a mission on the command line: the port options of `run`, `sim` and `serve`,
`--port-offset`, and their validation.

A mission uses, on 127.0.0.1 (docs/service.md, "Ports"): the ground loop's Zenoh endpoint
(`tcp/127.0.0.1:7447`), the console (`127.0.0.1:8080`, TCP), and PX4 SITL's MAVLink layout over
UDP: vehicle m (system id m + 1) sends its offboard link to 14540 + m from local port 14580 + m,
and its ground-station link to 14550 (one port for the fleet) from local port 18570 + m. A
MAVLink option not given takes the scenario's `links` section (whose defaults are those).

`--port-offset N` adds N to every one of these defaults (the scenario's `links` included; a local
base port of 0, ephemeral, stays 0), so that two missions on one host need one option each; a
port option given explicitly (`--zenoh-listen`, `--zenoh-connect`, `--console`,
`--mavlink-base-port`, ...) wins over the offset for the port it names. `mission_ports` resolves
them all and raises `PortOptionError`, naming the option, when a port would leave 1-65535 (or
leave no room above a base port for PX4's 254 vehicles: `mavwire.ports.HIGHEST_BASE_PORT`,
as the scenario's `links` and the world require).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Final, TypedDict

import typer

from isac_mission.config import Scenario
from isac_mission.mavwire.ports import HIGHEST_BASE_PORT, MAX_PORT, MAX_VEHICLES

CONSOLE_HOST: Final = "127.0.0.1"
CONSOLE_PORT: Final = 8080
"""The console's default TCP port (`console.DEFAULT_ADDRESS`)."""
DEFAULT_CONSOLE: Final = f"{CONSOLE_HOST}:{CONSOLE_PORT}"
ZENOH_LISTEN_HINT: Final = "choose another with --zenoh-listen"
"""What the message of a busy Zenoh listen port given with `--zenoh-listen` adds (the offset
does not move a port given explicitly)."""
ZENOH_PORT_HINT: Final = f"{ZENOH_LISTEN_HINT}, or move every port with --port-offset"
"""What the message of a busy default Zenoh listen port (7447 + `--port-offset`) adds."""


class PortOptionError(ValueError):
    """A port the mission cannot use: `--port-offset` moves one outside 1-65535 (or leaves no
    room for the vehicles above a base port), or `--zenoh-listen` is malformed or not on
    loopback. The message starts with the option (and its value)."""


def _base_port_callback(*, local: bool) -> Callable[[int | None], int | None]:
    """A typer callback that checks a base port option when it is given: 1 (0 too for a local
    port: ephemeral) up to HIGHEST_BASE_PORT (room for 254 vehicles above it)."""

    def check(value: int | None) -> int | None:
        if value is None or (local and value == 0):
            return value
        if not 1 <= value <= HIGHEST_BASE_PORT:
            zero = "0 (ephemeral) or " if local else ""
            raise typer.BadParameter(
                f"must be {zero}1 to {HIGHEST_BASE_PORT} (room for {MAX_VEHICLES} vehicles "
                f"above it), got {value}"
            )
        return value

    return check


def _gcs_port_callback(value: int | None) -> int | None:
    """A typer callback that checks `--gcs-port` when it is given: 1 to 65535."""
    if value is not None and not 1 <= value <= MAX_PORT:
        raise typer.BadParameter(f"must be 1 to {MAX_PORT}, got {value}")
    return value


MavlinkBasePortOpt = Annotated[
    int | None,
    typer.Option(
        callback=_base_port_callback(local=False),
        help="Offboard links: vehicle m's goes to 127.0.0.1:(P + m), where the service listens "
        "(default: the scenario's links.offboard_base_port, PX4 SITL's 14540, + --port-offset).",
    ),
]
MavlinkLocalBasePortOpt = Annotated[
    int | None,
    typer.Option(
        callback=_base_port_callback(local=True),
        help="Vehicle m sends its offboard link from local port P + m (default: "
        "links.offboard_local_base_port, PX4 SITL's 14580, + --port-offset; 0: ephemeral).",
    ),
]
GcsPortOpt = Annotated[
    int | None,
    typer.Option(
        callback=_gcs_port_callback,
        help="Every vehicle sends its ground-station link to 127.0.0.1:P (default: "
        "links.gcs_port, PX4 SITL's 14550, where QGroundControl and MAVProxy listen, "
        "+ --port-offset).",
    ),
]
GcsLocalBasePortOpt = Annotated[
    int | None,
    typer.Option(
        callback=_base_port_callback(local=True),
        help="Vehicle m sends its ground-station link from local port P + m (default: "
        "links.gcs_local_base_port, PX4 SITL's 18570, + --port-offset; 0: ephemeral).",
    ),
]
ServeMavlinkBasePortOpt = Annotated[
    int | None,
    typer.Option(
        "--mavlink-base-port",
        callback=_base_port_callback(local=False),
        help="The bridge of vehicle m listens on 127.0.0.1:(P + m) (default: the scenario's "
        "links.offboard_base_port, PX4 SITL's offboard ports 14540, + --port-offset).",
    ),
]
PortOffsetOpt = Annotated[
    int,
    typer.Option(
        min=0,
        max=MAX_PORT,
        metavar="N",
        help="Add N to every default port of the mission: Zenoh 7447, console 8080, MAVLink "
        "14540, 14580, 14550 and 18570 (+ m); a port option given explicitly wins for its "
        "port. Two missions on one host: e.g. 0 and 100 (docs/service.md, 'Ports').",
    ),
]


class PortOptions(TypedDict):
    """The port fields of `WorldOptions` and `LiveOptions`."""

    mavlink_base_port: int
    mavlink_local_base_port: int
    gcs_port: int
    gcs_local_base_port: int


def port_options(
    s: Scenario,
    mavlink_base_port: int | None = None,
    mavlink_local_base_port: int | None = None,
    gcs_port: int | None = None,
    gcs_local_base_port: int | None = None,
    *,
    offset: int = 0,
) -> PortOptions:
    """The `WorldOptions` / `LiveOptions` port fields: each option given, else the scenario's
    `links` section plus `offset` (a local base port of 0, ephemeral, stays 0). PortOptionError
    naming `--port-offset` when an offset port leaves the valid range (the options given are
    checked when parsed: `_base_port_callback`)."""
    links = s.links

    def shifted(default: int, what: str, *, base: bool) -> int:
        if default == 0 and base:
            return 0  # ephemeral local ports stay ephemeral
        port = default + offset
        if base and port > HIGHEST_BASE_PORT:
            raise PortOptionError(
                f"--port-offset {offset}: {what} would be {port}, which leaves no room for "
                f"{MAX_VEHICLES} vehicles above it (at most {HIGHEST_BASE_PORT})"
            )
        if not base and port > MAX_PORT:
            raise PortOptionError(
                f"--port-offset {offset}: {what} would be {port}, over {MAX_PORT}"
            )
        return port

    return {
        "mavlink_base_port": shifted(links.offboard_base_port, "the offboard base port", base=True)
        if mavlink_base_port is None
        else mavlink_base_port,
        "mavlink_local_base_port": shifted(
            links.offboard_local_base_port, "the offboard local base port", base=True
        )
        if mavlink_local_base_port is None
        else mavlink_local_base_port,
        "gcs_port": shifted(links.gcs_port, "the ground-station port", base=False)
        if gcs_port is None
        else gcs_port,
        "gcs_local_base_port": shifted(
            links.gcs_local_base_port, "the ground-station local base port", base=True
        )
        if gcs_local_base_port is None
        else gcs_local_base_port,
    }


def zenoh_endpoint(s: Scenario, offset: int = 0) -> str:
    """The ground loop's default Zenoh endpoint for `s` (tcp, or tls with the scenario's TLS on)
    with `offset` added to its port (7447); PortOptionError past 65535."""
    from isac_mission.bus.security import default_endpoint
    from isac_mission.bus.settings import endpoint_port, endpoint_with_port

    endpoint = default_endpoint(s.security.zenoh)
    port = endpoint_port(endpoint) + offset
    if port > MAX_PORT:
        raise PortOptionError(
            f"--port-offset {offset}: the Zenoh port would be {port}, over {MAX_PORT}"
        )
    return endpoint_with_port(endpoint, port)


def console_address(offset: int = 0) -> str:
    """The console's default `HOST:PORT` (127.0.0.1:8080) with `offset` added to its port;
    PortOptionError past 65535."""
    port = CONSOLE_PORT + offset
    if port > MAX_PORT:
        raise PortOptionError(
            f"--port-offset {offset}: the console port would be {port}, over {MAX_PORT}"
        )
    return f"{CONSOLE_HOST}:{port}"


@dataclass(frozen=True)
class MissionPorts:
    """Every port of one mission (docs/service.md, "Ports"): the ground loop's Zenoh endpoint,
    the console's `HOST:PORT`, and the MAVLink ports (`PortOptions`)."""

    zenoh: str
    console: str
    mavlink: PortOptions

    def table(self, n_vehicles: int) -> dict[str, tuple[int, ...]]:
        """The ports themselves, by use, for a fleet of n_vehicles (a local base of 0, ephemeral,
        gives none): what two missions on one host must not share."""
        from isac_mission.bus.settings import endpoint_port

        mav = self.mavlink

        def fleet(base: int) -> tuple[int, ...]:
            return tuple(range(base, base + n_vehicles)) if base else ()

        return {
            "zenoh (TCP)": (endpoint_port(self.zenoh),),
            "console (TCP)": (int(self.console.rpartition(":")[2]),),
            "offboard (UDP)": fleet(mav["mavlink_base_port"]),
            "offboard local (UDP)": fleet(mav["mavlink_local_base_port"]),
            "ground station (UDP)": (mav["gcs_port"],),
            "ground-station local (UDP)": fleet(mav["gcs_local_base_port"]),
        }


def _check_listen_endpoint(endpoint: str) -> None:
    """PortOptionError naming `--zenoh-listen` unless `endpoint` is a Zenoh endpoint on a
    loopback host (the bus's own rule, `bus.settings`)."""
    from isac_mission.bus.settings import LOOPBACK_HOSTS, endpoint_host
    from isac_mission.errors import ConfigError

    try:
        host = endpoint_host(endpoint)
    except ConfigError as err:
        raise PortOptionError(f"--zenoh-listen: {err}") from None
    if host not in LOOPBACK_HOSTS:
        raise PortOptionError(
            f"--zenoh-listen: {endpoint!r}: host {host} is not loopback (127.0.0.1 only)"
        )


def mission_ports(
    s: Scenario,
    offset: int = 0,
    *,
    zenoh: str | None = None,
    console: str | None = None,
    mavlink_base_port: int | None = None,
    mavlink_local_base_port: int | None = None,
    gcs_port: int | None = None,
    gcs_local_base_port: int | None = None,
) -> MissionPorts:
    """Every port of a mission of `s`: each option given as is, every other default plus
    `offset` (`--port-offset`). PortOptionError naming the option: `--port-offset` when a port
    would leave the valid range, `--zenoh-listen` for an endpoint that is malformed or not on
    a loopback host (`zenoh`: the ground loop's listen endpoint)."""
    if offset < 0:
        raise PortOptionError(f"--port-offset {offset}: must be 0 or more")
    if zenoh is not None:
        _check_listen_endpoint(zenoh)
    return MissionPorts(
        zenoh=zenoh if zenoh is not None else zenoh_endpoint(s, offset),
        console=console if console is not None else console_address(offset),
        mavlink=port_options(
            s,
            mavlink_base_port,
            mavlink_local_base_port,
            gcs_port,
            gcs_local_base_port,
            offset=offset,
        ),
    )
