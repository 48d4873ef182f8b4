"""One UDP MAVLink link of the simulated vehicle: its socket, its peers and its telemetry streams.

The link binds 127.0.0.1 and sends to its default peer (the offboard client's or the ground
station's port); whoever speaks to it joins its peers (at most 8, the oldest dropped first) and
gets what it sends. What it receives goes to the vehicle (`on_datagram`); the vehicle parses it
with `isac_mission.mavwire.parsing`. Everything it sends is packed (and signed, with a key) by its
own encoder, whose signing state its parsers share. Fault injection: `uplink` / `downlink`, when
set (`Autopilot.impair_links`), carry what the link receives / sends through a lossy, late
channel (`sim.impaired_io.DelayLine`).
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable
from typing import Any, cast

from isac_mission.config import MavlinkSigningKey
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.parsing import DatagramParser
from isac_mission.mavwire.ports import AUTOPILOT_COMPONENT_ID, Address
from isac_mission.mavwire.signing import enable_signing, new_encoder, pack
from sim.impaired_io import DelayLine

logger = logging.getLogger(__name__)

MAX_PEERS = 8


class VehicleLink(asyncio.DatagramProtocol):
    """One MAVLink UDP link of vehicle `system_id` (its own asyncio protocol).

    Args:
        system_id: The vehicle's MAVLink system id (component 1, the autopilot).
        name: "offboard" or "gcs", for log messages.
        default_peer: Where telemetry goes before anyone spoke (and always).
        signing: Sign everything sent and refuse what is not signed with this key; None: off.
        on_datagram: Called with (this link, datagram, sender) for every datagram received.
        radio_silent: True while the vehicle's radio is dead (nothing is sent).
    """

    def __init__(
        self,
        system_id: int,
        name: str,
        default_peer: Address,
        signing: MavlinkSigningKey | None,
        on_datagram: Callable[[VehicleLink, bytes, Address], None],
        radio_silent: Callable[[], bool],
    ) -> None:
        self.system_id = system_id
        self.name = name
        self.default_peer = default_peer
        self.peers: dict[Address, None] = {default_peer: None}
        self.transport: asyncio.DatagramTransport | None = None
        self.encoder = new_encoder(system_id, AUTOPILOT_COMPONENT_ID)
        """Packs (and signs) what the link sends; its signing state is shared by the parsers."""
        if signing is not None:
            enable_signing(self.encoder, signing)
        self.parser = DatagramParser(self.encoder)
        """Parses what the link receives (`isac_mission.mavwire.parsing`)."""
        self._on_datagram = on_datagram
        self._radio_silent = radio_silent
        self.intervals_s: dict[int, float] = {}
        """Streamed message id -> period, s (simulation time)."""
        self.next_due_s: dict[int, float] = {}
        """Streamed message id -> simulation time it is next due, s."""
        self.last_heartbeat_wall_s = -math.inf
        self.uplink: DelayLine | None = None
        """Impairs what the link receives (delivers to `on_datagram`); None: untouched."""
        self.downlink: DelayLine | None = None
        """Impairs what the link sends (delivers to `sendto`); None: untouched."""

    # asyncio.DatagramProtocol
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: Address) -> None:
        if self.uplink is not None:
            self.uplink.push(data, addr)
        else:
            self.receive(data, addr)

    def receive(self, data: bytes, addr: Address) -> None:
        """Hand one datagram (as it arrives after the uplink) to the vehicle."""
        self._on_datagram(self, data, addr)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable when nobody listens at a peer: normal for UDP telemetry.
        logger.debug("vehicle %d %s link: %s", self.system_id, self.name, exc)

    # sending
    def send(self, msg: Any, to: Address | None = None) -> None:
        """Send one message to `to`, or to every peer of the link."""
        if self.transport is None or self.transport.is_closing():
            return
        if self._radio_silent():
            return
        buf = pack(msg, self.encoder)
        for addr in [to] if to is not None else list(self.peers):
            if self.downlink is not None:
                self.downlink.push(buf, addr)
            else:
                self.sendto(buf, addr)
        if msg.get_msgId() == mavlink2.MAVLINK_MSG_ID_HEARTBEAT:
            self.last_heartbeat_wall_s = asyncio.get_running_loop().time()

    def sendto(self, buf: bytes, addr: Address) -> None:
        """Put one datagram on the socket (as it leaves the downlink); dropped once closed."""
        if self.transport is not None and not self.transport.is_closing():
            self.transport.sendto(buf, addr)

    def add_peer(self, addr: Address) -> None:
        """`addr` spoke to the link: it gets what the link sends from now on."""
        if addr in self.peers:
            return
        if len(self.peers) >= MAX_PEERS:
            oldest = next(a for a in self.peers if a != self.default_peer)
            del self.peers[oldest]
        self.peers[addr] = None
        logger.info("vehicle %d %s link: new peer %s:%d", self.system_id, self.name, *addr)

    def local_address(self) -> Address:
        """The bound (host, port); RuntimeError when not open."""
        if self.transport is None:
            raise RuntimeError("Autopilot is not open")
        host, port = self.transport.get_extra_info("sockname")[:2]
        return (str(host), int(port))

    def send_due(
        self, now_s: float, builders: dict[int, Callable[[], Any]], built: dict[int, Any]
    ) -> None:
        """Send every stream due at simulation time `now_s` (s); `built` caches the messages
        built this step, shared by the links."""
        for msg_id, interval in self.intervals_s.items():
            due = self.next_due_s.get(msg_id, now_s)
            if now_s + 1e-9 < due:
                continue
            if msg_id not in built:
                built[msg_id] = builders[msg_id]()
            self.send(built[msg_id])
            due += interval
            self.next_due_s[msg_id] = due if due > now_s else now_s + interval
