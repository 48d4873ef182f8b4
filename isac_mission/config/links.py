"""The `links` section of a scenario: the MAVLink ports of the live system, PX4 SITL's layout by
default (docs/service.md, "Ports"). Every port is UDP on 127.0.0.1.

Vehicle m (system id m + 1) sends its offboard link from `offboard_local_base_port` + m to
`offboard_base_port` + m (where `serve`'s bridge m listens) and its ground-station link from
`gcs_local_base_port` + m to `gcs_port` (one port for the whole fleet). The numbers repeat
`isac_mission.mavwire.ports` (config imports no peer package); a unit test keeps them equal.
The CLI's port options override them.
"""

from __future__ import annotations

from pydantic import Field

from isac_mission.config.sections import Section

_ROOM = 65535 - 253
"""The highest base port that leaves room for 254 vehicles."""


class LinksConfig(Section):
    """MAVLink ports (module docstring); a local base port of 0 binds ephemeral ports."""

    offboard_base_port: int = Field(
        14540, ge=1, le=_ROOM, description="Vehicle m's offboard link goes to this + m (PX4)."
    )
    offboard_local_base_port: int = Field(
        14580, ge=0, le=_ROOM, description="... from local port this + m (PX4; 0: ephemeral)."
    )
    gcs_port: int = Field(
        14550, ge=1, le=65535, description="Every vehicle's ground-station link goes here (PX4)."
    )
    gcs_local_base_port: int = Field(
        18570, ge=0, le=_ROOM, description="... from local port this + m (PX4; 0: ephemeral)."
    )
