"""The MAVLink mission protocol of the simulated vehicle: no mission support, an empty plan.

MISSION_REQUEST_LIST is answered with a count of 0; an upload of 0 items and MISSION_CLEAR_ALL
are ACCEPTED, an upload of any item is UNSUPPORTED, and a request for an item is an
INVALID_SEQUENCE (there is none). Every answer carries the request's mission_type.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.ports import Address

if TYPE_CHECKING:
    from sim.autopilot.link import VehicleLink


def on_mission_request_list(link: VehicleLink, msg: Any, addr: Address) -> None:
    """MISSION_REQUEST_LIST: MISSION_COUNT 0."""
    link.send(
        mavlink2.MAVLink_mission_count_message(
            msg.get_srcSystem(), msg.get_srcComponent(), 0, getattr(msg, "mission_type", 0)
        ),
        addr,
    )


def _mission_ack(link: VehicleLink, msg: Any, addr: Address, result: int) -> None:
    link.send(
        mavlink2.MAVLink_mission_ack_message(
            msg.get_srcSystem(), msg.get_srcComponent(), result, getattr(msg, "mission_type", 0)
        ),
        addr,
    )


def on_mission_count(link: VehicleLink, msg: Any, addr: Address) -> None:
    """MISSION_COUNT (an upload): ACCEPTED for 0 items, UNSUPPORTED otherwise."""
    ok = int(msg.count) == 0
    _mission_ack(
        link, msg, addr, mavlink2.MAV_MISSION_ACCEPTED if ok else mavlink2.MAV_MISSION_UNSUPPORTED
    )


def on_mission_clear_all(link: VehicleLink, msg: Any, addr: Address) -> None:
    """MISSION_CLEAR_ALL: ACCEPTED."""
    _mission_ack(link, msg, addr, mavlink2.MAV_MISSION_ACCEPTED)


def on_mission_request_item(link: VehicleLink, msg: Any, addr: Address) -> None:
    """MISSION_REQUEST_INT / MISSION_REQUEST: INVALID_SEQUENCE (the plan is empty)."""
    _mission_ack(link, msg, addr, mavlink2.MAV_MISSION_INVALID_SEQUENCE)
