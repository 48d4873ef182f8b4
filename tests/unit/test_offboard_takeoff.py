"""The mission start's arm and takeoff (service/bridge/offboard.py): a vehicle that disarmed
itself on the ground before the takeoff got through (PX4's COM_DISARM_PRFLT, over a lossy radio)
refuses it, and the bridge arms it again; other refusals and the last attempt are raised."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

import pytest

from isac_mission.errors import LinkError
from isac_mission.mavwire.builders import Target
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.service.bridge.offboard import TAKEOFF_ATTEMPTS, OffboardEntry
from isac_mission.service.bridge.settings import BridgeSettings

ARM, TAKEOFF = mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, mavlink2.MAV_CMD_NAV_TAKEOFF


@dataclass
class Vehicle:
    """A commander whose vehicle answers each takeoff with the next of `takeoff_answers`
    (None: accepted, else the refusal's text), and that arms whenever asked."""

    takeoff_answers: list[str | None]
    sent: list[int] = field(default_factory=list)
    link: Any = field(default_factory=lambda: type("Link", (), {"target": Target(1)})())
    counters: Any = None

    async def command(self, msg: Any) -> None:
        self.sent.append(int(msg.command))
        if int(msg.command) == TAKEOFF:
            answer = self.takeoff_answers.pop(0)
            if answer is not None:
                raise LinkError(f"vehicle 0: MAV_CMD_NAV_TAKEOFF refused: {answer}")


def _take_off(vehicle: Vehicle) -> None:
    entry = OffboardEntry(BridgeSettings(), None, None, vehicle)  # type: ignore[arg-type]
    asyncio.run(entry._arm_and_take_off(140.0))


def test_a_takeoff_denied_after_an_auto_disarm_is_armed_again_and_retried() -> None:
    vehicle = Vehicle(["MAV_RESULT_DENIED", None])
    _take_off(vehicle)
    assert vehicle.sent == [ARM, TAKEOFF, ARM, TAKEOFF]


def test_the_last_denied_takeoff_and_other_refusals_are_raised() -> None:
    vehicle = Vehicle(["MAV_RESULT_DENIED"] * TAKEOFF_ATTEMPTS)
    with pytest.raises(LinkError, match="DENIED"):
        _take_off(vehicle)
    assert vehicle.sent == [ARM, TAKEOFF] * TAKEOFF_ATTEMPTS
    vehicle = Vehicle(["MAV_RESULT_UNSUPPORTED"])
    with pytest.raises(LinkError, match="UNSUPPORTED"):
        _take_off(vehicle)
    assert vehicle.sent == [ARM, TAKEOFF]
