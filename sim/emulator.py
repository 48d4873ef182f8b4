"""Sensing emulator: publishes each slot's reports on the bus and follows the plans' shares.

The world's scene (`sim.scenes.WorldScene`) draws every UAV's report of a slot with the shares
in use (`shares_for`) and makes it the message of its detection model (`detection`, a miss with
null range and radial velocity; or an unlabelled `detection_set`, empty when it detected
nothing); `publish_reports` puts each on `isac/<mission>/detections/<m>`. The bandwidth shares
are equal (1/M) until a plan arrives on `isac/<mission>/plan`; slot n then uses the shares of
the plan with the largest slot <= n (plan n carries eta_n; see isac_mission/wire/models.py). A
malformed plan (including one for a different number of UAVs or base stations) is counted in
`plans_rejected`, logged with its reason and ignored.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterable, Callable, Sequence
from typing import Protocol

import numpy as np

from isac_mission.errors import MessageError
from isac_mission.types import FloatArray
from isac_mission.wire import DetectionMsg, DetectionSetMsg, Keys, PlanMsg, decode, encode
from sim.sensing import equal_shares

log = logging.getLogger(__name__)

PlanListener = Callable[[PlanMsg], None]


class Publisher(Protocol):
    """What the emulator needs from a bus (ZenohBus satisfies it)."""

    def publish(self, key: str, payload: bytes) -> None:
        """Put `payload` on `key`."""
        ...


class SensingEmulator:
    """Publishes reports for n_uavs UAVs; n_bs (optional) bounds a plan's BS indices."""

    def __init__(self, bus: Publisher, keys: Keys, n_uavs: int, *, n_bs: int | None = None) -> None:
        if n_uavs < 1:
            raise ValueError(f"n_uavs must be >= 1, got {n_uavs}")
        self._bus = bus
        self._keys = keys
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

    def publish_reports(self, slot: int, reports: Sequence[DetectionMsg | DetectionSetMsg]) -> None:
        """Put slot `slot`'s reports (one message per UAV, drawn with `shares_for(slot)`) on
        each one's UAV's detections key, in order."""
        for msg in reports:
            self._bus.publish(self._keys.detections(msg.uav), encode(msg))
            self.detections_published += 1
        self._forget_old_plans(slot)

    def _forget_old_plans(self, slot: int) -> None:
        """Plans older than the one in use at `slot` can no longer be selected."""
        current = self.plan_for(slot)
        if current is not None:
            self._plans = {s: p for s, p in self._plans.items() if s >= current.slot}
