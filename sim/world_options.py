"""How to run the simulated world (`WorldOptions`, scheduled link outages) and what it counts
(`WorldStats`). Times are simulation seconds unless marked wall."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

from isac_mission.bus import BusSettings
from isac_mission.config import ImpairmentConfig
from isac_mission.frames import PX4_SITL_ORIGIN, GeoPoint
from isac_mission.mavwire.ports import (
    GCS_LOCAL_BASE_PORT,
    GCS_PORT,
    OFFBOARD_BASE_PORT,
    OFFBOARD_LOCAL_BASE_PORT,
    check_base_port,
)

StartMode = Literal["immediate", "offboard"]


@dataclass(frozen=True)
class LinkOutage:
    """Vehicle `vehicle`'s MAVLink radio is dead for `duration_s` simulation seconds from
    `start_s` after mission start (slot 0)."""

    vehicle: int
    start_s: float
    duration_s: float

    @classmethod
    def parse(cls, text: str) -> LinkOutage:
        """`M:START:DURATION`, e.g. `1:20:5` (vehicle 1, 20 s into the mission, for 5 s)."""
        parts = text.split(":")
        try:
            m, start, duration = int(parts[0]), float(parts[1]), float(parts[2])
            if len(parts) != 3 or m < 0 or start < 0 or duration <= 0:
                raise ValueError
        except (ValueError, IndexError):
            raise ValueError(
                f"link outage {text!r}: expected VEHICLE:START_S:DURATION_S, e.g. 1:20:5"
            ) from None
        return cls(m, start, duration)


def parse_outages(texts: Sequence[str], n_vehicles: int) -> tuple[LinkOutage, ...]:
    """LinkOutage.parse of each text, checked against the fleet size; ValueError names the bad one."""
    outages = tuple(LinkOutage.parse(text) for text in texts)
    for text, outage in zip(texts, outages, strict=True):
        if outage.vehicle >= n_vehicles:
            raise ValueError(
                f"link outage {text!r}: no vehicle {outage.vehicle} (M = {n_vehicles})"
            )
    return outages


@dataclass(frozen=True)
class SerialLink:
    """Vehicle `vehicle` also speaks MAVLink on the serial device `device` at `baud`."""

    vehicle: int
    device: str
    baud: int = 57600

    @classmethod
    def parse(cls, text: str) -> SerialLink:
        """`M=DEVICE[:BAUD]`, e.g. `1=/dev/pts/5:57600` (vehicle 1 on /dev/pts/5)."""
        m_text, _, rest = text.partition("=")
        device, _, baud_text = rest.rpartition(":")
        if not baud_text.isdigit():
            device, baud_text = rest, "57600"
        if not m_text.isdigit() or not device.startswith("/") or int(baud_text) <= 0:
            raise ValueError(
                f"serial link {text!r}: expected VEHICLE=DEVICE[:BAUD], e.g. 1=/dev/ttyUSB0"
            )
        return cls(int(m_text), device, int(baud_text))


def parse_serial_links(texts: Sequence[str], n_vehicles: int) -> tuple[SerialLink, ...]:
    """SerialLink.parse of each text, checked against the fleet size (one device per vehicle)."""
    links = tuple(SerialLink.parse(text) for text in texts)
    seen: set[int] = set()
    for text, link in zip(texts, links, strict=True):
        if link.vehicle >= n_vehicles or link.vehicle in seen:
            raise ValueError(f"serial link {text!r}: no vehicle {link.vehicle}, or given twice")
        seen.add(link.vehicle)
    return links


@dataclass(frozen=True)
class WorldOptions:
    """How to run the world. Times are simulation seconds unless marked wall.

    speed: simulation seconds per wall second (math.inf: as fast as possible).
    lockstep: hold the clock at each slot boundary until the next slot's plan arrives.
    lockstep_timeout_s: wall seconds to wait for that plan before going on.
    seed: seed of the target and sensing noise (None: the scenario's seed).
    bus: Zenoh settings (default: peer connecting to tcp/127.0.0.1:7447).
    PX4 SITL's port layout (docs/service.md, "Ports"), every port UDP on 127.0.0.1:
    mavlink_base_port: vehicle m sends its offboard link to base + m (14540 + m);
    mavlink_local_base_port: ... from local port base + m (14580 + m; 0: ephemeral);
    gcs_port: every vehicle sends its ground-station link to this one port (14550)...
    gcs_local_base_port: ... from local port base + m (18570 + m; 0: ephemeral).
    tick_hz: physics rate (simulation Hz); clock_rate_hz: clock publication rate (simulation Hz).
    start: "immediate" or "offboard" (see `sim.world`: slot 0 at t = 0, or once every vehicle
    is up in OFFBOARD); start_altitude_tol_m: |alt - H| allowed for an "offboard" start.
    target_waypoints_xy_m / target_speed_mps: a scripted target path instead of the CV model
    (speed default: the speed of x0). reflect_target: keep the CV target inside the area.
    initial_error: start the CV target at x0 + e, e ~ N(0, P0), so that the tracker's prior
    (mean x0, covariance P0) is honest; False starts it exactly at x0.
    geo_origin: geodetic position of the scenario origin (GPS of the simulated vehicles).
    link_outages: scheduled MAVLink radio failures (fault injection, docs/reliability.md).
    impairment: lossy, late links (fault injection, `sim.world_impairment`); None: the
    scenario's `impairment` section.
    serial_links: vehicles that also speak MAVLink on a serial device (SerialLink).
    """

    speed: float = 1.0
    lockstep: bool = False
    lockstep_timeout_s: float = 30.0
    seed: int | None = None
    bus: BusSettings = field(default_factory=BusSettings)
    mavlink_base_port: int = OFFBOARD_BASE_PORT
    mavlink_local_base_port: int = OFFBOARD_LOCAL_BASE_PORT
    gcs_port: int = GCS_PORT
    gcs_local_base_port: int = GCS_LOCAL_BASE_PORT
    tick_hz: float = 50.0
    clock_rate_hz: float = 10.0
    start: StartMode = "immediate"
    start_altitude_tol_m: float = 2.0
    target_waypoints_xy_m: tuple[tuple[float, float], ...] | None = None
    target_speed_mps: float | None = None
    reflect_target: bool = True
    initial_error: bool = True
    geo_origin: GeoPoint = PX4_SITL_ORIGIN
    link_outages: tuple[LinkOutage, ...] = ()
    impairment: ImpairmentConfig | None = None
    serial_links: tuple[SerialLink, ...] = ()

    def __post_init__(self) -> None:
        if math.isnan(self.speed) or self.speed <= 0:
            raise ValueError(f"speed must be > 0 or inf, got {self.speed}")
        if not self.lockstep_timeout_s > 0:
            raise ValueError(f"lockstep_timeout_s must be > 0, got {self.lockstep_timeout_s}")
        if not (math.isfinite(self.tick_hz) and self.tick_hz > 0):
            raise ValueError(f"tick_hz must be finite and > 0, got {self.tick_hz}")
        if not (math.isfinite(self.clock_rate_hz) and self.clock_rate_hz > 0):
            raise ValueError(f"clock_rate_hz must be finite and > 0, got {self.clock_rate_hz}")
        if self.start not in ("immediate", "offboard"):
            raise ValueError(f"start must be immediate or offboard, got {self.start!r}")
        for name in ("mavlink_base_port", "mavlink_local_base_port", "gcs_local_base_port"):
            problem = check_base_port(name, getattr(self, name))
            if problem is not None:
                raise ValueError(problem)
        if self.mavlink_base_port == 0:
            raise ValueError("mavlink_base_port must be a port, got 0")
        if not 1 <= self.gcs_port <= 65535:
            raise ValueError(f"gcs_port must be a UDP port, got {self.gcs_port}")


@dataclass
class WorldStats:
    """Counters of a world run (returned by run_world)."""

    slots: int = 0
    mission_t0_s: float | None = None
    sim_time_s: float = 0.0
    detections_published: int = 0
    clock_published: int = 0
    truth_published: int = 0
    plans_received: int = 0
    plans_rejected: int = 0
    lockstep_holds: int = 0
    lockstep_timeouts: int = 0
    last_error: str = ""
