"""The MAVLink port options of `run`, `sim` and `serve`: PX4 SITL's layout by default.

Vehicle m (system id m + 1) sends its offboard link to 127.0.0.1:(14540 + m) from local port
14580 + m, and its ground-station link to 127.0.0.1:14550 (one port for the fleet) from local
port 18570 + m (docs/service.md, "Ports").
"""

from __future__ import annotations

from typing import Annotated

import typer

MavlinkBasePortOpt = Annotated[
    int,
    typer.Option(
        help="Offboard links: vehicle m's goes to 127.0.0.1:(P + m), where the service listens "
        "(PX4 SITL: 14540)."
    ),
]
MavlinkLocalBasePortOpt = Annotated[
    int,
    typer.Option(
        help="Vehicle m sends its offboard link from local port P + m (PX4 SITL: 14580; "
        "0: ephemeral)."
    ),
]
GcsPortOpt = Annotated[
    int,
    typer.Option(
        help="Every vehicle sends its ground-station link to 127.0.0.1:P (PX4 SITL: 14550; "
        "QGroundControl and MAVProxy listen there)."
    ),
]
GcsLocalBasePortOpt = Annotated[
    int,
    typer.Option(
        help="Vehicle m sends its ground-station link from local port P + m (PX4 SITL: 18570; "
        "0: ephemeral)."
    ),
]
