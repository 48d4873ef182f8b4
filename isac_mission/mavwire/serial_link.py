"""MAVLink over a serial device (a telemetry radio, a USB autopilot, a pseudo-terminal), and the
link URLs that choose between serial and UDP.

A link URL names one vehicle's link (`parse_link_url`):

- `udpin:127.0.0.1:PORT`: listen on UDP PORT and answer the vehicle where it speaks from (the
  service's default, `udpin:127.0.0.1:(14540 + m)`, as MAVSDK's `udpin://`); only 127.0.0.1;
- `serial:DEVICE[:BAUD]`: the serial device DEVICE (e.g. `serial:/dev/ttyUSB0:57600`,
  `serial:/dev/pts/5`), raw 8N1 at BAUD (default 57600).

`SerialTransport` makes a serial device look like a datagram transport to an
`asyncio.DatagramProtocol` (the service's `MavlinkLink`, the simulated vehicle's `VehicleLink`):
pyserial opens and configures the device (raw mode, the baud rate), the event loop watches its
file descriptor, and `PacketFramer` cuts the byte stream into MAVLink packets by their length
fields, each handed to `datagram_received(packet, (device, baud))`. The link's datagram parser
then checks CRC and signature as for UDP; bytes between packets reach it as one chunk and are
counted as `garbage`. `sendto(packet, addr)` writes to the device (addr ignored); a device whose
output buffer is full (nobody reading, a slow radio) drops the rest of the packet, counted in
`dropped_bytes`, as a radio would: the event loop never blocks on the device. A device that goes
away (unplugged, hung up) is opened again by its path every 0.5 s until it is back.

`open_link(url, ...)` is the service's link for a URL: a `MavlinkLink` (UDP) or a
`SerialMavlinkLink` (serial).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final, Literal

import serial  # pyserial

from isac_mission.errors import LinkError
from isac_mission.mavwire.link import MavlinkLink
from isac_mission.mavwire.ports import LOOPBACK

log = logging.getLogger(__name__)

DEFAULT_BAUD: Final = 57600
"""The usual telemetry-radio rate (SiK radios, PX4's TELEM1 default)."""
_STX_V2: Final = 0xFD
_STX_V1: Final = 0xFE
_READ_SIZE: Final = 4096


@dataclass(frozen=True)
class LinkUrl:
    """A parsed link URL: `kind` "udpin" (host, port) or "serial" (device, baud)."""

    kind: Literal["udpin", "serial"]
    host: str = LOOPBACK
    port: int = 0
    device: str = ""
    baud: int = DEFAULT_BAUD

    def __str__(self) -> str:
        if self.kind == "udpin":
            return f"udpin:{self.host}:{self.port}"
        return f"serial:{self.device}:{self.baud}"


def parse_link_url(url: str) -> LinkUrl:
    """`udpin:127.0.0.1:PORT` or `serial:DEVICE[:BAUD]` (module docstring); ValueError naming
    the URL and what is wrong with it."""
    scheme, _, rest = url.partition(":")
    if scheme == "udpin":
        host, _, port_text = rest.rpartition(":")
        if host != LOOPBACK:
            raise ValueError(f"link {url!r}: udpin listens on {LOOPBACK} only (got {host!r})")
        if not port_text.isdigit() or not 0 < int(port_text) <= 65535:
            raise ValueError(f"link {url!r}: port must be 1..65535 (got {port_text!r})")
        return LinkUrl("udpin", host=host, port=int(port_text))
    if scheme == "serial":
        device, baud = rest, DEFAULT_BAUD
        head, _, tail = rest.rpartition(":")
        if head and tail.isdigit():
            device, baud = head, int(tail)
        if not device.startswith("/"):
            raise ValueError(f"link {url!r}: expected serial:/path/to/device[:BAUD]")
        if baud <= 0:
            raise ValueError(f"link {url!r}: baud must be > 0 (got {baud})")
        return LinkUrl("serial", device=device, baud=baud)
    raise ValueError(
        f"link {url!r}: expected udpin:127.0.0.1:PORT or serial:DEVICE[:BAUD] "
        f"(e.g. serial:/dev/ttyUSB0:57600)"
    )


def parse_vehicle_links(specs: Sequence[str], n_vehicles: int) -> dict[int, str]:
    """`M=URL` specs (`--vehicle-link`) as {vehicle index: link URL}; ValueError naming the bad
    spec (a bad URL, a vehicle outside 0..n_vehicles - 1, a vehicle given twice)."""
    links: dict[int, str] = {}
    for spec in specs:
        m_text, sep, url = spec.partition("=")
        if not sep or not m_text.isdigit():
            raise ValueError(f"vehicle link {spec!r}: expected M=URL, e.g. 1=serial:/dev/ttyUSB0")
        m = int(m_text)
        if m >= n_vehicles or m in links:
            raise ValueError(f"vehicle link {spec!r}: no vehicle {m} (M = {n_vehicles}), or twice")
        parse_link_url(url)
        links[m] = url
    return links


class PacketFramer:
    """Cuts a MAVLink byte stream into packets by their headers (no CRC check: the parser does).

    MAVLink 2: 0xFD, payload length, incompat flags (bit 0: signed, 13 more bytes), ... : 12 +
    length (+ 13) bytes. MAVLink 1: 0xFE, length: 8 + length bytes. Bytes before a start marker
    come out as one chunk of their own (the parser calls them garbage).
    """

    def __init__(self) -> None:
        self._buf = bytearray()

    @property
    def pending(self) -> int:
        """Bytes held: the start of a packet not yet complete."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[bytes]:
        """The complete packets (and garbage chunks) that `data` finishes, in order."""
        self._buf += data
        out: list[bytes] = []
        buf = self._buf
        while buf:
            starts = [i for i in (buf.find(_STX_V2), buf.find(_STX_V1)) if i >= 0]
            if not starts:
                out.append(bytes(buf))
                buf.clear()
                break
            start = min(starts)
            if start > 0:
                out.append(bytes(buf[:start]))
                del buf[:start]
            if buf[0] == _STX_V2:
                if len(buf) < 3:
                    break
                total = 12 + buf[1] + (13 if buf[2] & 0x01 else 0)
            else:
                if len(buf) < 2:
                    break
                total = 8 + buf[1]
            if len(buf) < total:
                break
            out.append(bytes(buf[:total]))
            del buf[:total]
        return out


class SerialTransport(asyncio.DatagramTransport):
    """A serial device as a datagram transport for `protocol` (module docstring).

    Opens `device` at `baud` (OSError if it cannot), calls `protocol.connection_made(self)`, and
    from then on `protocol.datagram_received(packet, (device, baud))` for every packet read.
    When the device goes away (a read fails or hits end of file: unplugged, the other end of a
    pty closed) the transport drops what is sent (`dropped_bytes`) and tries to open the same
    path again every `reopen_s` wall seconds (a radio plugged back in, a udev symlink pointing
    at the new device), counting `reopens`; the protocol sees no interruption but silence.
    Must be created on the event loop that reads it.
    """

    def __init__(
        self, protocol: asyncio.DatagramProtocol, device: str, baud: int, reopen_s: float = 0.5
    ) -> None:
        super().__init__()
        self._loop = asyncio.get_running_loop()
        self._protocol = protocol
        self.device, self.baud, self.reopen_s = device, baud, reopen_s
        self._framer = PacketFramer()
        self._closing = False
        self._serial: Any = None
        self._fd = -1
        self._reopen: asyncio.Task[None] | None = None
        self.dropped_bytes = 0
        """Bytes not written: the device's output buffer was full, or the device was gone."""
        self.reopens = 0
        """Times the device was opened again after it went away."""
        self._open_device()
        protocol.connection_made(self)

    def _open_device(self) -> None:
        try:
            self._serial = serial.Serial(self.device, baudrate=self.baud, timeout=0, exclusive=True)
        except (serial.SerialException, ValueError) as err:
            raise OSError(f"serial {self.device}: {err}") from err
        self._fd = self._serial.fileno()
        os.set_blocking(self._fd, False)
        self._framer = PacketFramer()
        self._loop.add_reader(self._fd, self._on_readable)

    def _drop_device(self) -> None:
        """Stop reading and close the device (idempotent)."""
        if self._fd >= 0:
            with contextlib.suppress(ValueError, OSError):
                self._loop.remove_reader(self._fd)
            self._fd = -1
        if self._serial is not None:
            with contextlib.suppress(OSError, serial.SerialException):
                self._serial.close()
            self._serial = None

    def _on_readable(self) -> None:
        try:
            data = os.read(self._fd, _READ_SIZE)
        except BlockingIOError:
            return
        except OSError as err:  # EIO: the other end hung up, or the device is unplugged
            self._lost(str(err))
            return
        if not data:  # end of file on a tty: hung up
            self._lost("end of file")
            return
        addr = (self.device, self.baud)
        for packet in self._framer.feed(data):
            self._protocol.datagram_received(packet, addr)

    def _lost(self, why: str) -> None:
        log.warning("serial %s: lost (%s); reopening every %g s", self.device, why, self.reopen_s)
        self._drop_device()
        if self._reopen is None and not self._closing:
            self._reopen = self._loop.create_task(self._reopen_loop())

    async def _reopen_loop(self) -> None:
        while not self._closing:
            await asyncio.sleep(self.reopen_s)
            try:
                self._open_device()
            except OSError:
                continue
            self.reopens += 1
            log.info("serial %s: open again", self.device)
            break
        self._reopen = None

    # asyncio.DatagramTransport
    def sendto(self, data: Any, addr: Any = None) -> None:
        """Write one packet to the device (addr ignored); drop what does not fit."""
        if self._closing:
            return
        buf = bytes(data)
        written = 0
        if self._fd >= 0:
            try:
                written = os.write(self._fd, buf)
            except BlockingIOError:
                pass
            except OSError as err:
                log.debug("serial %s: write failed: %s", self.device, err)
        if written < len(buf):
            self.dropped_bytes += len(buf) - written

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        """`sockname` / `peername`: (device, baud), as a UDP transport's (host, port)."""
        if name in ("sockname", "peername"):
            return (self.device, self.baud)
        return default

    def is_closing(self) -> bool:
        return self._closing

    def close(self) -> None:
        if self._closing:
            return
        self._closing = True
        if self._reopen is not None:
            self._reopen.cancel()
            self._reopen = None
        self._drop_device()
        self._loop.call_soon(self._protocol.connection_lost, None)

    def abort(self) -> None:
        self.close()


class SerialMavlinkLink(MavlinkLink):
    """The service's `MavlinkLink` over a serial device instead of a UDP port.

    Args:
        device, baud: The serial device and its rate.
        **kwargs: `MavlinkLink`'s keyword arguments (system_id, clock, signing, name, ...).
    """

    def __init__(self, device: str, baud: int = DEFAULT_BAUD, **kwargs: Any) -> None:
        kwargs.setdefault("name", f"serial:{device}")
        super().__init__(0, **kwargs)
        self.device, self.baud = device, baud

    async def open(self) -> None:
        """Open the device (LinkError naming it if it cannot be opened)."""
        if self.is_open:
            return
        try:
            SerialTransport(self, self.device, self.baud)
        except (OSError, ValueError) as err:
            raise LinkError(f"{self.name}: cannot open {self.device}: {err}") from err
        log.info("%s: open at %d baud", self.name, self.baud)


def open_link(url: str, **kwargs: Any) -> MavlinkLink:
    """The service's link for a link URL (not yet open): `MavlinkLink(port)` for `udpin:`,
    `SerialMavlinkLink(device, baud)` for `serial:`; ValueError for a bad URL."""
    parsed = parse_link_url(url)
    if parsed.kind == "udpin":
        return MavlinkLink(parsed.port, **kwargs)
    return SerialMavlinkLink(parsed.device, parsed.baud, **kwargs)
