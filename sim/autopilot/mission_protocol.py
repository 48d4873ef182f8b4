"""The MAVLink mission protocol of the simulated vehicle (https://mavlink.io/en/services/mission.html).

- Upload: MISSION_COUNT -> MISSION_REQUEST_INT (seq 0) -> MISSION_ITEM_INT (or MISSION_ITEM) ...
  -> MISSION_ACK. Every item is checked (`mission_plan.check_item`); the first one the vehicle
  does not fly ends the upload with a MISSION_ACK naming the fault (MAV_MISSION_UNSUPPORTED,
  UNSUPPORTED_FRAME, INVALID_PARAMn) and the previous plan stays, as PX4 keeps it. A count of 0
  clears the plan; more than `MAX_ITEMS` is NO_SPACE. A new MISSION_COUNT restarts the upload.
  An item out of order is answered by requesting the expected one again; an unanswered request
  is sent again after RETRY_S (0.25 s of wall time) and the upload given up after TIMEOUT_S (5 s)
  without an item, as PX4 does (counted `mission_upload_timeout`).
- Download: MISSION_REQUEST_LIST -> MISSION_COUNT, MISSION_REQUEST_INT (MISSION_REQUEST) ->
  MISSION_ITEM_INT (MISSION_ITEM); the client's closing MISSION_ACK is taken silently. A request
  out of range is MAV_MISSION_INVALID_SEQUENCE.
- MISSION_CLEAR_ALL (ACCEPTED; a vehicle flying the plan holds), MISSION_SET_CURRENT (the
  vehicle answers with MISSION_CURRENT; out of range: a STATUSTEXT, as the protocol asks).
- Fences and rally points (mission_type 1, 2) are not simulated: an empty one is accepted and
  listed, a non-empty upload is MAV_MISSION_UNSUPPORTED.

MISSION_CURRENT (streamed at 1 Hz and sent on each change) and MISSION_ITEM_REACHED come from
the flight side (`mission_flight.MissionRunner.events`, sent by the endpoint). Every answer
carries the request's mission_type.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from isac_mission.mavwire.ports import Address
from sim.autopilot.mission_plan import MAX_ITEMS, MissionItem, check_item
from sim.autopilot.params import Reject

if TYPE_CHECKING:
    from sim.autopilot.flight import FlightLogic
    from sim.autopilot.link import VehicleLink

logger = logging.getLogger(__name__)

MISSION = int(mavlink2.MAV_MISSION_TYPE_MISSION)


RETRY_S = 0.25
"""Wall seconds before an unanswered MISSION_REQUEST_INT is sent again (PX4's
MAVLINK_MISSION_RETRY_TIMEOUT_DEFAULT)."""
TIMEOUT_S = 5.0
"""Wall seconds without an item before the upload is given up (PX4's
MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT)."""


@dataclass
class _Upload:
    """An upload in progress from `peer` (client `target`, on `link`); wall times, s."""

    peer: Address
    target: tuple[int, int]
    link: VehicleLink
    count: int
    last_item_wall_s: float
    last_request_wall_s: float
    items: list[MissionItem] = field(default_factory=list)


def _kind(msg: Any) -> int:
    return int(getattr(msg, "mission_type", MISSION))


class MissionProtocol:
    """The mission protocol of one vehicle (handlers take (link, message, sender))."""

    def __init__(self, flight: FlightLogic, reject: Reject, wall_s: Callable[[], float]) -> None:
        self._flight = flight
        self._reject = reject
        self._wall_s = wall_s
        self._upload: _Upload | None = None

    def tick(self) -> None:
        """Re-request the awaited item after RETRY_S; give the upload up after TIMEOUT_S."""
        up = self._upload
        if up is None:
            return
        now = self._wall_s()
        if now - up.last_item_wall_s > TIMEOUT_S:
            self._upload = None
            self._reject("mission_upload_timeout", f"item {len(up.items)} from {up.peer}")
            return
        if now - up.last_request_wall_s > RETRY_S:
            self._send_request(up, len(up.items))

    def _ack(self, link: VehicleLink, msg: Any, addr: Address, result: int) -> None:
        link.send(
            mavlink2.MAVLink_mission_ack_message(
                msg.get_srcSystem(), msg.get_srcComponent(), result, _kind(msg)
            ),
            addr,
        )

    def _send_request(self, up: _Upload, seq: int) -> None:
        up.last_request_wall_s = self._wall_s()
        up.link.send(
            mavlink2.MAVLink_mission_request_int_message(*up.target, seq, MISSION), up.peer
        )

    def on_count(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """MISSION_COUNT: an upload of `count` items begins (0: clear)."""
        count = int(msg.count)
        if _kind(msg) != MISSION:
            result = (
                mavlink2.MAV_MISSION_ACCEPTED if count == 0 else mavlink2.MAV_MISSION_UNSUPPORTED
            )
            self._ack(link, msg, addr, result)
            return
        self._upload = None
        if count == 0:
            self._set_plan([])
            self._ack(link, msg, addr, mavlink2.MAV_MISSION_ACCEPTED)
        elif count > MAX_ITEMS:
            self._reject("mission_too_long", f"{count} items from {addr}")
            self._ack(link, msg, addr, mavlink2.MAV_MISSION_NO_SPACE)
        else:
            now = self._wall_s()
            target = (msg.get_srcSystem(), msg.get_srcComponent())
            self._upload = _Upload(addr, target, link, count, now, now)
            self._send_request(self._upload, 0)

    def on_item(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """MISSION_ITEM_INT or MISSION_ITEM of the upload in progress."""
        up = self._upload
        if up is None or up.peer != addr or _kind(msg) != MISSION:
            self._reject("mission_item_unexpected", f"item {msg.seq} from {addr}")
            return
        expected = len(up.items)
        if int(msg.seq) != expected:
            self._send_request(up, expected)
            return
        up.last_item_wall_s = self._wall_s()
        item = MissionItem.from_message(msg)
        result = check_item(item)
        if result != mavlink2.MAV_MISSION_ACCEPTED:
            self._upload = None
            self._reject("mission_item_refused", f"{item} from {addr}: result {result}")
            self._ack(link, msg, addr, result)
            return
        up.items.append(item)
        if len(up.items) < up.count:
            self._send_request(up, len(up.items))
            return
        self._upload = None
        self._set_plan(up.items)
        logger.info("vehicle %d: mission of %d items uploaded", self._flight.system_id, up.count)
        self._ack(link, msg, addr, mavlink2.MAV_MISSION_ACCEPTED)

    def _set_plan(self, items: list[MissionItem]) -> None:
        f = self._flight
        f.mission.set_plan(items)
        if f.mode is FlightMode.MISSION:
            # A new plan in flight starts from its first item; no plan: hold.
            if items:
                f.set_mode(FlightMode.MISSION, "new mission")
            else:
                f.set_mode(FlightMode.HOLD, "mission cleared")

    def on_request_list(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """MISSION_REQUEST_LIST: MISSION_COUNT of the plan (0 for fences and rally points)."""
        n = len(self._flight.mission.items) if _kind(msg) == MISSION else 0
        link.send(
            mavlink2.MAVLink_mission_count_message(
                msg.get_srcSystem(), msg.get_srcComponent(), n, _kind(msg)
            ),
            addr,
        )

    def on_request_item(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """MISSION_REQUEST_INT (-> MISSION_ITEM_INT) / MISSION_REQUEST (-> MISSION_ITEM)."""
        mission = self._flight.mission
        seq = int(msg.seq)
        if _kind(msg) != MISSION or not 0 <= seq < len(mission.items):
            self._ack(link, msg, addr, mavlink2.MAV_MISSION_INVALID_SEQUENCE)
            return
        item = mission.items[seq]
        as_int = msg.get_type() == "MISSION_REQUEST_INT"
        target = (msg.get_srcSystem(), msg.get_srcComponent())
        link.send(item.to_message(target, seq == mission.current, as_int), addr)

    def on_ack(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """MISSION_ACK from a client (the end of a download): nothing to do."""
        logger.debug("vehicle %d: mission ack %d from %s", self._flight.system_id, msg.type, addr)

    def on_clear_all(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """MISSION_CLEAR_ALL: ACCEPTED (the plan is gone; a vehicle flying it holds)."""
        if _kind(msg) == MISSION:
            self._upload = None
            self._set_plan([])
        self._ack(link, msg, addr, mavlink2.MAV_MISSION_ACCEPTED)

    def on_set_current(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """MISSION_SET_CURRENT: the item to fly next (answered by MISSION_CURRENT)."""
        f = self._flight
        seq = int(msg.seq)
        if 0 <= seq < len(f.mission.items):
            f.mission.set_current(seq)
            if f.mode is FlightMode.MISSION:
                f.set_mode(FlightMode.MISSION, f"mission item {seq}")
        else:
            self._reject("mission_bad_current", f"seq {seq} from {addr}")
            f.say(mavlink2.MAV_SEVERITY_WARNING, f"Mission: no item {seq}")
