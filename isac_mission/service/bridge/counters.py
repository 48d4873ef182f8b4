"""What the bridges and the fleet count, for health reports and the end-of-run summary."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class BridgeCounters:
    """What a bridge did, for health reports."""

    telemetry_published: int = 0
    setpoints_sent: int = 0
    heartbeats_sent: int = 0
    link_losses: int = 0
    link_interruptions: int = 0
    offboard_reentries: int = 0
    overrides: int = 0
    """Times the vehicle was found not to be the service's to fly (override.py)."""
    loop_errors: int = 0
    last_error: str = ""


@dataclass
class FleetCounters:
    """Plans the fleet took or dropped."""

    plans_applied: int = 0
    plans_stale: int = 0
    plans_late: int = 0
    """Plans that arrived more than LATE_PLAN_SLOTS after their slot ended (fleet.py)."""
    plans_invalid: int = 0
    fleet_invalid: int = 0
    """Refused `fleet` commands."""
    last_error: str = ""
