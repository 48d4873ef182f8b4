"""A slot's detections, gathered: one per UAV, counted when stale, duplicate or out of range.

Slot n is ready when all M detections have arrived (a missed detection arrives as null), when
the simulation clock passes the slot's end by `detection_wait_s`, or `detection_wall_wait_s` of
wall time after the first of them or after the clock reached the slot's end (a held lockstep
clock whose detections were all lost must not wait for the world's timeout).
"""

from __future__ import annotations

import time
from collections import Counter
from typing import Generic, TypeVar

from isac_mission.service.ground.settings import GroundSettings
from isac_mission.timebase import SlotTimeline, reached
from isac_mission.wire import DetectionMsg, DetectionSetMsg

Report = TypeVar("Report", bound=DetectionMsg | DetectionSetMsg)
"""A UAV's report of a slot: one detection, or an unlabelled set (multi-target missions)."""


class DetectionAssembler(Generic[Report]):
    """Reports by slot and UAV until their slot is processed (times: time.monotonic, s)."""

    def __init__(
        self, n_uavs: int, n_slots: int, settings: GroundSettings, counters: Counter[str]
    ) -> None:
        self.n_uavs = n_uavs
        self.n_slots = n_slots
        self.settings = settings
        self.counters = counters
        self.buffer: dict[int, dict[int, Report]] = {}
        self.first_seen_wall: dict[int, float] = {}
        self.last_detection_wall = 0.0
        """Wall time the last accepted detection arrived."""

    def add(self, msg: Report, processed_slot: int) -> None:
        """Keep msg for its slot, unless it is for slot 0, an already processed slot, a slot
        beyond the mission or a UAV already heard in its slot (each counted)."""
        if msg.slot == 0:
            self.counters["detections of slot 0 (before plan 1)"] += 1
            return
        if msg.slot <= processed_slot:
            self.counters["detections stale"] += 1
            return
        if msg.slot > self.n_slots:
            self.counters["detections beyond mission"] += 1
            return
        slot_buf = self.buffer.setdefault(msg.slot, {})
        if msg.uav in slot_buf:
            self.counters["detections duplicate"] += 1
            return
        slot_buf[msg.uav] = msg
        now = time.monotonic()
        self.first_seen_wall.setdefault(msg.slot, now)
        self.last_detection_wall = now

    def ready(self, n: int, t_s: float, mission_t0_s: float | None, dt_s: float) -> bool:
        """Whether slot n can be processed now, at simulation time t_s (see the module doc)."""
        got = self.buffer.get(n, {})
        if len(got) == self.n_uavs:
            return True
        now = time.monotonic()
        if mission_t0_s is not None:
            boundary = SlotTimeline(mission_t0_s, dt_s).slot_end_s(n)
            if reached(t_s, boundary + self.settings.detection_wait_s):
                return True
            if reached(t_s, boundary):
                # The wall wait also runs from the clock reaching the slot's end, so that a slot
                # whose detections were all lost does not wait for a held (lockstep) clock.
                self.first_seen_wall.setdefault(n, now)
        first = self.first_seen_wall.get(n)
        return first is not None and now - first > self.settings.detection_wall_wait_s

    def take(self, n: int) -> dict[int, Report]:
        """Slot n's detections by UAV (removed); missing ones counted."""
        msgs = self.buffer.pop(n, {})
        self.first_seen_wall.pop(n, None)
        if len(msgs) < self.n_uavs:
            self.counters["slots with missing detections"] += 1
            self.counters["detections missing"] += self.n_uavs - len(msgs)
        return msgs
