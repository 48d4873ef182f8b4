"""One vehicle's bridge settings, validated with pydantic; a bad value raises ConfigError."""

from __future__ import annotations

import math
from typing import ClassVar

from pydantic import InstanceOf, model_validator

from isac_mission.config import MavlinkSigningKey
from isac_mission.config.validation import Settings
from isac_mission.errors import ConfigError
from isac_mission.mavwire.ports import LOOPBACK, OFFBOARD_BASE_PORT
from isac_mission.mavwire.serial_link import parse_link_url

_POSITIVE = (
    "v_max_mps",
    "setpoint_rate_hz",
    "telemetry_rate_hz",
    "heartbeat_rate_hz",
    "link_lost_after_s",
    "interruption_after_s",
    "arrive_tolerance_m",
    "altitude_tolerance_m",
    "phase_timeout_s",
    "command_timeout_s",
    "connect_timeout_s",
)
"""Fields that must be finite and > 0."""

_NON_NEGATIVE = ("offboard_stream_s", "disarm_wait_s", "setpoint_lead_s", "leg_coast_s")
"""Fields that must be finite and >= 0."""


class BridgeSettings(Settings):
    """One vehicle's bridge. Units: m, m/s, Hz; times in simulation seconds unless "wall".

    Frozen; every bad value is named, one `BridgeSettings: ...` line each, in one ConfigError
    (`BridgeSettings: setpoint_rate_hz must be finite and > 0 (got 0.0)`).

    Attributes:
        index: 0-based vehicle index m (telemetry key `telemetry/<m>`).
        port: UDP port to bind on 127.0.0.1; None = base_port + index.
        link: The vehicle's link URL (`isac_mission.mavwire.serial_link`):
            `udpin:127.0.0.1:PORT` or `serial:DEVICE[:BAUD]`; None = `udpin:127.0.0.1:` +
            the port above.
        base_port: PX4's offboard base port (14540).
        system_id: The vehicle's MAVLink system id; None = index + 1.
        origin_xy_m: Scenario-plane position of the vehicle's local NED origin (on the ground).
        v_max_mps: V_max: the carrot never moves faster.
        transit_speed_mps: Carrot speed flying to the start point; None = v_max_mps.
        setpoint_rate_hz: SET_POSITION_TARGET_LOCAL_NED rate (simulation Hz, >= 10).
        setpoint_lead_s: Each setpoint is the carrot this far ahead of now: a setpoint is
            held for one period (half a period late on average) and reaches the vehicle after
            the link's latency, so the vehicle would otherwise trail the plan by v x delay.
            Default: half a period at 20 Hz, for a link of negligible latency (loopback, the
            simulated vehicles); add the link's latency for a radio. Measured with the
            simulated vehicle (tests/numerics/test_tracking_error.py): 0.05 s put it 0.6 m
            ahead of the plan at 22.5 m/s (docs/model.md, "Vehicle model").
        velocity_feed_forward: Send the carrot's velocity (type_mask 0xDC0) or position only.
        smooth_legs: Fly planned legs (with an arrival time) on a cubic that keeps position and
            velocity continuous (HermiteLeg) instead of a constant-speed carrot.
        leg_coast_s: A smooth leg's setpoint goes on at the leg's end velocity for this long
            past the deadline, then rests (HermiteLeg): the next plan comes after the slot
            boundary (in lockstep while the world holds there and the setpoint is sampled
            setpoint_lead_s ahead; in real time a planning latency later), and its leg then
            starts at the planned velocity instead of at rest (docs/model.md, "Vehicle model").
        yaw_rad: Heading to hold (0 = north); None = yaw ignored (the vehicle keeps its own).
        telemetry_rate_hz: Telemetry publication rate (simulation Hz).
        heartbeat_rate_hz: GCS HEARTBEAT rate (simulation Hz).
        link_lost_after_s: Nothing from the vehicle for this long = link lost (a
            HEARTBEAT ends the loss).
        interruption_after_s: A gap this long in the vehicle's position stream is an
            interruption (PX4's COM_OF_LOSS_T: the vehicle may have left OFFBOARD).
        arrive_tolerance_m: Horizontal distance to the start point counted as arrived.
        altitude_tolerance_m: |altitude - H| counted as at altitude.
        offboard_stream_s: How long setpoints stream before the OFFBOARD switch.
        phase_timeout_s: Budget of each prepare/land phase on top of its expected duration.
        disarm_wait_s: After touchdown, how long the vehicle may take to disarm by itself.
        command_timeout_s: Wall seconds to wait for a COMMAND_ACK per attempt.
        command_attempts: Attempts per command (8: over a radio losing 20 % of the packets
            each way an attempt fails 36 % of the time, so 3 attempts would leave 4.7 % of the
            commands unanswered, 8 leave 0.03 %; docs/reliability.md).
        connect_timeout_s: Wall seconds to wait for the vehicle's first heartbeat and position.
        signing: MAVLink 2 signing key of the link (sign all, reject unsigned or badly signed;
            `link.errors` counts them); None = no signing.
    """

    settings_name: ClassVar[str] = "BridgeSettings"

    index: int = 0
    port: int | None = None
    link: str | None = None
    base_port: int = OFFBOARD_BASE_PORT
    system_id: int | None = None
    origin_xy_m: tuple[float, float] = (0.0, 0.0)
    v_max_mps: float = 25.0
    transit_speed_mps: float | None = None
    setpoint_rate_hz: float = 20.0
    setpoint_lead_s: float = 0.025
    velocity_feed_forward: bool = True
    smooth_legs: bool = True
    leg_coast_s: float = 0.5
    yaw_rad: float | None = None
    telemetry_rate_hz: float = 10.0
    heartbeat_rate_hz: float = 1.0
    link_lost_after_s: float = 3.0
    interruption_after_s: float = 1.0
    arrive_tolerance_m: float = 1.0
    altitude_tolerance_m: float = 1.0
    offboard_stream_s: float = 1.0
    phase_timeout_s: float = 60.0
    disarm_wait_s: float = 5.0
    command_timeout_s: float = 1.0
    command_attempts: int = 8
    connect_timeout_s: float = 30.0
    signing: InstanceOf[MavlinkSigningKey] | None = None

    @model_validator(mode="after")
    def _check_values(self) -> BridgeSettings:
        """Every out-of-range value, one line each (ConfigError)."""
        problems: list[str] = []
        if not 0 <= self.index <= 253:
            problems.append(f"index must be in [0, 253] (got {self.index})")
        if not 0 <= self.listen_port <= 65535:
            problems.append(f"port must be a UDP port (got {self.listen_port})")
        if self.link is not None:
            try:
                parse_link_url(self.link)
            except ValueError as err:
                problems.append(f"link: {err}")
        for name in _POSITIVE:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                problems.append(f"{name} must be finite and > 0 (got {value})")
        if self.transit_speed_mps is not None and not (
            math.isfinite(self.transit_speed_mps) and self.transit_speed_mps > 0
        ):
            problems.append(f"transit_speed_mps must be > 0 or None (got {self.transit_speed_mps})")
        for name in _NON_NEGATIVE:
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                problems.append(f"{name} must be finite and >= 0 (got {value})")
        if self.command_attempts < 1:
            problems.append(f"command_attempts must be >= 1 (got {self.command_attempts})")
        if problems:
            raise ConfigError("\n".join(f"BridgeSettings: {p}" for p in problems))
        return self

    @property
    def listen_port(self) -> int:
        """The bound port: `port`, or base_port + index."""
        return self.base_port + self.index if self.port is None else self.port

    @property
    def link_url(self) -> str:
        """The vehicle's link URL: `link`, or `udpin:127.0.0.1:<listen_port>`."""
        return self.link if self.link is not None else f"udpin:{LOOPBACK}:{self.listen_port}"

    @property
    def vehicle_system_id(self) -> int:
        """The vehicle's system id: `system_id`, or index + 1."""
        return self.index + 1 if self.system_id is None else self.system_id
