"""The ground loop (service/ground/loop.py) on a scenario of several targets handles a
late plan, a plan made before a stall and a solver error as the single-target loop does
(loop.py; tests/unit/test_fallbacks.py, tests/reliability/test_solver_faults.py): a plan the
bridges would drop is marked "late" and counted; a plan made before a stall is dropped, counted,
and made again from the same prediction; after a solver error the communication-optimal plan is
flown, and the fleet holds only if that fails too. No network: the loop's planning step is run
on its own event loop, with a bus that records what is published."""

from __future__ import annotations

import asyncio
from typing import Any

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.planning import fleet
from isac_mission.planning import tracks as mt_planning
from isac_mission.planning.tracks import multi_target_kit
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.tracking.tracker import TrackPrediction
from isac_mission.wire import PlanMsg, decode
from tests.support.ground_steps import plan_slot_of


class RecordingBus:
    """What the loop publishes, by key (the loop's only use of the bus here)."""

    def __init__(self) -> None:
        self.published: list[tuple[str, bytes]] = []

    def publish(self, key: str, payload: bytes) -> None:
        self.published.append((key, payload))


class PlanningStep(GroundLoop):
    """The loop's planning step alone: nothing is processed after it (no slot machine)."""

    def _advance(self) -> None:
        pass


@pytest.fixture(scope="module")
def scenario() -> Scenario:
    return load_scenario("multi-target").with_changes(N=5)


def ground(s: Scenario, **settings: Any) -> tuple[GroundLoop, RecordingBus]:
    bus = RecordingBus()
    loop = PlanningStep(
        s,
        bus,  # type: ignore[arg-type]  # publish is all the planning step uses
        GroundSettings(**settings),
        multi_target_kit(s),
    )
    return loop, bus


def plan_slot_1(loop: GroundLoop) -> tuple[TrackPrediction, ...]:
    """Plan slot 1 from the start points as `_advance` does (no slot completed by it)."""
    xy = loop.s.uav_start_xy.copy()
    job = loop.state.next_job(xy, np.zeros_like(xy))
    asyncio.run(loop._plan(job, None, None))
    return job.predictions


def plans_published(loop: GroundLoop, bus: RecordingBus) -> list[PlanMsg]:
    return [
        decode(PlanMsg, payload, n_uavs=loop.s.M)
        for key, payload in bus.published
        if key == loop.keys.plan
    ]


def test_a_plan_published_after_the_bridges_drop_it_is_marked_late(scenario: Scenario) -> None:
    s = scenario
    loop, bus = ground(s)
    loop.mission_t0_s = 10.0
    loop.t_s = 10.0 + 2 * s.dt + 0.5  # 1.5 slots after slot 1's end: the bridges drop it
    plan_slot_1(loop)
    pending = loop.state.pending
    assert pending is not None and pending.slot == 1
    assert pending.plan.report.fallback == "late"
    end_s = 10.0 + s.dt
    assert pending.plan.report.reason.startswith(
        f"late: published at {loop.t_s:.1f} s, its slot ended at {end_s:.1f} s"
    )
    assert loop.report.counters["plans late"] == 1
    assert len(plans_published(loop, bus)) == 1

    on_time, _ = ground(s)
    on_time.mission_t0_s = 10.0
    on_time.t_s = 10.0 + s.dt + 0.5  # half a slot after its end: still flown
    plan_slot_1(on_time)
    assert on_time.state.pending is not None
    assert on_time.state.pending.plan.report.fallback != "late"
    assert on_time.report.counters["plans late"] == 0


def test_a_plan_made_before_a_stall_is_dropped_and_made_again(scenario: Scenario) -> None:
    s = scenario
    loop, bus = ground(s, wait_for_telemetry=True)
    gate = loop.gate
    gate.closed = False  # the vehicles had reported: the loop plans
    gate.last_tick_wall_s = gate.wall() - 10 * loop.settings.stall_gap_s  # stalled meanwhile
    tracks_before = len(loop.state.tracker.saved().tracks)
    predictions = plan_slot_1(loop)
    assert loop.report.counters["plans dropped after a stall"] == 1
    assert plans_published(loop, bus) == []
    assert loop.state.pending is None and gate.closed
    # Planned again once the gate opens, from the same prediction: the tracker is not
    # predicted twice, the known targets' tracks are not started twice.
    gate.closed = False
    again = plan_slot_1(loop)
    assert again is predictions
    assert len(loop.state.tracker.saved().tracks) == tracks_before + sum(
        1 for t in s.targets if t.prior_known and t.first_slot == 0
    )
    assert [m.slot for m in plans_published(loop, bus)] == [1]
    assert loop.state.pending is not None and loop.state.pending.slot == 1
    assert loop.report.counters["plans dropped after a stall"] == 1


def _failing_unless(monkeypatch: pytest.MonkeyPatch, allowed: tuple[str, ...]) -> list[str]:
    """plan_tracks raises for every method but `allowed`; returns the methods asked for."""
    asked: list[str] = []
    original = mt_planning.plan_tracks

    def plan_tracks(s: Scenario, method: str, *args: Any, **kwargs: Any) -> Any:
        asked.append(method)
        if method not in allowed:
            raise RuntimeError(f"{method} broke")
        return original(s, method, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(fleet, "plan_tracks", plan_tracks)
    return asked


def test_after_a_solver_error_the_communication_optimal_plan_is_flown(
    scenario: Scenario, monkeypatch: pytest.MonkeyPatch
) -> None:
    s = scenario
    loop, bus = ground(s)
    asked = _failing_unless(monkeypatch, ("comm",))
    predictions = plan_slot_1(loop)
    assert asked == ["proposed", "comm"]
    pending = loop.state.pending
    assert pending is not None
    report = pending.plan.report
    assert report.status == "solver error" and report.fallback == "solver error"
    assert report.reason == (
        "solver error: RuntimeError: proposed broke; fell back to the communication-optimal plan"
    )
    assert loop.report.counters["planner errors"] == 1
    # The tracks' communication-optimal plan (the other tracks kept out), not a hold.
    xy = s.uav_start_xy.copy()
    planned_for, comm = plan_slot_of(loop.state, xy, np.zeros_like(xy), method="comm", commit=False)
    assert loop.state.next_job(xy).predictions is predictions
    assert pending.planned_for == planned_for != 0
    np.testing.assert_array_equal(pending.plan.uav_xy_m, comm.uav_xy_m)
    np.testing.assert_array_equal(pending.plan.bandwidth_share, comm.bandwidth_share)
    assert not np.allclose(pending.plan.uav_xy_m, xy)
    (sent,) = plans_published(loop, bus)
    np.testing.assert_array_equal(sent.plan.uav_xy_m, comm.uav_xy_m)


def test_the_fleet_holds_when_the_communication_optimal_plan_fails_too(
    scenario: Scenario, monkeypatch: pytest.MonkeyPatch
) -> None:
    s = scenario
    loop, _ = ground(s)
    asked = _failing_unless(monkeypatch, ())
    plan_slot_1(loop)
    assert asked == ["proposed", "comm"]
    pending = loop.state.pending
    assert pending is not None and pending.planned_for == 0
    report = pending.plan.report
    assert report.status == "solver error" and report.fallback == "solver error"
    assert report.reason == (
        "solver error: RuntimeError: proposed broke; communication-optimal fallback failed "
        "too: comm broke; hold"
    )
    np.testing.assert_array_equal(pending.plan.uav_xy_m, s.uav_start_xy)
