"""Sensing emulator: publishes each slot's detections on the bus and follows the plans' shares.

A thin I/O wrapper around the pure `sim.sensing.Sensor`. Each slot it draws every UAV's detection
and publishes it on `isac/<mission>/detections/<m>` (codec `detection` payload; a missed
detection is published with null range and radial velocity). On a multi-target mission
(`draw_reports`, `publish_reports`) each UAV's unlabelled report of `sim.multi_target_scene` goes out instead, as a
`detection_set` (an empty one when it detected nothing). The bandwidth shares are equal
(1/M) until a plan arrives on `isac/<mission>/plan`; slot n then uses the shares of the plan
with the largest slot <= n (plan n carries eta_n; see isac_mission/wire/models.py). A malformed
plan (including one for a different number of UAVs or base stations) is counted in
`plans_rejected`, logged with its reason and ignored.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterable, Callable
from typing import Protocol

import numpy as np

from isac_mission.errors import MessageError
from isac_mission.model.detections import UavReport
from isac_mission.types import Detections, FloatArray
from isac_mission.wire import (
    Keys,
    PlanMsg,
    decode,
    detection_messages,
    detection_set_messages,
    encode,
)
from sim.multi_target_scene import MultiTargetScene
from sim.sensing import Sensor, equal_shares

log = logging.getLogger(__name__)

PlanListener = Callable[[PlanMsg], None]


class Publisher(Protocol):
    """What the emulator needs from a bus (ZenohBus satisfies it)."""

    def publish(self, key: str, payload: bytes) -> None:
        """Put `payload` on `key`."""
        ...


class SensingEmulator:
    """Publishes detections for n_uavs UAVs; n_bs (optional) bounds a plan's BS indices."""

    def __init__(
        self,
        bus: Publisher,
        keys: Keys,
        sensor: Sensor,
        n_uavs: int,
        *,
        n_bs: int | None = None,
    ) -> None:
        if n_uavs < 1:
            raise ValueError(f"n_uavs must be >= 1, got {n_uavs}")
        self._bus = bus
        self._keys = keys
        self._sensor = sensor
        self.n_uavs = n_uavs
        self.n_bs = n_bs
        self._plans: dict[int, PlanMsg] = {}
        self._listeners: list[PlanListener] = []
        self.latest_plan_slot = -1
        self.plans_received = 0
        self.plans_rejected = 0
        self.detections_published = 0
        self.last_error = ""

    def add_plan_listener(self, listener: PlanListener) -> None:
        """Call `listener(plan)` for every valid plan received (on the event loop)."""
        self._listeners.append(listener)

    def on_plan_payload(self, payload: bytes) -> PlanMsg | None:
        """Take one plan payload; returns the plan, or None if it was rejected."""
        try:
            msg = decode(PlanMsg, payload, n_uavs=self.n_uavs, n_bs=self.n_bs)
        except MessageError as err:
            self.plans_rejected += 1
            self.last_error = str(err)
            log.warning("plan rejected (%d so far): %s", self.plans_rejected, err)
            return None
        self.plans_received += 1
        self._plans[msg.slot] = msg
        self.latest_plan_slot = max(self.latest_plan_slot, msg.slot)
        for listener in list(self._listeners):
            listener(msg)
        return msg

    async def listen_plans(self, samples: AsyncIterable[tuple[str, bytes]]) -> None:
        """Feed every (key, payload) of a plan subscription to `on_plan_payload` until it ends."""
        async for _key, payload in samples:
            self.on_plan_payload(payload)

    def plan_for(self, slot: int) -> PlanMsg | None:
        """The plan with the largest slot <= `slot`, or None."""
        usable = [s for s in self._plans if s <= slot]
        return self._plans[max(usable)] if usable else None

    def shares_for(self, slot: int) -> FloatArray:
        """eta [M] in use at `slot`: the plan's shares, or equal shares before any plan."""
        plan = self.plan_for(slot)
        if plan is None:
            return equal_shares(self.n_uavs)
        return np.array(plan.plan.bandwidth_share, dtype=float)

    def emit(self, slot: int, t_s: float, target_x: FloatArray, uav_xy_m: FloatArray) -> Detections:
        """Draw slot `slot`'s detections at sim time t_s (s) from the true target state [4] and
        the UAVs' actual horizontal positions [M, 2] (m), publish them, and return them."""
        eta = self.shares_for(slot)
        det = self._sensor.sense(slot, target_x, uav_xy_m, eta)
        for msg in detection_messages(det, t_s, eta):
            self._bus.publish(self._keys.detections(msg.uav), encode(msg))
            self.detections_published += 1
        self._forget_old_plans(slot)
        return det

    def draw_reports(
        self, slot: int, scene: MultiTargetScene, uav_xy_m: FloatArray
    ) -> tuple[list[UavReport], FloatArray]:
        """Slot `slot`'s unlabelled reports [M] (1..N, with their origins) from the UAVs'
        actual horizontal positions [M, 2] (m), and the shares eta [M] in use."""
        eta = self.shares_for(slot)
        return scene.reports(slot, uav_xy_m, eta), eta

    def publish_reports(
        self,
        slot: int,
        t_s: float,
        reports: list[UavReport],
        uav_xy_m: FloatArray,
        eta: FloatArray,
    ) -> None:
        """One `detection_set` per UAV of `draw_reports`' reports, stamped t_s (s)."""
        msgs = detection_set_messages(slot, t_s, [r.measurements for r in reports], uav_xy_m, eta)
        for msg in msgs:
            self._bus.publish(self._keys.detections(msg.uav), encode(msg))
            self.detections_published += 1
        self._forget_old_plans(slot)

    def _forget_old_plans(self, slot: int) -> None:
        """Plans older than the one in use at `slot` can no longer be selected."""
        current = self.plan_for(slot)
        if current is not None:
            self._plans = {s: p for s, p in self._plans.items() if s >= current.slot}
