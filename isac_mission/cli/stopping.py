"""What Ctrl-C (SIGINT) and SIGTERM do to a live mission, and what the operator is told.

The first request stops the mission after the slot in flight and lands the fleet, and says so
at once with how long the landing takes; the second stops waiting for touchdown (the vehicles
were sent LAND and finish it on their own: PX4's LAND needs no ground station) and the command
exits; further ones are refused with a word, not silently. Pure: the CLI's signal handler calls
`StopRequests.on_signal` and acts on the answer through the service's port (`Stopping`, with the
service's landing budget `land_budget_s`: isac_mission/service/assembly.py; docs/service.md,
"Stopping a mission").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from isac_mission.service.assembly import land_budget_s

LAND_FAST_MPS = 1.5
"""Descent rate of PX4's LAND above `LAND_SLOW_BELOW_M` (MPC_Z_VEL_MAX_DN's default), m/s."""
LAND_SLOW_MPS = 0.7
"""Descent rate of PX4's LAND near the ground (MPC_LAND_SPEED's default), m/s."""
LAND_SLOW_BELOW_M = 10.0
"""Height below which LAND descends slowly (MPC_LAND_ALT1's default), m."""
DISARM_AFTER_LAND_S = 2.0
"""PX4 disarms this long after touchdown (COM_DISARM_LAND's default), s."""


def landing_time_s(height_m: float) -> float:
    """Simulation seconds from LAND at `height_m` (m) to the disarm, at PX4's default rates."""
    h = max(height_m, 0.0)
    fast = max(h - LAND_SLOW_BELOW_M, 0.0) / LAND_FAST_MPS
    slow = min(h, LAND_SLOW_BELOW_M) / LAND_SLOW_MPS
    return fast + slow + DISARM_AFTER_LAND_S


Action = Literal["stop", "leave", "refuse"]


@dataclass
class StopRequests:
    """Counts the requests to stop one live mission and words the answer to each.

    height_m: the vehicles' flight height H (m); speed: simulation seconds per wall second;
    embedded: the world runs in this process (`run`), so it ends with it.
    """

    height_m: float
    speed: float
    embedded: bool
    count: int = 0

    def on_signal(
        self, signal_name: str, slot: int, n_slots: int, flying: bool = True
    ) -> tuple[Action, str]:
        """The action for one more request (`signal_name`: "SIGINT", "SIGTERM"), at the last
        traced slot `slot` of `n_slots`, and the line to print; flying: the fleet has been
        told to take off (False while the service still waits for its clock and vehicles:
        nothing to land)."""
        self.count += 1
        key = "Ctrl-C" if signal_name == "SIGINT" else signal_name
        if self.count == 1 and not flying:
            return (
                "stop",
                f"{key}: stopping before any vehicle was told to take off: nothing to land",
            )
        if self.count == 1:
            wall_s = landing_time_s(self.height_m) / max(self.speed, 1e-3)
            where = f"after slot {slot} of {n_slots}" if slot > 0 else "before slot 1"
            return "stop", (
                f"{key}: stopping the mission {where}; landing the fleet: about {wall_s:.0f} s "
                f"(at most {land_budget_s(self.height_m, self.speed):.0f} s) at --speed "
                f"{self.speed:g}. {key} again: stop waiting for the landing and exit"
            )
        if self.count == 2:
            after = (
                "the simulated world ends with this command"
                if self.embedded
                else "the vehicles were sent LAND and land on their own"
            )
            return "leave", f"{key} again: not waiting for the landing; exiting ({after})"
        return "refuse", f"{key}: already exiting; the summary and the trace are being written"
