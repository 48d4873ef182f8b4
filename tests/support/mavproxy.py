"""A real MAVProxy ground station for the tests: a subprocess on loopback, commands on its stdin.

MAVProxy (the `MAVProxy` package, `mavproxy.py` in the venv, 1.8.x) is the third-party client
the ground-station tests use. Two pieces:

- `MavProxy(master, outs)`: starts `mavproxy.py --master=MASTER --out=OUT ... --no-state` in
  its own empty HOME (no user start-up scripts), unbuffered, and reads its console output in a
  thread. `send("arm throttle")` types a command; `wait_for(r"regex", timeout_s)` waits for a
  console line; `set_px4_mode(sysid, FlightMode.HOLD)` switches one vehicle's PX4 mode the way
  a ground station does (COMMAND_LONG MAV_CMD_DO_SET_MODE 1, main, sub, to that system; see
  below); `close()` ends it (EOF on stdin, then SIGTERM, then SIGKILL).
- `MavlinkListener(port)`: a pymavlink `udpin:127.0.0.1:PORT` that records every HEARTBEAT by
  system id, the capture end of MAVProxy's `--out=udp:127.0.0.1:PORT` (MAVProxy forwards every
  packet it hears from its master to each `--out`). `wait_for_systems({1, 2, 3}, timeout_s)`.

Typical use (a fleet sending its ground-station links to `gcs`):

```python
with MavlinkListener() as seen, MavProxy(f"udpin:127.0.0.1:{gcs}", [seen.out]) as mp:
    seen.wait_for_systems({1, 2, 3}, timeout_s=30)   # what MAVProxy's master heard
    mp.set_px4_mode(2, FlightMode.HOLD)               # operator takes vehicle 2 (system id 2)
    mp.wait_for(r"DO_SET_MODE: ACCEPTED", timeout_s=30)
    seen.wait_for_mode(2, FlightMode.HOLD, timeout_s=30)
```

Why not MAVProxy's own `mode HOLD`: with pymavlink 2.4.50 its `mode` command hands PX4's
(base, main, sub) tuple to `set_mode` as one float and fails ("required argument is not a
float"); `long DO_SET_MODE 1 MAIN SUB` (the cmdlong module) is the same command as sent by
QGroundControl. MAVProxy addresses commands to its current target, chosen with `vehicle N`.

Everything binds and sends on 127.0.0.1. Waits are bounded by generous wall-clock timeouts.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")
from pymavlink import mavutil

from isac_mission.mavwire.modes import FlightMode, px4_main_sub, px4_mode_name
from tests.support.ports import LOOPBACK, free_udp_port

MODULES = "link,signing,wp,param,arm,mode,cmdlong,misc,output"
"""MAVProxy modules loaded (its defaults minus ftp, terrain, adsb, rally, fence, calibration...)."""


def mavproxy_path() -> Path:
    """`mavproxy.py` beside this interpreter (the venv), else on PATH; skips the test if absent."""
    here = Path(sys.executable).parent / "mavproxy.py"
    if here.is_file():
        return here
    found = shutil.which("mavproxy.py")
    if found is None:
        pytest.skip("MAVProxy is not installed (pip install mavproxy, the dev extra)")
    return Path(found)


class MavProxy:
    """A MAVProxy process on loopback (module docstring).

    Args:
        master: `--master`, e.g. `udpin:127.0.0.1:14550` (a fleet's ground-station port),
            `udpout:127.0.0.1:18570` or a serial device `/dev/pts/3,57600`.
        outs: `--out`s, e.g. `udp:127.0.0.1:14540` (MAVProxy as a router) or a listener's `out`.
        source_system: MAVProxy's own system id (255: a ground station).
        extra: More command-line options (e.g. `--cmd=...`).
        modules: Modules to load (`--default-modules`).
    """

    def __init__(
        self,
        master: str,
        outs: Sequence[str] = (),
        *,
        source_system: int = 255,
        extra: Sequence[str] = (),
        modules: str = MODULES,
    ) -> None:
        self._home = tempfile.mkdtemp(prefix="mavproxy-")
        self.argv = [
            str(mavproxy_path()),
            f"--master={master}",
            *(f"--out={out}" for out in outs),
            f"--source-system={source_system}",
            f"--default-modules={modules}",
            "--no-state",
            "--nowait",
            *extra,
        ]
        self._lines: list[str] = []
        self._cond = threading.Condition()
        self.proc = subprocess.Popen(
            self.argv,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            cwd=self._home,
            env=os.environ | {"HOME": self._home, "PYTHONUNBUFFERED": "1"},
        )
        self._reader = threading.Thread(target=self._read, name="mavproxy-out", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._cond:
                self._lines.append(line.rstrip("\n"))
                self._cond.notify_all()

    # -- console -----------------------------------------------------------------------------

    @property
    def lines(self) -> list[str]:
        """Console lines so far (a copy)."""
        with self._cond:
            return list(self._lines)

    def mark(self) -> int:
        """The number of console lines so far: `wait_for(..., since=mark)` looks only after it."""
        with self._cond:
            return len(self._lines)

    def wait_for(self, pattern: str, timeout_s: float, since: int = 0) -> re.Match[str]:
        """The first console line from line `since` on matching the regex `pattern`;
        AssertionError (with the console's tail) after `timeout_s` wall seconds or if MAVProxy
        exits first."""
        rx = re.compile(pattern)
        deadline = time.monotonic() + timeout_s
        i = since
        with self._cond:
            while True:
                while i < len(self._lines):
                    found = rx.search(self._lines[i])
                    if found is not None:
                        return found
                    i += 1
                remaining = deadline - time.monotonic()
                if remaining <= 0 or (self.proc.poll() is not None and not self._reader.is_alive()):
                    tail = "\n".join(self._lines[-30:])
                    raise AssertionError(
                        f"MAVProxy: no line matching {pattern!r} within {timeout_s} s "
                        f"(exit code {self.proc.poll()}); last lines:\n{tail}"
                    )
                self._cond.wait(min(remaining, 0.5))

    # -- commands ----------------------------------------------------------------------------

    def send(self, command: str) -> None:
        """Type one command line into MAVProxy's console (e.g. `vehicle 2`, `arm throttle`)."""
        assert self.proc.stdin is not None
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def set_px4_mode(self, system_id: int, mode: FlightMode) -> int:
        """Send PX4 mode `mode` to vehicle `system_id` (`vehicle N`, then `long DO_SET_MODE 1
        MAIN SUB`); returns the console mark before it, for `wait_for(r"DO_SET_MODE: ACCEPTED",
        since=...)`."""
        main, sub = px4_main_sub(mode.px4_custom_mode)
        mark = self.mark()
        self.send(f"vehicle {system_id}")
        self.send(f"long DO_SET_MODE 1 {main} {sub}")
        return mark

    # -- lifecycle ---------------------------------------------------------------------------

    def close(self, timeout_s: float = 10.0) -> int:
        """End MAVProxy: EOF on its stdin (it exits), then SIGTERM, then SIGKILL; its exit code."""
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.close()
            except OSError:
                pass
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.send_signal(signal.SIGTERM)
                try:
                    self.proc.wait(timeout_s)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(timeout_s)
        self._reader.join(timeout_s)
        shutil.rmtree(self._home, ignore_errors=True)
        return int(self.proc.returncode)

    def __enter__(self) -> MavProxy:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class MavlinkListener:
    """A pymavlink `udpin:127.0.0.1:PORT` that records the HEARTBEATs it hears, by system id.

    `out` is the `--out` to give MAVProxy (`udp:127.0.0.1:PORT`). A receiver thread drains the
    socket all the time. Signed packets are parsed (not checked) like any other.
    """

    def __init__(self, port: int | None = None) -> None:
        self.port = free_udp_port() if port is None else port
        self.out = f"udp:{LOOPBACK}:{self.port}"
        self.conn: Any = mavutil.mavlink_connection(
            f"udpin:{LOOPBACK}:{self.port}", source_system=254, dialect="common"
        )
        self.heartbeats: dict[int, Any] = {}
        """System id -> its latest HEARTBEAT (autopilot component 1 only)."""
        self.first_heard_s: dict[int, float] = {}
        """System id -> monotonic wall time of its first HEARTBEAT."""
        self.count = 0
        """Messages received."""
        self._cond = threading.Condition()
        self._closed = threading.Event()
        self._rx = threading.Thread(target=self._rx_loop, name="mavlink-listener", daemon=True)
        self._rx.start()

    def _rx_loop(self) -> None:
        while not self._closed.is_set():
            try:
                msg = self.conn.recv_match(blocking=True, timeout=0.2)
            except (OSError, ValueError):
                if self._closed.is_set():
                    return
                continue
            if msg is None:
                continue
            with self._cond:
                self.count += 1
                if msg.get_type() == "HEARTBEAT" and msg.get_srcComponent() == 1:
                    sysid = int(msg.get_srcSystem())
                    self.heartbeats[sysid] = msg
                    self.first_heard_s.setdefault(sysid, time.monotonic())
                    self._cond.notify_all()

    def systems(self) -> set[int]:
        """System ids heard so far."""
        with self._cond:
            return set(self.heartbeats)

    def mode(self, system_id: int) -> str | None:
        """The PX4 mode name (`px4_mode_name`: "offboard", "hold", "rtl", ...) in
        `system_id`'s latest HEARTBEAT; None before one was heard."""
        with self._cond:
            hb = self.heartbeats.get(system_id)
        return None if hb is None else px4_mode_name(int(hb.custom_mode))

    def wait_for_systems(self, wanted: set[int], timeout_s: float) -> set[int]:
        """Wait until HEARTBEATs of every system id in `wanted` were heard; the ids heard.
        AssertionError naming the missing ones after `timeout_s` wall seconds."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not wanted <= set(self.heartbeats):
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise AssertionError(
                        f"heartbeats of systems {sorted(wanted - set(self.heartbeats))} not "
                        f"heard within {timeout_s} s (heard {sorted(self.heartbeats)}, "
                        f"{self.count} messages)"
                    )
                self._cond.wait(min(remaining, 0.5))
            return set(self.heartbeats)

    def wait_for_mode(self, system_id: int, mode: FlightMode | str, timeout_s: float) -> None:
        """Wait until `system_id`'s HEARTBEAT shows `mode` (a FlightMode or a `px4_mode_name`);
        AssertionError after `timeout_s` wall seconds."""
        name = mode.px4_name if isinstance(mode, FlightMode) else mode
        deadline = time.monotonic() + timeout_s
        while self.mode(system_id) != name:
            if time.monotonic() > deadline:
                raise AssertionError(
                    f"system {system_id} not in {name} within {timeout_s} s "
                    f"(last {self.mode(system_id)})"
                )
            with self._cond:
                self._cond.wait(0.2)

    def close(self) -> None:
        self._closed.set()
        self._rx.join(timeout=5.0)
        self.conn.close()

    def __enter__(self) -> MavlinkListener:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
