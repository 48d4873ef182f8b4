"""MavlinkLink: one vehicle's MAVLink 2 link over UDP, as the service's side of it.

The link works like MAVSDK's `udpin://127.0.0.1:14540+m`: it binds 127.0.0.1:(base + m), learns
the vehicle's address from the first packet of the vehicle's system, and replies there. It is an
`asyncio.DatagramProtocol`; each datagram goes through the one datagram parser
(`parsing.DatagramParser`, pymavlink's `parse_buffer`), and every message is dispatched to the
handlers registered for its type (a dict keyed by message type). A handler that raises is logged and counted in `errors["handler_error"]`; it never stops
the link. A message type without a handler is noted once in the log and counted in `ignored`.
Bad input is counted per reason in `errors`: the parser's rejections (`garbage`, `bad_crc`,
`bad_data`, `truncated`, `unknown_message`, `parse_error`, see `isac_mission.mavwire.parsing`), and
`foreign_address` (a packet in the vehicle's name from another address than the vehicle's:
the address is learnt from the vehicle's HEARTBEAT and moves only after the link was lost).

MAVLink 2 signing (`signing=` a `MavlinkSigningKey`, from the scenario's
`security.mavlink_signing`): every message we send is signed, with timestamps that follow the wall
clock; every packet without a valid signature is dropped and counted in `errors` as `unsigned`
(no signature, or MAVLink 1), `bad_signature` (another key, or altered) or `replayed` (our key,
but a timestamp not newer than its stream's last). pymavlink does the checks (`enable_signing`);
`_MAVLink` fixes its order so a forged packet cannot poison a stream's timestamp. Off by default:
nothing is signed and everything is accepted, as MAVSDK and PX4 SITL expect.

Vehicle state (`VehicleStatus` of `isac_mission.mavwire.status`, a snapshot taken by `status()`): local NED position and velocity
(LOCAL_POSITION_NED), heading (ATTITUDE), home altitude AMSL (GLOBAL_POSITION_INT), the PX4 mode
name decoded from HEARTBEAT.custom_mode (`px4_mode_name`), armed (HEARTBEAT base_mode), landed
state (EXTENDED_SYS_STATE), and the time of the last HEARTBEAT. Times come from the `clock`
callable given to the link (the bridge passes its simulation time, so "lost" is judged in
simulation seconds, like every other timeout of the service). The link is *lost* when nothing
from the vehicle's autopilot was heard for `lost_after_s` (or no HEARTBEAT ever): any message
counts, as a lossy radio drops 1 Hz heartbeats in a row far more often than a 20 Hz stream, but
only a HEARTBEAT (a fresh mode) ends a loss (docs/reliability.md, "Lossy, late radio links").

Outgoing messages come from the pure builder functions of `isac_mission.mavwire.builders`
(`gcs_heartbeat`, `arm_command`, `takeoff_command`, `land_command`, `set_mode_command`,
`position_target_local_ned`, ...), which return pymavlink message objects and can be checked without a socket. `MavlinkLink.command()`
sends a COMMAND_LONG and waits for its COMMAND_ACK (wall-clock timeout per attempt, with
retries that bump the `confirmation` field as the MAVLink command protocol asks); a final result
other than ACCEPTED, or no answer, raises `LinkError` naming the command and the result.
IN_PROGRESS extends the wait without resending.

Frames and units: MAV_FRAME_LOCAL_NED (north, east, down), m, m/s, rad; arrays are float64 (3,).
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections import Counter
from collections.abc import Callable
from typing import Any, cast

from isac_mission.config import MavlinkSigningKey
from isac_mission.errors import LinkError
from isac_mission.mavwire.builders import Target
from isac_mission.mavwire.commands import CommandProtocol
from isac_mission.mavwire.parsing import DatagramParser, Rejection
from isac_mission.mavwire.ports import (
    AUTOPILOT_COMPONENT_ID,
    GCS_COMPONENT_ID,
    GCS_SYSTEM_ID,
    LOOPBACK,
    Address,
)
from isac_mission.mavwire.signing import enable_signing, new_encoder, pack
from isac_mission.mavwire.status import VehicleStatus, VehicleTelemetry

log = logging.getLogger(__name__)

Handler = Callable[[Any], None]
"""Called with one parsed pymavlink message."""


class MavlinkLink(asyncio.DatagramProtocol):
    """One vehicle's MAVLink link, bound to 127.0.0.1:`port` (see the module docstring).

    Args:
        port: Local UDP port the vehicle sends to (14540 + m for PX4 SITL vehicle m).
        system_id: The vehicle's system id (m + 1); None: the first system heard.
        vehicle_component: Component whose HEARTBEAT and state we follow (1: the autopilot).
        clock: Time source for heartbeat ages and sample times, s (default: monotonic wall).
        lost_after_s: The link is lost after this long without a HEARTBEAT (clock seconds)...
        lost_min_wall_s: ... and at least this long in wall seconds.
        own_system_id / own_component_id: Our MAVLink address (a GCS by default).
        signing: MAVLink 2 signing key: sign everything we send and drop (and count in
            `errors` as "unsigned", "bad_signature" or "replayed") every packet without a
            valid signature; None (default): no signing, unsigned and signed packets accepted.
        name: For log messages.

    Use `await link.open()` (or `async with`) on the event loop that will own the socket.
    """

    def __init__(
        self,
        port: int,
        *,
        system_id: int | None = None,
        vehicle_component: int = AUTOPILOT_COMPONENT_ID,
        clock: Callable[[], float] = time.monotonic,
        lost_after_s: float = 3.0,
        lost_min_wall_s: float = 2.0,
        own_system_id: int = GCS_SYSTEM_ID,
        own_component_id: int = GCS_COMPONENT_ID,
        signing: MavlinkSigningKey | None = None,
        name: str = "",
    ) -> None:
        if not 0 <= port <= 65535:
            raise ValueError(f"port must be a UDP port, got {port}")
        if not (math.isfinite(lost_after_s) and lost_after_s > 0):
            raise ValueError(f"lost_after_s must be finite and > 0, got {lost_after_s}")
        self.port = port
        self.name = name or f"mavlink:{port}"
        self.lost_after_s = float(lost_after_s)
        self.lost_min_wall_s = float(lost_min_wall_s)
        self._clock = clock
        self._expected_system = system_id
        self._vehicle_component = vehicle_component
        self._own_system = own_system_id
        self._encoder = new_encoder(own_system_id, own_component_id)
        if signing is not None:
            enable_signing(self._encoder, signing)
            log.info(
                "%s: MAVLink signing on (key %s from %s, link id %d)",
                self.name,
                signing.fingerprint,
                signing.source,
                signing.link_id,
            )
        self._datagrams = DatagramParser(self._encoder)
        self._transport: asyncio.DatagramTransport | None = None
        self._address: Address | None = None
        self._system_id: int | None = system_id

        self.errors: Counter[str] = Counter()
        """Bad input and handler failures, by reason."""
        self.ignored: Counter[str] = Counter()
        """Benign drops: other systems/components, message types without a handler."""
        self.received: Counter[str] = Counter()
        """Messages from the vehicle, by type (dispatched or not)."""
        self.sent: Counter[str] = Counter()
        """Messages sent, by type."""
        self.handlers: dict[str, list[Handler]] = {}
        """Handlers by message type; `on()` adds one."""
        self._noted: set[str] = set()

        self._heard_s = self._heard_wall_s = -math.inf  # last message of the vehicle's autopilot
        self._vehicle = VehicleTelemetry(clock, self.name, self._count_error)
        self._commands = CommandProtocol(self.name, self.send, self.ignored)
        self._changed = asyncio.Event()

        vehicle = self._vehicle
        self.on("HEARTBEAT", self._on_heartbeat)
        self.on("LOCAL_POSITION_NED", self._from_vehicle(vehicle.on_local_position_ned))
        self.on("GLOBAL_POSITION_INT", self._from_vehicle(vehicle.on_global_position_int))
        self.on("EXTENDED_SYS_STATE", self._from_vehicle(vehicle.on_extended_sys_state))
        self.on("ATTITUDE", self._from_vehicle(vehicle.on_attitude))
        self.on("COMMAND_ACK", self._commands.on_ack)
        self.on("STATUSTEXT", self._on_statustext)

    # -- lifecycle ---------------------------------------------------------------------------

    async def open(self) -> None:
        """Bind 127.0.0.1:`port` (OSError if it is taken)."""
        if self._transport is not None:
            return
        loop = asyncio.get_running_loop()
        await loop.create_datagram_endpoint(lambda: self, local_addr=(LOOPBACK, self.port))
        log.info("%s: listening on %s:%d", self.name, LOOPBACK, self.port)

    def close(self) -> None:
        """Close the socket; a pending command fails with LinkError (idempotent)."""
        if self._transport is not None:
            self._transport.close()
            self._transport = None
        self._commands.fail_pending()

    async def __aenter__(self) -> MavlinkLink:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    @property
    def is_open(self) -> bool:
        """True between open() and close()."""
        return self._transport is not None

    @property
    def local_address(self) -> Address:
        """The bound (host, port); RuntimeError before open()."""
        if self._transport is None:
            raise RuntimeError(f"{self.name}: not open")
        host, port = self._transport.get_extra_info("sockname")[:2]
        return (str(host), int(port))

    # -- asyncio.DatagramProtocol ------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.DatagramTransport, transport)

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable after a send while the vehicle is down: normal for UDP.
        log.debug("%s: %s", self.name, exc)

    def datagram_received(self, data: bytes, addr: Address) -> None:
        """Parse one datagram and dispatch its messages (UDP keeps packets whole); count what
        the parser refuses."""
        for item in self._datagrams.parse(data, addr):
            if isinstance(item, Rejection):
                self._count_error(item.reason, item.detail)
            else:
                self.dispatch(item, addr)

    # -- dispatch ----------------------------------------------------------------------------

    def on(self, message_type: str, handler: Handler) -> None:
        """Call `handler(msg)` for every `message_type` message of the vehicle (after those
        registered before)."""
        self.handlers.setdefault(message_type, []).append(handler)

    def dispatch(self, msg: Any, addr: Address) -> None:
        """Filter, count and hand one parsed message of the dialect to its handlers."""
        mtype = str(msg.get_type())
        src = int(msg.get_srcSystem())
        if src == self._own_system:
            self.ignored["own_system"] += 1
            return
        if self._system_id is None:
            self._system_id = src
            log.info("%s: vehicle is system %d", self.name, src)
        if src != self._system_id:
            self.ignored["other_system"] += 1
            return
        if getattr(msg, "target_system", 0) not in (0, self._own_system):
            self.ignored["for_other_system"] += 1
            return
        if self._address != addr and not self._learn_address(msg, mtype, addr):
            self._count_error("foreign_address", f"{mtype} as system {src} from {addr}")
            return
        self.received[mtype] += 1
        if int(msg.get_srcComponent()) == self._vehicle_component and not self.lost:
            self._heard_s, self._heard_wall_s = self._clock(), time.monotonic()
        handlers = self.handlers.get(mtype)
        if not handlers:
            self.ignored[f"unhandled:{mtype}"] += 1
            if mtype not in self._noted:
                self._noted.add(mtype)
                log.info("%s: no handler for %s messages (ignored)", self.name, mtype)
            return
        for handler in handlers:
            try:
                handler(msg)
            except Exception:
                self.errors["handler_error"] += 1
                log.exception("%s: handler for %s failed", self.name, mtype)
        self._notify()

    def _learn_address(self, msg: Any, mtype: str, addr: Address) -> bool:
        """Whether a packet from `addr`, not the vehicle's known address, may be taken; if so the
        link now sends there. Like MAVSDK's udpin, the link learns where the vehicle is from
        what it hears, but only from a HEARTBEAT of the vehicle's own system and autopilot
        component, and only while no address is known or the vehicle has been lost (it
        restarted on another port). While the vehicle is heard, anything in its name from
        elsewhere is dropped: a sender on our port cannot take the link over."""
        if mtype != "HEARTBEAT" or int(msg.get_srcComponent()) != self._vehicle_component:
            return self._address is None  # state before the first heartbeat; no address yet
        if self._address is not None and not self.lost:
            return False
        log.info("%s: vehicle %d at %s:%d", self.name, int(msg.get_srcSystem()), *addr)
        self._address = addr
        return True

    def _count_error(self, reason: str, detail: str) -> None:
        self.errors[reason] += 1
        n = self.errors[reason]
        if n <= 5 or n % 100 == 0:
            log.warning("%s: %s (#%d): %s", self.name, reason, n, detail)

    def _notify(self) -> None:
        event, self._changed = self._changed, asyncio.Event()
        event.set()

    async def wait_change(self, timeout_s: float) -> bool:
        """Wait until the next message has been handled, at most `timeout_s` wall seconds;
        True if one was."""
        event = self._changed
        try:
            async with asyncio.timeout(timeout_s):
                await event.wait()
        except TimeoutError:
            return False
        return True

    async def wait_for(
        self, predicate: Callable[[VehicleStatus], bool], timeout_s: float, what: str
    ) -> VehicleStatus:
        """The first status satisfying `predicate`, checked after every message; LinkError
        naming `what` after `timeout_s` wall seconds."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while True:
            status = self.status()
            if predicate(status):
                return status
            remaining = deadline - loop.time()
            if remaining <= 0:
                raise LinkError(f"{self.name}: timed out after {timeout_s:g} s waiting for {what}")
            await self.wait_change(min(remaining, 0.5))

    # -- handlers ----------------------------------------------------------------------------

    def _from_vehicle_component(self, msg: Any) -> bool:
        if int(msg.get_srcComponent()) == self._vehicle_component:
            return True
        self.ignored["other_component"] += 1
        return False

    def _from_vehicle(self, handle: Handler) -> Handler:
        """`handle` for the messages of the vehicle's own component only."""

        def handler(msg: Any) -> None:
            if self._from_vehicle_component(msg):
                handle(msg)

        return handler

    def _on_heartbeat(self, msg: Any) -> None:
        if not self._from_vehicle_component(msg):
            return
        was_lost = self.lost
        self._vehicle.on_heartbeat(msg)
        if was_lost:
            log.info("%s: heartbeat from vehicle %s", self.name, self._system_id)

    def _on_statustext(self, msg: Any) -> None:
        text = msg.text
        if isinstance(text, bytes):
            text = text.split(b"\x00", 1)[0].decode("utf-8", errors="replace")
        log.info("%s: vehicle says (severity %d): %s", self.name, int(msg.severity), text)

    # -- state -------------------------------------------------------------------------------

    @property
    def lost(self) -> bool:
        """Nothing from the vehicle for `lost_after_s` clock and `lost_min_wall_s` wall seconds
        (or no HEARTBEAT yet); the wall floor keeps CPU stalls of a fast simulation from it."""
        hb = self._vehicle.heartbeat_s
        if hb is None:
            return True
        wall_s = max(self._vehicle.heartbeat_wall_s, self._heard_wall_s)
        return self._clock() - max(hb, self._heard_s) > self.lost_after_s and (
            time.monotonic() - wall_s > self.lost_min_wall_s
        )

    @property
    def signatures_ok(self) -> int:
        """Packets whose signature was checked and accepted (0 when signing is off)."""
        return int(self._encoder.signing.goodsig_count)

    @property
    def target(self) -> Target:
        """The vehicle's MAVLink address (LinkError before its system id is known)."""
        if self._system_id is None:
            raise LinkError(f"{self.name}: vehicle not heard yet")
        return Target(self._system_id, self._vehicle_component)

    @property
    def vehicle_address(self) -> Address | None:
        """The vehicle's UDP address, learnt from its packets (None until heard)."""
        return self._address

    def status(self) -> VehicleStatus:
        """A snapshot of the vehicle state (see `VehicleStatus`)."""
        return self._vehicle.snapshot(self._system_id, self._address, self.lost)

    # -- sending -----------------------------------------------------------------------------

    def send(self, msg: Any) -> bool:
        """Send one message to the vehicle; False (nothing sent) before its address is known
        or when the link is closed."""
        if self._transport is None or self._transport.is_closing() or self._address is None:
            return False
        self._transport.sendto(pack(msg, self._encoder), self._address)
        self.sent[str(msg.get_type())] += 1
        return True

    async def command(self, msg: Any, *, timeout_s: float = 1.0, attempts: int = 3) -> None:
        """Send a COMMAND_LONG and wait for ACCEPTED.

        Each attempt waits `timeout_s` wall seconds for the matching COMMAND_ACK (an
        IN_PROGRESS answer restarts the wait without resending); a retry bumps `confirmation`.
        Commands are sent one at a time. Raises LinkError naming the command and the result
        when the vehicle answers anything but ACCEPTED, or when no answer came after `attempts`
        attempts (`isac_mission.mavwire.commands`).
        """
        await self._commands.run(msg, timeout_s, attempts)
