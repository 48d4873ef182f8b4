"""A serial cable made of two pseudo-terminals, for the serial-link tests.

`PtyCable()` opens two pty pairs (`os.openpty()`) and relays bytes between their master ends in a
thread, so that what one program writes to the device `a` (a /dev/pts/N path) comes out of the
device `b`, and back: each side opens its own real tty device, as two programs at the two ends
of a null-modem cable or a pair of telemetry radios would (`socat pty,raw pty,raw` does the
same; it is not installed here). The slave ends are put in raw mode at once (no echo, no line
discipline) and held open by the cable, so the devices exist before either program opens them.
`bytes_relayed` counts what crossed, both ways.
"""

from __future__ import annotations

import os
import select
import threading
import tty


class PtyCable:
    """Two pty devices `a` and `b` joined by a relay thread (module docstring). Use as a context
    manager, or call `close()`."""

    def __init__(self) -> None:
        self._m1, self._s1 = os.openpty()
        self._m2, self._s2 = os.openpty()
        for fd in (self._s1, self._s2):
            tty.setraw(fd)
        for fd in (self._m1, self._m2):
            os.set_blocking(fd, False)
        self.a = os.ttyname(self._s1)
        self.b = os.ttyname(self._s2)
        self.bytes_relayed = 0
        self._stop_r, self._stop_w = os.pipe()
        self._thread = threading.Thread(target=self._relay, name="pty-cable", daemon=True)
        self._thread.start()

    def _relay(self) -> None:
        other = {self._m1: self._m2, self._m2: self._m1}
        while True:
            ready, _, _ = select.select([self._m1, self._m2, self._stop_r], [], [])
            if self._stop_r in ready:
                return
            for fd in ready:
                try:
                    data = os.read(fd, 65536)
                except (BlockingIOError, OSError):  # EIO: nobody has the slave open now
                    continue
                if not self._write_all(other[fd], data):
                    return
                self.bytes_relayed += len(data)

    def _write_all(self, fd: int, data: bytes) -> bool:
        """Write `data` to `fd`, waiting while the far end's buffer is full (nobody reading it,
        like a cable) but not past `close()`; False when closed meanwhile."""
        view = memoryview(data)
        while view:
            _, writable, _ = select.select([self._stop_r], [fd], [])
            if not writable:
                return False
            try:
                view = view[os.write(fd, view) :]
            except BlockingIOError:
                continue
            except OSError:
                return True  # the far end went away: the bytes are lost, as on a cable
        return True

    def close(self) -> None:
        os.write(self._stop_w, b"x")
        self._thread.join(timeout=5.0)
        for fd in (self._m1, self._s1, self._m2, self._s2, self._stop_r, self._stop_w):
            os.close(fd)

    def __enter__(self) -> PtyCable:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
