"""The bridge's side of operator override: taking note that a vehicle is not the service's, and
giving it back (the rules are in override.py; docs/service.md, "Operator override")."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from isac_mission.mavwire.status import VehicleStatus
from isac_mission.service.bridge.counters import BridgeCounters
from isac_mission.service.bridge.offboard import OffboardEntry
from isac_mission.service.bridge.override import KILLED, OverrideWatch, is_offboard_loss
from isac_mission.service.bridge.setpoints import SetpointStream
from isac_mission.service.bridge.supervision import LinkWatch
from isac_mission.timebase import SimTime

log = logging.getLogger(__name__)


class OverrideKeeper:
    """Whether one vehicle is the service's to fly, and why not (`reason`).

    Args:
        index: Vehicle index m.
        time: Simulation time.
        stream: The bridge's setpoint stream (`follow_vehicle` while overridden).
        offboard: The bridge's OFFBOARD entry (`want`, `awaiting`).
        watch: The bridge's link supervision (`gap_recent`).
        counters: The bridge's counters (`overrides`).
        reenter: Starts the bridge's re-entry into OFFBOARD.
    """

    def __init__(
        self,
        index: int,
        time: SimTime,
        stream: SetpointStream,
        offboard: OffboardEntry,
        watch: LinkWatch,
        counters: BridgeCounters,
        reenter: Callable[[], None],
    ) -> None:
        self.index = index
        self.time = time
        self.stream = stream
        self.offboard = offboard
        self.watch = watch
        self.counters = counters
        self.reenter = reenter
        self.reason = ""
        """Why the service does not fly the vehicle; "" while it does."""
        self.was_in_air = False
        """The last status checked showed it armed and in the air (VehicleStatus.in_air)."""
        self.texts = OverrideWatch()

    def on_statustext(self, msg: Any) -> None:
        """A STATUSTEXT from the vehicle (its failsafes announce themselves; the offboard loss
        opens link supervision's re-entry watch)."""
        text = msg.text
        if isinstance(text, bytes):
            text = text.split(b"\x00", 1)[0].decode("utf-8", errors="replace")
        now = self.time.now_s()
        self.texts.on_statustext(now, str(text))
        if is_offboard_loss(str(text)):
            self.watch.offboard_loss_reported(now)

    def after_gap(self, st: VehicleStatus, now: float) -> bool:
        """Link supervision asks for a re-entry: True when it is the offboard-loss HOLD or LAND
        (re-enter); otherwise the vehicle's own failsafe took it (RTL, ...): an override."""
        if st.mode in ("hold", "land", "offboard") or self.texts.offboard_lost(now):
            return True
        self.take(self.texts.reason(st, now))
        return False

    def check(self, st: VehicleStatus, now: float, flying: bool, reentry_idle: bool) -> None:
        """Take status `st` (link up) while the bridge flies the mission (`flying`): notice an
        override, follow one (re-worded as the mode changes), or end it when the vehicle is back
        in OFFBOARD and airborne (an operator's switch)."""
        if not flying or st.lost:
            return
        was_in_air, self.was_in_air = self.was_in_air, st.in_air
        if was_in_air and not st.armed and not self.reason:
            # Disarmed straight from the air: no failsafe of a link gap disarms, and the fall
            # may reach the ground before a gap's grace ends (it would then read "landed").
            self.take(KILLED)
            return
        if self.reason == "control: hold" and (
            st.mode not in ("hold", "offboard", "unknown") or not st.airborne
        ):
            self.take(self.texts.reason(st, now))  # a ground station took the held vehicle
            return
        if self.reason:
            if self.reason.startswith(("control:", "landed", "killed")):
                return  # an operator's fleet command, or out of the mission
            if st.airborne and st.mode == "offboard":
                self.hand_back(st, command=False)
                return
            reason = self.texts.reason(st, now, self.reason)
            if reason != self.reason:
                log.warning("vehicle %d: %s (was %s)", self.index, reason, self.reason)
                self.reason = reason
                self._stop_if_out()
            return
        leaving = st.mode not in ("offboard", "unknown") or not st.airborne
        if not leaving or not self.offboard.want or not reentry_idle or self.offboard.awaiting:
            return
        if self.watch.gap_recent(st, now) or self.texts.offboard_lost(now):
            return  # the offboard-loss action of a link gap: supervision.py re-enters
        self.take(self.texts.reason(st, now))

    def take(self, reason: str) -> None:
        """The vehicle is not the service's: no mode change, no command; setpoints at its own
        position; `reason` says why."""
        self.reason = reason
        self.offboard.want = False
        self.stream.follow_vehicle = True
        self.counters.overrides += 1
        log.warning("vehicle %d: %s; not commanding it", self.index, reason)
        self._stop_if_out()

    def _stop_if_out(self) -> None:
        """A vehicle on the ground (landed, or killed) is out of the mission: no more setpoints
        (there is nothing to hand back, and setpoints on the ground are refused)."""
        if self.reason.startswith(("landed", "killed")):
            self.stream.stop()

    def hand_back(self, st: VehicleStatus, command: bool) -> None:
        """The service flies the vehicle again toward the current goal; `command`: switch it to
        OFFBOARD (resume, release), else it is there already (an operator's switch)."""
        log.warning("vehicle %d: flown by the service again (was: %s)", self.index, self.reason)
        self.reason = ""
        self.stream.follow_vehicle = False
        self.stream.reanchor(st)
        self.offboard.want = True
        if command and st.mode != "offboard":
            self.reenter()

    def not_ours(self, what: str) -> bool:
        """True (logged) when an operator or the vehicle's failsafe has it: no `what` then."""
        if self.reason and not self.reason.startswith("control:"):
            log.warning("vehicle %d: %s; no %s", self.index, self.reason, what)
            return True
        return False
