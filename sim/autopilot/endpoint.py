"""`Autopilot`: one simulated PX4-like multirotor with its MAVLink 2 endpoint on 127.0.0.1.

One `Autopilot` is one vehicle: the flight logic (`flight`) around the kinematic core in
`sim/vehicle.py`, and two UDP MAVLink links (`link`) as PX4 SITL has them:

- the offboard link binds `bind_port` (default 14580 + index) and sends to `offboard_port`
  (default 14540 + index) where the offboard client listens (`udpin://127.0.0.1:14540` for
  MAVSDK, the service's bridge);
- the GCS link binds `gcs_bind_port` (default 18570 + index) and sends to `gcs_port` (default
  14550, the same for every vehicle) for the ground stations: one QGroundControl or MAVProxy
  on 14550 sees the whole fleet, told apart by system id;
- with `serial_device`, a third link on that serial device (a telemetry radio's, or one end of a
  pseudo-terminal pair), framed by `isac_mission.mavwire.serial_link.SerialTransport`.

Both links stream telemetry (`telemetry`), accept every command (`commands`, `params`,
`mission_protocol`), and also answer whoever speaks to them (the sender's address joins the link's
peers). Vehicle index m is MAVLink system m + 1, component 1.

Time: everything runs on simulation time. The world's clock calls `step(now_s, dt_s)` at the
physics rate; `step` integrates the vehicle, checks the timeouts against `now_s` and sends the
telemetry that is due. Incoming messages are stamped with the latest `now_s`. A setpoint stream
therefore has to be faster than `offboard_min_rate_hz` in simulation time (at speed s: s times
that in wall time). Only a keep-alive heartbeat (`heartbeat_keepalive_wall_s`) runs on the wall
clock, so links stay up while the clock is held or slow.

Bad input is counted per reason in `rejected` (and logged): what the datagram parser refuses
(`isac_mission.mavwire.parsing`: garbage bytes, bad CRC, unknown message ids, truncated packets,
...), non-finite or unsupported setpoints (dropped), setpoints out of the area or below the
minimum altitude (clamped), bad parameter values, commands with a NaN, infinite or absurd
integer parameter (answered DENIED), and handler exceptions. Benign drops (messages for another
system or component, message types this vehicle does not handle) are counted in `ignored`.
Nothing a client sends stops the vehicle from flying.

MAVLink 2 signing (`AutopilotSettings.signing`, a key): both links sign everything they send and
drop every packet without a valid signature, counted in `rejected` as `unsigned`,
`bad_signature` or `replayed` (see isac_mission/mavwire/signing.py); the vehicle neither obeys
nor answers such a packet, and its sender does not become a peer. Off by default, as in PX4 SITL.

Frames: local NED (north, east, down) around the scenario-plane point `local_origin_xy_m` on the
ground, GPS positions from `geo_origin` by a flat-earth conversion (`isac_mission.frames`), so
all vehicles of a scenario agree on global positions whatever their local origins.

Threading: `open`, `close` and `step` must run on the event loop that owns the sockets.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import math
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from isac_mission.mavwire.parsing import Rejection
from isac_mission.mavwire.ports import AUTOPILOT_COMPONENT_ID, LOOPBACK, Address
from isac_mission.mavwire.serial_link import SerialTransport
from sim.autopilot.commands import CommandHandler
from sim.autopilot.flight import FlightLogic
from sim.autopilot.link import VehicleLink
from sim.autopilot.mission_plan import MissionItem
from sim.autopilot.mission_protocol import MissionProtocol
from sim.autopilot.params import ParamProtocol, make_params
from sim.autopilot.settings import AutopilotSettings
from sim.autopilot.state import AutopilotState
from sim.autopilot.telemetry import Telemetry, default_intervals
from sim.impaired_io import DelayLine

logger = logging.getLogger(__name__)

Handler = Callable[[VehicleLink, Any, Address], None]
"""Handles one message: (the link it came on, the message, its sender)."""


def _same(link: VehicleLink) -> VehicleLink:
    """Protocol factory for `create_datagram_endpoint` (the link is its own protocol)."""
    return link


class Autopilot:
    """One simulated PX4 multirotor: flight modes, failsafes and a MAVLink 2 endpoint.

    Usage: `ap = Autopilot(settings); await ap.open(); clock.add_tick_callback(ap.step); ...;
    await ap.close()` (or `async with Autopilot(settings) as ap:`).
    """

    def __init__(self, settings: AutopilotSettings) -> None:
        self.settings = settings
        self.rejected: Counter[str] = Counter()
        """Bad input by reason (dropped or clamped)."""
        self.ignored: Counter[str] = Counter()
        """Benign drops by reason (other system/component, unhandled message types)."""
        self._sysid = settings.system_id
        self._silence_from_s = self._silence_until_s = math.inf
        self._links: list[VehicleLink] = []
        self._keepalive: asyncio.Task[None] | None = None
        self._warned_types: set[str] = set()
        self._statustext_id = 0
        self._params = make_params(settings)
        self._flight = FlightLogic(settings, self._params, self._statustext)
        self._telemetry = Telemetry(self._flight)
        commands = CommandHandler(self._flight, self._telemetry, self._reject)
        params = ParamProtocol(self._params, self._reject, self._flight.apply_param, self._sysid)
        mission = MissionProtocol(self._flight, self._reject, time.monotonic)
        self._mission = mission
        self._handlers: dict[str, Handler] = {
            "HEARTBEAT": self._on_heartbeat,
            "COMMAND_LONG": commands.on_command_long,
            "COMMAND_INT": commands.on_command_int,
            "SET_MODE": commands.on_set_mode,
            "SET_POSITION_TARGET_LOCAL_NED": commands.on_position_target,
            "PARAM_REQUEST_LIST": params.on_request_list,
            "PARAM_REQUEST_READ": params.on_request_read,
            "PARAM_SET": params.on_set,
            "MISSION_REQUEST_LIST": mission.on_request_list,
            "MISSION_COUNT": mission.on_count,
            "MISSION_ITEM_INT": mission.on_item,
            "MISSION_ITEM": mission.on_item,
            "MISSION_CLEAR_ALL": mission.on_clear_all,
            "MISSION_REQUEST_INT": mission.on_request_item,
            "MISSION_REQUEST": mission.on_request_item,
            "MISSION_SET_CURRENT": mission.on_set_current,
            "MISSION_ACK": mission.on_ack,
            "PING": commands.on_ping,
        }

    # -- public API --------------------------------------------------------------------------

    @property
    def system_id(self) -> int:
        """MAVLink system id (index + 1)."""
        return self._sysid

    @property
    def state(self) -> AutopilotState:
        """The latest snapshot (replaced after every step and every state change)."""
        return self._flight.state

    @property
    def mode(self) -> FlightMode:
        """Current flight mode."""
        return self._flight.mode

    @property
    def armed(self) -> bool:
        """True when the motors are armed."""
        return self._flight.armed

    @property
    def landed(self) -> bool:
        """True when the land detector says the vehicle is on the ground."""
        return self._flight.landed

    @property
    def mission_items(self) -> tuple[MissionItem, ...]:
        """The uploaded mission plan (empty without one)."""
        return tuple(self._flight.mission.items)

    @property
    def signatures_ok(self) -> int:
        """Packets (both links) whose signature was checked and accepted; 0 without signing."""
        return sum(int(link.encoder.signing.goodsig_count) for link in self._links)

    @property
    def offboard_address(self) -> Address:
        """Local (host, port) of the offboard link; valid after `open()`."""
        return self._local_address(0)

    @property
    def gcs_address(self) -> Address:
        """Local (host, port) of the GCS link; valid after `open()`."""
        return self._local_address(1)

    def param(self, name: str) -> float:
        """Current value of a parameter of the simulated param table (KeyError if unknown)."""
        return self._params[name].value

    async def open(self) -> None:
        """Bind both links on 127.0.0.1 and start the wall-clock heartbeat keep-alive."""
        if self._links:
            return
        loop = asyncio.get_running_loop()
        s = self.settings
        serial = () if s.serial_device is None else (("serial", 0, 0),)
        for name, bind, dest in (
            ("offboard", s.offboard_local_port, s.offboard_dest_port),
            ("gcs", s.gcs_local_port, s.gcs_dest_port),
            *serial,
        ):
            peer = (LOOPBACK, dest) if name != "serial" else (str(s.serial_device), s.serial_baud)
            link = VehicleLink(
                self._sysid, name, peer, s.signing, self._on_datagram, lambda: self.radio_silent
            )
            try:
                if name == "serial":  # a telemetry radio's device (mavwire/serial_link.py)
                    SerialTransport(link, *peer)
                else:
                    await loop.create_datagram_endpoint(
                        functools.partial(_same, link), local_addr=(LOOPBACK, bind)
                    )
            except OSError:
                await self.close()  # do not leave the first link bound
                raise
            self._links.append(link)
            link.intervals_s = default_intervals(s)
            link.next_due_s = dict.fromkeys(link.intervals_s, self._flight.now_s)
        logger.info(
            "vehicle %d: offboard link %s:%d -> %d, gcs link %s:%d -> %d",
            self._sysid,
            *self.offboard_address,
            s.offboard_dest_port,
            *self.gcs_address,
            s.gcs_dest_port,
        )
        if s.signing is not None:
            logger.info(
                "vehicle %d: MAVLink signing on (key %s from %s, link id %d)",
                self._sysid,
                s.signing.fingerprint,
                s.signing.source,
                s.signing.link_id,
            )
        if s.heartbeat_keepalive_wall_s is not None:
            self._keepalive = asyncio.create_task(
                self._keepalive_loop(s.heartbeat_keepalive_wall_s),
                name=f"autopilot-{self._sysid}-keepalive",
            )

    def impair_links(self, make_line: Callable[[VehicleLink, str], DelayLine | None]) -> None:
        """Fault injection: each open link's uplink and downlink from `make_line(link,
        "uplink" | "downlink")` (None: that direction untouched); `close` drops what is in
        flight (sim/impaired_io.py, docs/reliability.md)."""
        for link in self._links:
            link.uplink = make_line(link, "uplink")
            link.downlink = make_line(link, "downlink")

    async def close(self) -> None:
        """Stop the keep-alive and close both sockets."""
        if self._keepalive is not None:
            self._keepalive.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._keepalive
            self._keepalive = None
        for link in self._links:
            for line in (link.uplink, link.downlink):
                if line is not None:
                    line.close()
            if link.transport is not None:
                link.transport.close()
        self._links = []

    async def __aenter__(self) -> Autopilot:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def step(self, now_s: float, dt_s: float) -> None:
        """Advance the vehicle to simulation time `now_s` (s) by `dt_s` (s) and send due telemetry.

        Meant as a `SimClock` tick callback: physics, mode logic, failsafes, then telemetry.
        """
        self._flight.step(now_s, dt_s)
        built: dict[int, Any] = {}
        for link in self._links:
            link.send_due(now_s, self._telemetry.builders, built)
        self._mission.tick()
        self._send_mission_events()

    def _send_mission_events(self) -> None:
        """MISSION_CURRENT and MISSION_ITEM_REACHED for what the mission did since last time."""
        events = self._flight.mission.events
        if not events:
            return
        for kind, seq in events:
            if kind == "reached":
                msg = mavlink2.MAVLink_mission_item_reached_message(seq)
            else:
                msg = self._telemetry.mission_current()
            for link in self._links:
                link.send(msg)
        events.clear()

    # -- radio -------------------------------------------------------------------------------

    @property
    def radio_silent(self) -> bool:
        """True inside a `silence_radio` window: nothing is sent and everything heard is lost."""
        return self._silence_from_s <= self._flight.now_s < self._silence_until_s

    def silence_radio(self, from_s: float, duration_s: float) -> None:
        """Fault injection: the vehicle's MAVLink radio (both links) is dead from simulation time
        `from_s` for `duration_s` seconds. The vehicle flies on under its own failsafes
        (offboard loss after COM_OF_LOSS_T, lost GCS after COM_DL_LOSS_T)."""
        if not (math.isfinite(from_s) and math.isfinite(duration_s) and duration_s >= 0):
            raise ValueError(
                f"radio silence needs finite from_s and duration_s >= 0, got {from_s}, {duration_s}"
            )
        self._silence_from_s, self._silence_until_s = from_s, from_s + duration_s
        logger.warning(
            "vehicle %d: radio silence from t = %.2f s for %.2f s",
            self._sysid,
            from_s,
            duration_s,
        )

    # -- receiving ---------------------------------------------------------------------------

    def _reject(self, reason: str, detail: str) -> None:
        self.rejected[reason] += 1
        n = self.rejected[reason]
        if n <= 5 or n % 100 == 0:
            logger.warning("vehicle %d: rejected (%s, #%d): %s", self._sysid, reason, n, detail)

    def _on_datagram(self, link: VehicleLink, data: bytes, addr: Address) -> None:
        if self.radio_silent:
            self.rejected["radio silence"] += 1
            return
        for item in link.parser.parse(data, addr):
            if isinstance(item, Rejection):
                self._reject(item.reason, item.detail)
            else:
                self._dispatch(link, item, addr)

    def _dispatch(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        mtype = msg.get_type()
        if msg.get_srcSystem() == self._sysid:
            self.ignored["own_system"] += 1
            return
        target_system = getattr(msg, "target_system", 0)
        if target_system not in (0, self._sysid):
            self.ignored["other_system"] += 1
            return
        if getattr(msg, "target_component", 0) not in (0, AUTOPILOT_COMPONENT_ID):
            self.ignored["other_component"] += 1
            return
        link.add_peer(addr)
        handler = self._handlers.get(mtype)
        if handler is None:
            self.ignored[f"unhandled:{mtype}"] += 1
            if mtype not in self._warned_types:
                self._warned_types.add(mtype)
                logger.info("vehicle %d: ignoring %s messages", self._sysid, mtype)
            return
        try:
            handler(link, msg, addr)
        except Exception:
            self.rejected["handler_error"] += 1
            logger.exception("vehicle %d: handler for %s failed", self._sysid, mtype)

    def _on_heartbeat(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        self._flight.client_heartbeat(link.name)

    # -- sending -----------------------------------------------------------------------------

    async def _keepalive_loop(self, period_s: float) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(period_s / 2.0)
            for link in self._links:
                if loop.time() - link.last_heartbeat_wall_s >= period_s:
                    link.send(self._telemetry.heartbeat())

    def _statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT to every peer; a text over 50 characters goes in chunks of 50 with one
        nonzero id and chunk_seq 0, 1, ... (MAVLink 2, as PX4 sends them), the last chunk
        shorter than 50 (NUL-terminated on the wire; empty when the text fills the chunks)."""
        data = text.encode("ascii", "replace")
        if len(data) <= 50:
            chunks, text_id = [data], 0
        else:
            chunks = [data[i : i + 50] for i in range(0, len(data), 50)]
            if len(chunks[-1]) == 50:
                chunks.append(b"")
            self._statustext_id = self._statustext_id % 65535 + 1
            text_id = self._statustext_id
        for seq, chunk in enumerate(chunks):
            msg = mavlink2.MAVLink_statustext_message(severity, chunk, text_id, seq)
            for link in self._links:
                link.send(msg)

    def _local_address(self, i: int) -> Address:
        if len(self._links) <= i or self._links[i].transport is None:
            raise RuntimeError("Autopilot is not open")
        return self._links[i].local_address()
