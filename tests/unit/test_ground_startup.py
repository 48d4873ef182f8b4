"""The planning gate (ground/startup.py) and the bridges' late-plan rule, without I/O: the gate
opens only on fresh telemetry of every vehicle (or after the timeout for those that reported),
closes on a stall of the loop, and the slots the world ran meanwhile are traced without made-up
positions."""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.planning.kit import SolverKit
from isac_mission.service.ground import exclusion
from isac_mission.service.ground.exclusion import VehicleWatch
from isac_mission.service.ground.mission import MissionState
from isac_mission.service.ground.report import GroundReport
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.service.ground.startup import PlanningGate
from isac_mission.service.ground.tracefile import slot_record
from isac_mission.timebase import plan_is_late
from isac_mission.types import Gaussian
from isac_mission.wire import DetectionMsg, TelemetryMsg


class FakeWall:
    """A wall clock the test moves (s)."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def _tel(m: int, t_s: float, link: str = "ok") -> TelemetryMsg:
    return TelemetryMsg(
        slot=0,
        t_s=t_s,
        uav=m,
        position_xy_m=np.array([100.0 * m, 0.0]),
        altitude_m=100.0,
        velocity_xy_mps=np.zeros(2),
        mode="offboard",
        armed=True,
        landed=False,
        link=link,
    )


@pytest.fixture
def wall(monkeypatch: pytest.MonkeyPatch) -> FakeWall:
    """One fake wall clock for the gate and the vehicle watch's arrival times."""
    fake = FakeWall()
    monkeypatch.setattr(exclusion.time, "monotonic", fake)
    return fake


def _rig(wall: FakeWall, **settings: object) -> tuple[PlanningGate, VehicleWatch]:
    s = GroundSettings(wait_for_telemetry=True, **settings)  # type: ignore[arg-type]
    return PlanningGate(3, s, wall), VehicleWatch(3, s, GroundReport())


def test_the_gate_opens_only_when_every_vehicle_has_reported_over_a_live_link(
    wall: FakeWall,
) -> None:
    gate, vehicles = _rig(wall)
    assert gate.closed and not gate.try_open(vehicles, 5.0)
    vehicles.on_telemetry(_tel(0, 5.0))
    vehicles.on_telemetry(_tel(1, 5.0))
    vehicles.on_telemetry(_tel(2, 5.0, link="lost"))  # a bridge that has not heard it yet
    vehicles.update(5.0)
    assert vehicles.excluded == {}  # "lost" before the link was ever up is no loss
    assert not gate.try_open(vehicles, 5.0)
    vehicles.on_telemetry(_tel(2, 5.1))
    vehicles.update(5.1)
    assert gate.try_open(vehicles, 5.1) and not gate.closed
    assert gate.waits[-1].planned == (0, 1, 2)


def test_a_normal_start_warns_of_nothing_and_a_start_without_a_vehicle_names_it(
    wall: FakeWall, caplog: pytest.LogCaptureFixture
) -> None:
    """Every vehicle reported at once: nothing logged (nothing is amiss); vehicles that never
    reported: one warning naming each, none for the start itself."""
    gate, vehicles = _rig(wall, startup_wait_s=10.0)
    for m in range(3):
        vehicles.on_telemetry(_tel(m, 5.0))
    with caplog.at_level("INFO", logger="isac_mission.service.ground.startup"):
        assert gate.try_open(vehicles, 5.0)
    assert [r.levelname for r in caplog.records] == []
    caplog.clear()
    gate, vehicles = _rig(wall, startup_wait_s=10.0)
    vehicles.on_telemetry(_tel(1, 5.0))
    assert not gate.try_open(vehicles, 5.0)
    wall.t += 10.5
    with caplog.at_level("INFO", logger="isac_mission.service.ground.startup"):
        assert gate.try_open(vehicles, 5.0)
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert [w.split(":")[0] for w in warnings] == ["vehicle 0", "vehicle 2"]


def test_after_the_timeout_the_gate_plans_those_that_reported_and_excludes_the_rest(
    wall: FakeWall,
) -> None:
    gate, vehicles = _rig(wall, startup_wait_s=10.0)
    assert not gate.try_open(vehicles, 5.0)  # the first call starts the timeout
    wall.t += 10.5
    assert not gate.try_open(vehicles, 5.0)  # nobody reported: still waiting
    vehicles.on_telemetry(_tel(1, 5.0))
    assert gate.try_open(vehicles, 5.0)
    assert sorted(vehicles.excluded) == [0, 2]
    assert gate.waits[-1].waited_s == pytest.approx(10.5)


def test_a_stall_closes_the_gate_until_telemetry_newer_than_the_stall_plus_settle(
    wall: FakeWall,
) -> None:
    gate, vehicles = _rig(wall, stall_gap_s=1.0, stall_settle_s=0.3)
    for m in range(3):
        vehicles.on_telemetry(_tel(m, 5.0))
    assert gate.try_open(vehicles, 5.0)
    wall.t += 3.0  # before the loop's first tick (its start-up) is no stall
    assert gate.tick() is None and not gate.closed
    wall.t += 0.05
    assert gate.tick() is None and not gate.closed
    wall.t += 5.0  # SIGSTOP
    assert gate.tick() == pytest.approx(5.0) and gate.closed
    assert not gate.try_open(vehicles, 5.0)  # the telemetry is from before the stall
    wall.t += 0.1
    for m in range(3):
        vehicles.on_telemetry(_tel(m, 20.0))  # the backlog, within the settle time
    assert not gate.try_open(vehicles, 20.0)
    wall.t += 0.3
    for m in range(3):
        vehicles.on_telemetry(_tel(m, 21.0))
    assert gate.try_open(vehicles, 21.0)
    assert gate.stalls_s == [pytest.approx(5.0)]


def test_without_telemetry_to_wait_for_the_gate_stays_open() -> None:
    s = GroundSettings()
    gate = PlanningGate(3, s, FakeWall())
    gate.close("resume")
    assert not gate.closed


def test_slots_run_without_a_plan_are_held_with_real_positions_or_unobserved_with_none(
    paper: Scenario, wall: FakeWall
) -> None:
    state = MissionState.from_prior(
        paper, SolverKit(paper), "proposed", Gaussian(paper.x0, paper.P0)
    )
    t0 = 10.0
    assert list(state.slots_to_skip(t0 + 2.0 * paper.dt, t0)) == [1, 2]
    compute_xy = paper.uav_start_xy
    rec1 = slot_record(state.skip(1, {}, None, compute_xy, "resume"), {})
    assert rec1.status == "unobserved" and np.isnan(np.asarray(rec1.uav_xy_m)).all()
    assert np.isnan(np.asarray(rec1.r_diag)).all()
    where = np.array([1234.0, 987.0])
    det = DetectionMsg(
        slot=2,
        t_s=t0 + 2.0,
        uav=1,
        uav_xy_m=where,
        range_m=800.0,
        radial_velocity_mps=1.0,
        bandwidth_share=0.5,
    )
    rec2 = slot_record(state.skip(2, {1: det}, None, compute_xy, "resume"), {})
    xy = np.asarray(rec2.uav_xy_m)
    assert rec2.status == "held" and state.slot == 2
    np.testing.assert_array_equal(xy[1], where)
    assert np.isnan(xy[[0, 2]]).all()
    assert np.isfinite(np.asarray(rec2.r_diag)[[1, 1 + paper.M]]).all()


def test_a_plan_more_than_a_slot_late_is_dropped() -> None:
    assert not plan_is_late(None, 1e9, 1.0)  # no mission start known
    assert not plan_is_late(10.0, 10.9, 1.0)  # within its slot's end plus one slot
    assert not plan_is_late(10.0, 11.0, 1.0)
    assert plan_is_late(10.0, 11.01, 1.0)
