"""sim/emulator.py without a network: shares follow the plans, each report goes out on its UAV's
key; bad plans are counted and ignored."""

from __future__ import annotations

import json

import numpy as np

from isac_mission.config import parse_scenario
from isac_mission.types import SlotPlan, SolveReport
from isac_mission.wire import DetectionMsg, Keys, PlanMsg, decode, detection_messages, encode
from sim.emulator import SensingEmulator
from sim.sensing import SensingModel, Sensor


class FakeBus:
    def __init__(self) -> None:
        self.sent: list[tuple[str, bytes]] = []

    def publish(self, key: str, payload: bytes) -> None:
        self.sent.append((key, payload))


def _plan(slot: int, shares: list[float]) -> bytes:
    m = len(shares)
    plan = SlotPlan(
        uav_xy_m=np.zeros((m, 2)),
        bs_of_uav=np.zeros(m, dtype=np.int64),
        bandwidth_share=np.array(shares),
        pcrb_trace=1.0,
        report=SolveReport(status="ok"),
    )
    return encode(PlanMsg.from_plan(slot, 0.0, plan))


def _emulator() -> tuple[SensingEmulator, FakeBus]:
    s = parse_scenario({})
    bus = FakeBus()
    return SensingEmulator(bus, Keys("t"), 3, n_bs=s.K), bus


def _run_slot(em: SensingEmulator, n: int, t_s: float) -> None:
    """Slot n as the world runs it: detections drawn with the shares in use, then published."""
    sensor = Sensor(SensingModel.from_scenario(parse_scenario({})), np.random.default_rng(n))
    target = np.array([1500.0, 1500.0, 30.0, 0.0])
    uav_xy = np.array([[1500.0, 2300.0], [807.0, 1100.0], [2193.0, 1100.0]])
    eta = em.shares_for(n)
    em.publish_reports(n, detection_messages(sensor.sense(n, target, uav_xy, eta), t_s, eta))


def test_equal_shares_until_a_plan_then_the_latest_plan_not_after_the_slot() -> None:
    em, bus = _emulator()
    _run_slot(em, 0, 0.0)
    assert len(bus.sent) == 3
    keys = [k for k, _ in bus.sent]
    assert keys == ["isac/t/detections/0", "isac/t/detections/1", "isac/t/detections/2"]
    assert [decode(DetectionMsg, p).bandwidth_share for _, p in bus.sent] == [1 / 3] * 3
    em.on_plan_payload(_plan(1, [0.5, 0.3, 0.2]))
    em.on_plan_payload(_plan(3, [0.2, 0.2, 0.6]))  # for a later slot: not used before it
    np.testing.assert_array_equal(em.shares_for(1), [0.5, 0.3, 0.2])
    np.testing.assert_array_equal(em.shares_for(2), [0.5, 0.3, 0.2])
    np.testing.assert_array_equal(em.shares_for(3), [0.2, 0.2, 0.6])
    bus.sent.clear()
    _run_slot(em, 2, 2.0)
    assert [decode(DetectionMsg, p).bandwidth_share for _, p in bus.sent] == [0.5, 0.3, 0.2]
    assert em.detections_published == 6 and em.plans_received == 2


def test_a_malformed_plan_is_counted_with_its_reason_and_ignored() -> None:
    em, _ = _emulator()
    em.on_plan_payload(_plan(1, [0.5, 0.3, 0.2]))
    assert em.on_plan_payload(b"{oops") is None
    wrong_m = _plan(2, [0.5, 0.5])
    assert em.on_plan_payload(wrong_m) is None
    bad_bs = json.loads(_plan(2, [0.5, 0.3, 0.2]))
    bad_bs["assoc"] = [0, 0, 99]
    assert em.on_plan_payload(json.dumps(bad_bs).encode()) is None
    assert em.plans_rejected == 3 and em.plans_received == 1
    assert em.last_error.startswith("plan.assoc[2]")
    np.testing.assert_array_equal(em.shares_for(5), [0.5, 0.3, 0.2])
