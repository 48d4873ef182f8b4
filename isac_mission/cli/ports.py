"""The MAVLink port options of `run`, `sim` and `serve`: PX4 SITL's layout by default.

Vehicle m (system id m + 1) sends its offboard link to 127.0.0.1:(14540 + m) from local port
14580 + m, and its ground-station link to 127.0.0.1:14550 (one port for the fleet) from local
port 18570 + m (docs/service.md, "Ports"). An option not given takes the scenario's `links`
section (whose defaults are those); `port_options` resolves them.
"""

from __future__ import annotations

from typing import Annotated, TypedDict

import typer

from isac_mission.config import Scenario

MavlinkBasePortOpt = Annotated[
    int | None,
    typer.Option(
        help="Offboard links: vehicle m's goes to 127.0.0.1:(P + m), where the service listens "
        "(default: the scenario's links.offboard_base_port, PX4 SITL's 14540)."
    ),
]
MavlinkLocalBasePortOpt = Annotated[
    int | None,
    typer.Option(
        help="Vehicle m sends its offboard link from local port P + m (default: "
        "links.offboard_local_base_port, PX4 SITL's 14580; 0: ephemeral)."
    ),
]
GcsPortOpt = Annotated[
    int | None,
    typer.Option(
        help="Every vehicle sends its ground-station link to 127.0.0.1:P (default: "
        "links.gcs_port, PX4 SITL's 14550, where QGroundControl and MAVProxy listen)."
    ),
]
GcsLocalBasePortOpt = Annotated[
    int | None,
    typer.Option(
        help="Vehicle m sends its ground-station link from local port P + m (default: "
        "links.gcs_local_base_port, PX4 SITL's 18570; 0: ephemeral)."
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
) -> PortOptions:
    """The `WorldOptions` / `LiveOptions` port fields: each option given, else the scenario's
    `links` section."""
    links = s.links
    return {
        "mavlink_base_port": links.offboard_base_port
        if mavlink_base_port is None
        else mavlink_base_port,
        "mavlink_local_base_port": links.offboard_local_base_port
        if mavlink_local_base_port is None
        else mavlink_local_base_port,
        "gcs_port": links.gcs_port if gcs_port is None else gcs_port,
        "gcs_local_base_port": links.gcs_local_base_port
        if gcs_local_base_port is None
        else gcs_local_base_port,
    }
