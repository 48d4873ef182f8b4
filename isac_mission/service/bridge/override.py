"""Operator override: when a vehicle is not the service's to fly, and why (pure state).

A vehicle the bridge flies in OFFBOARD can leave OFFBOARD for two kinds of reasons:

- **the offboard-loss hold after a link gap**: the bridge's own link had a gap (heartbeats lost,
  or its position stream stopped for more than `interruption_after_s`: supervision.py), or the
  vehicle says so in a STATUSTEXT ("Offboard lost", a one-way gap the bridge cannot see). The
  bridge takes the vehicle back into OFFBOARD (supervision.py, offboard.py), as before;
- **everything else is an override**: a ground station's mode change (HOLD, RTL, LAND, MISSION,
  POSCTL, ...) or a failsafe of the vehicle's own (low battery, datalink-loss RTL, geofence),
  seen with the link up, the position stream fresh and no gap in the watch window. The bridge
  then sends the vehicle no mode change and no command, streams setpoints at the vehicle's own
  position (setpoints.py, `follow_vehicle`), and reports why in its telemetry (`override`):
  "operator: HOLD", "RTL: low battery" (the cause read from the vehicle's recent STATUSTEXT),
  "landed", "killed: disarmed in the air".

An override ends when the vehicle is back in OFFBOARD and airborne (an operator's plain switch),
or when an operator sends `release` on `control` (the bridge then takes it back itself). A
vehicle that lands or is disarmed in the air stays out (docs/service.md, "Operator override").
"""

from __future__ import annotations

from collections import deque
from typing import Final

from isac_mission.mavwire.status import VehicleStatus

KILLED: Final = "killed: disarmed in the air"
"""The override of a vehicle disarmed in the air (it falls: out of the mission)."""

STATUSTEXT_KEPT_S: Final = 10.0
"""How long a vehicle's STATUSTEXT is taken as the cause of its next mode change (link clock s)."""
_CAUSES: Final = (
    (("battery",), "low battery"),
    (("fence",), "geofence"),
    (("ground station", "datalink", "data link", "gcs"), "datalink loss"),
)
"""STATUSTEXT keywords (lower case) -> the cause named in `override`."""


def is_offboard_loss(text: str) -> bool:
    """True for a STATUSTEXT announcing the offboard-loss failsafe ("Offboard lost: HOLD")."""
    low = text.lower()
    return "offboard" in low and ("lost" in low or "loss" in low)


class OverrideWatch:
    """Recent STATUSTEXT of one vehicle and the words of an override."""

    def __init__(self) -> None:
        self.texts: deque[tuple[float, str]] = deque(maxlen=16)
        """(link-clock time s, text) of the vehicle's latest STATUSTEXT."""

    def on_statustext(self, time_s: float, text: str) -> None:
        """A STATUSTEXT from the vehicle at link-clock time `time_s`."""
        self.texts.append((time_s, text))

    def recent(self, now_s: float) -> list[str]:
        """The texts of the last STATUSTEXT_KEPT_S seconds, newest first."""
        return [t for s, t in reversed(self.texts) if now_s - s <= STATUSTEXT_KEPT_S]

    def offboard_lost(self, now_s: float) -> bool:
        """The vehicle announced the offboard-loss failsafe lately (its own link gap)."""
        return any(is_offboard_loss(t) for t in self.recent(now_s))

    def cause(self, now_s: float) -> str | None:
        """The failsafe cause the vehicle announced lately (None: none, an operator's)."""
        for text in self.recent(now_s):
            low = text.lower()
            for words, cause in _CAUSES:
                if any(w in low for w in words):
                    return cause
        return None

    def reason(self, st: VehicleStatus, now_s: float, was: str = "") -> str:
        """Why vehicle status `st` is an override (the `override` text); `was`: the override
        so far, whose failsafe cause is kept once its STATUSTEXT is old ("RTL: low battery"
        then "LAND: low battery", not "operator: LAND")."""
        if not st.airborne:
            return "landed" if st.landed else KILLED
        mode = {"hold": "HOLD", "rtl": "RTL", "land": "LAND", "mission": "MISSION"}.get(
            st.mode, st.mode.upper()
        )
        kept = was.partition(": ")[2] if not was.startswith("operator") else ""
        cause = self.cause(now_s) or kept or None
        return f"{mode}: {cause}" if cause else f"operator: {mode}"
