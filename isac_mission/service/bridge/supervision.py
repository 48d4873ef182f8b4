"""Link supervision of one vehicle: losses, regains, interruptions, and when to re-enter OFFBOARD.

A vehicle silent for `link_lost_after_s` (simulation seconds: nothing heard from it, its
heartbeat or anything else; `MavlinkLink.lost`) is reported with link "lost"; the setpoint
stream keeps running meanwhile (the uplink may still work). When heartbeats return while the
bridge is flying the mission, the bridge re-enters OFFBOARD if the
vehicle took its loss action. A radio gap shorter than link loss but longer than PX4's
offboard-loss timeout (`interruption_after_s`) also leaves the vehicle in hold: after such a gap
in its position stream, the bridge re-enters OFFBOARD once the vehicle reports the hold. So it does
after a gap in its own setpoint stream (the uplink: a stalled process, or a simulation catching up
after a pause, while positions kept coming) longer than the offboard-loss timeout less one
setpoint period (`uplink_gap_limit_s`: the vehicle stamps setpoints when they arrive), and after
the vehicle announces the offboard loss itself (a STATUSTEXT: a one-way gap the bridge cannot
see). A mode change by anyone else while the link is up is respected (no re-entry). Pure state:
the bridge calls `observe_uplink` and `observe` with each status and runs the re-entry itself
(docs/reliability.md).
"""

from __future__ import annotations

import logging
import math

from isac_mission.mavwire.status import VehicleStatus
from isac_mission.service.bridge.counters import BridgeCounters
from isac_mission.service.bridge.settings import BridgeSettings

log = logging.getLogger(__name__)


class LinkWatch:
    """Follows one vehicle's link-state transitions and the gaps of its position and setpoint
    streams.

    Args:
        settings: The bridge's settings (index, link_lost_after_s, interruption_after_s).
        counters: The bridge's counters (link_losses, link_interruptions).
    """

    def __init__(self, settings: BridgeSettings, counters: BridgeCounters) -> None:
        self.settings = settings
        self.counters = counters
        self._reported_lost = True
        self._ever_ok = False
        self._last_position_s: float | None = None
        self._reentry_watch_until_s = -math.inf
        """After the vehicle's stream resumes from a gap, re-enter OFFBOARD until this time if
        the vehicle reports the offboard-loss hold (the gap may be shorter than link loss)."""
        self._gap_until_s = -math.inf
        """Until this time a mode change is put down to the last gap (override.py)."""
        self._watch_from_s: float | None = None
        """Simulation time of the first `observe`: positions stamped before it are not compared
        (a bridge fed by the world's clock stamps what it hears before the first clock message
        with 0, and that is no time the vehicle was heard at)."""
        self._uplink_gap_s: float | None = None
        """The longest setpoint-stream gap of the re-entry watch, not counted yet (it is counted
        and logged if the vehicle's hold follows: an uplink gap alone need not have cost
        anything)."""
        self._loss_reported = False
        """The vehicle announced the offboard loss during the re-entry watch (not counted yet)."""
        self._uplink_silent = False
        """The setpoint stream is silent for longer than `uplink_gap_limit_s` now: no re-entry
        until it runs again (the vehicle refuses OFFBOARD without a recent setpoint)."""

    @property
    def index(self) -> int:
        """Vehicle index m."""
        return self.settings.index

    @property
    def _window_s(self) -> float:
        """How long after a gap a mode change is the gap's: 3 x interruption_after_s + 2 s."""
        return 3.0 * self.settings.interruption_after_s + 2.0

    @property
    def uplink_gap_limit_s(self) -> float:
        """A gap in the setpoint stream longer than this may have cost the vehicle its
        OFFBOARD: interruption_after_s (the vehicle's COM_OF_LOSS_T) less one setpoint period,
        for the jitter of the vehicle stamping setpoints on arrival (at least half of it)."""
        s = self.settings
        t = s.interruption_after_s
        return max(t - 1.0 / s.setpoint_rate_hz, 0.5 * t)

    def observe_uplink(self, gap_s: float, silent_s: float, now_s: float) -> None:
        """Take the setpoint stream's state at simulation time `now_s`: `gap_s`, its longest
        gap between two setpoints since the last call, and `silent_s`, how long it has sent
        nothing now (simulation s; setpoints.py). A gap longer than `uplink_gap_limit_s` opens
        the re-entry watch, like a gap in the position stream; a silence that long marks a gap
        (so that a hold seen before the stream resumes is not taken for an override)."""
        limit = self.uplink_gap_limit_s
        self._uplink_silent = silent_s > limit
        if self._uplink_silent:
            self._gap_until_s = max(self._gap_until_s, now_s + self._window_s)
        if gap_s <= limit:
            return
        log.debug("vehicle %d: no setpoint sent for %.2f s", self.index, gap_s)
        if not self._counted_watch(now_s):
            self._uplink_gap_s = max(gap_s, self._uplink_gap_s or 0.0)
        self._open_watch(now_s)

    def offboard_loss_reported(self, now_s: float) -> None:
        """The vehicle announced its offboard-loss failsafe (STATUSTEXT) at simulation time
        `now_s`: it heard no setpoint for its timeout, whether or not the bridge saw a gap (a
        one-way radio gap). Opens the re-entry watch, like a gap."""
        if not self._counted_watch(now_s):
            self._loss_reported = True
        self._open_watch(now_s)

    def _counted_watch(self, now_s: float) -> bool:
        """A re-entry watch is open for a gap counted already (one in the position stream)."""
        pending = self._uplink_gap_s is not None or self._loss_reported
        return now_s <= self._reentry_watch_until_s and not pending

    def _open_watch(self, now_s: float) -> None:
        self._reentry_watch_until_s = now_s + self._window_s
        self._gap_until_s = max(self._gap_until_s, now_s + self._window_s)

    def _count_pending(self, mode: str) -> None:
        """The vehicle left OFFBOARD after an uplink gap or its announced offboard loss: one
        interruption, logged once with the gap's length."""
        gap_s, reported = self._uplink_gap_s, self._loss_reported
        self._uplink_gap_s, self._loss_reported = None, False
        if gap_s is None and not reported:
            return
        self.counters.link_interruptions += 1
        said = "; the vehicle reported the offboard loss" if reported else ""
        if gap_s is None:
            log.warning("vehicle %d: %s%s; link interrupted", self.index, mode.upper(), said)
            return
        log.warning(
            "vehicle %d: %s after %.2f s without a setpoint sent (the offboard-loss timeout is "
            "%.1f s)%s; link interrupted",
            self.index,
            mode.upper(),
            gap_s,
            self.settings.interruption_after_s,
            said,
        )

    def gap_recent(self, st: VehicleStatus, now_s: float) -> bool:
        """True while a mode change may be the offboard-loss action of a link gap: the link is
        lost, the position stream has stopped for more than interruption_after_s, or a gap
        ended less than 3 x interruption_after_s + 2 s ago."""
        stalled = (
            st.position_s is None or now_s - st.position_s > self.settings.interruption_after_s
        )
        return st.lost or stalled or now_s <= self._gap_until_s

    def observe(
        self, st: VehicleStatus, now_s: float, want_offboard: bool, reentry_idle: bool
    ) -> bool:
        """Take status `st` at simulation time `now_s`; True when the bridge should start
        re-entering OFFBOARD (it wants OFFBOARD and no re-entry is running)."""
        start = self._watch_interruptions(st, now_s, want_offboard, reentry_idle)
        if st.lost == self._reported_lost:
            return start
        self._reported_lost = st.lost
        if st.lost:
            if self._ever_ok:
                self.counters.link_losses += 1
                log.warning(
                    "vehicle %d: link lost (no heartbeat for %.1f s)",
                    self.index,
                    self.settings.link_lost_after_s,
                )
            return start
        regained = self._ever_ok
        self._ever_ok = True
        self._gap_until_s = now_s + self._window_s
        if regained:
            log.info("vehicle %d: link regained (mode %s)", self.index, st.mode)
            # A re-entry the interruption watch has just asked for is the one to run.
            return start or (want_offboard and reentry_idle)
        return start

    def _watch_interruptions(
        self, st: VehicleStatus, now_s: float, want_offboard: bool, reentry_idle: bool
    ) -> bool:
        if self._watch_from_s is None:
            self._watch_from_s = now_s
        if st.position_s is not None and st.position_s >= self._watch_from_s:
            last, self._last_position_s = self._last_position_s, st.position_s
            if last is not None and st.position_s - last > self.settings.interruption_after_s:
                log.warning(
                    "vehicle %d: no position for %.1f s; link interrupted",
                    self.index,
                    st.position_s - last,
                )
                self.counters.link_interruptions += 1
                self._uplink_gap_s, self._loss_reported = None, False  # this one is counted
                self._open_watch(now_s)
        if now_s > self._reentry_watch_until_s:
            # The watch ended without a hold: the uplink gap cost nothing.
            self._uplink_gap_s, self._loss_reported = None, False
            return False
        if (
            not st.lost
            and st.mode != "offboard"
            and want_offboard
            and reentry_idle
            and not self._uplink_silent
        ):
            self._reentry_watch_until_s = -math.inf
            self._count_pending(st.mode)
            return True
        return False
