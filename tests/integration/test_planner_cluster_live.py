"""The decomposed horizon's groups solved on a real Dask cluster during a live mission (`run`'s
world, the MAVLink bridges and the multi-target ground loop in this process, over Zenoh on an
explicit tcp/127.0.0.1 endpoint and MAVLink over loopback UDP, in lockstep): the planner
cluster of `LiveOptions.planner_cluster` (`run`/`serve --planner-workers 2`) is started before
the mission and closed after it, interrupted or not, and flies the serial mission's plans; a
worker killed mid-mission costs the slot in flight the per-slot plan (fallback `horizon:
decomposed worker lost`, counted in the report) and the mission flies on to its last slot and
lands. The options' refusals: tests/unit/test_planner_cluster_options.py; the cluster offline:
tests/integration/test_decomposed_cluster.py.

Live lockstep is not bit-reproducible from one run to the next, cluster or not: the vehicles
follow setpoints streamed at 20 Hz of wall time, so where they are at a slot boundary varies by
millimetres between runs. Measured on this scene at --speed 5 (serial against serial, two
runs): slot 1 (planned from the start points) equal to the bit, slots 2-10 within 2.8 mm and
shares within 1.7e-4; serial against a 2-worker cluster: within 4.6 mm and 3.5e-5. So the
missions are compared slot by slot within a tolerance above that spread (slot 1 exactly), and
the cluster's answers are checked to the bit against this process's solve of the very jobs it
was sent (the serial path's per-group solve: test_decomposed_cluster.py shows the two equal).
"""

from __future__ import annotations

import asyncio
import dataclasses
import os
import socket
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import psutil
import pytest
import yaml
from distributed import Client

from isac_mission.bus import tcp_loopback
from isac_mission.cli.embedded import embedded_world
from isac_mission.config import Scenario, load_scenario
from isac_mission.planner_cluster import DaskGroupExecutor, PlannerCluster, planner_client
from isac_mission.planning.decomposed import GroupJob, solve_group_job
from isac_mission.records.tracks import TracksSlot
from isac_mission.service.assembly import (
    CLUSTER_FALLBACKS,
    CLUSTER_SLOTS,
    LiveOptions,
    run_serve,
)
from isac_mission.service.mission_result import LiveResult
from isac_mission.types import SlotPlan
from tests.support import two_clusters as scene
from tests.support.ports import free_port_block, listening_hosts, sitl_ports

pytestmark = pytest.mark.timeout(180)

SLOTS = 10
SPEED = 5.0
"""Simulation seconds per wall second: slow enough that a busy moment does not stop the
setpoint stream for the vehicles' 1 s offboard-loss timeout (at --speed 25 one did, and that
run's plans then strayed metres from the other's)."""
MISSION_S = 120.0
"""Wall bound on one mission (start-up, about 20 s on a 2-core machine, included)."""
WORKER_LOST = "horizon: decomposed worker lost"
POSITION_TOL_M = 0.25
"""How far a slot's planned waypoints may be from the other mission's (m): ~50 times the
measured spread (module doc)."""
SHARE_TOL = 0.01
"""How far a slot's planned shares may be from the other mission's: ~50 times the spread."""

SCENE: dict[str, Any] = {
    "mission_id": "two-clusters-live",
    "timing": {"duration_s": SLOTS},
    "area": {"size_m": [4500, 2000]},
    "radio": {"bs_capacity": 3},
    "base_stations": {"count": 2, "xy_m": [[1000, 300], [3500, 300]]},
    "uavs": {
        "start_xy_m": [[800, 900], [1200, 900], [3700, 900], [3300, 900]],
        "altitude_m": 40,
    },
    "targets": [
        {"name": "west", "initial_state": [1000, 1000, 0, 10]},
        {"name": "east", "initial_state": [3500, 1000, 0, 10]},
    ],
    "planner": {"horizon": {"length": 3, "decompose": "targets"}},
}
"""tests/support/two_clusters.py's scene as a mission: two targets 2.5 km apart flying north
at 10 m/s, two UAVs and a BS at each, ten 1 s slots, the horizon decomposed by targets (two
groups of two UAVs every slot), the vehicles flying at 40 m (take-off and landing in seconds)."""


@pytest.fixture
def mission(tmp_path: Path) -> Scenario:
    config = tmp_path / "two-clusters-live.yaml"
    config.write_text(yaml.safe_dump(SCENE))
    return load_scenario(config)


def _options(s: Scenario, out: Path, cluster: PlannerCluster | None = None) -> LiveOptions:
    """`run --lockstep --method horizon --plan-budget 0` on free loopback ports (no budget: a
    plan is checked, not this machine's speed; the cluster's deadline is then 120 s)."""
    return LiveOptions(
        speed=SPEED,
        lockstep=True,
        method="horizon",
        seed=1,
        out_dir=out,
        zenoh_endpoint=tcp_loopback(free_port_block(1, socket.SOCK_STREAM)),
        plan_budget_s=None,
        planner_cluster=cluster,
        **sitl_ports(s.M).world_kwargs(),
    )


async def _fly(
    s: Scenario,
    opts: LiveOptions,
    on_tracks: Callable[[TracksSlot, asyncio.Event], None] | None = None,
    executor: DaskGroupExecutor | None = None,
) -> LiveResult:
    """The mission as `run` flies it (the world beside the service); on_tracks(slot, stop)
    after each slot."""
    stop = asyncio.Event()

    def tracks(o: TracksSlot, _latency_s: float) -> None:
        if on_tracks is not None:
            on_tracks(o, stop)

    world = embedded_world(s, opts)
    flown = run_serve(s, opts, stop, on_tracks=tracks, world=world, executor=executor)
    return await asyncio.wait_for(flown, timeout=MISSION_S)


def _workers() -> list[psutil.Process]:
    """This process's children that multiprocessing spawned (the cluster's worker processes)."""
    return [
        p
        for p in psutil.Process().children(recursive=True)
        if "spawn_main" in " ".join(p.cmdline())
    ]


def _assert_flown(result: LiveResult, s: Scenario) -> list[TracksSlot]:
    """Every slot flown and traced, and every vehicle landed; the slots."""
    slots = result.multi_target_slots
    assert [o.slot for o in slots] == list(range(1, SLOTS + 1)), result.report.counters
    assert not result.interrupted
    assert result.fleet_counters["vehicles landed"] == s.M, result.fleet_counters
    lines = result.trace_path.read_text().splitlines()
    assert len(lines) == SLOTS + 2  # config, the slots, the end
    return slots


def _assert_same_group_plan(a: SlotPlan, b: SlotPlan) -> None:
    """A group's plans equal to the bit (`assert_same_plan`), and no fallback in either."""
    scene.assert_same_plan(a, b)
    assert a.report.fallback == ""


async def test_a_lockstep_mission_on_two_planner_workers_flies_the_serial_missions_plans(
    mission: Scenario, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`--planner-workers 2`: the cluster's worker processes are up while the mission flies
    (every socket on 127.0.0.1) and gone after it; every slot is planned on it, its groups'
    plans are this process's solve of the same jobs to the bit, and the mission's plans are
    the serial mission's slot by slot (slot 1 exactly, then within the runs' spread)."""
    s = mission
    serial = _assert_flown(await _fly(s, _options(s, tmp_path / "serial")), s)

    sent: list[tuple[list[GroupJob], list[SlotPlan]]] = []
    dask_map = DaskGroupExecutor.map

    def recorded(self: DaskGroupExecutor, jobs: Sequence[GroupJob]) -> list[SlotPlan]:
        plans = dask_map(self, jobs)
        sent.append((list(jobs), plans))
        return plans

    monkeypatch.setattr(DaskGroupExecutor, "map", recorded)
    during: dict[str, Any] = {}

    def look(o: TracksSlot, _stop: asyncio.Event) -> None:
        if o.slot == 2:
            during["workers"] = _workers()
            during["hosts"] = listening_hosts()

    opts = _options(s, tmp_path / "cluster", PlannerCluster(workers=2))
    result = await _fly(s, opts, look)
    on_cluster = _assert_flown(result, s)

    workers = during["workers"]
    assert len(workers) >= 2 and during["hosts"] == {"127.0.0.1"}
    _, alive = psutil.wait_procs(workers, timeout=30)
    assert alive == [], "the planner cluster's workers outlived the mission"
    assert result.report.counters[CLUSTER_SLOTS] == SLOTS
    assert result.report.counters[CLUSTER_FALLBACKS] == 0

    assert len(sent) == SLOTS
    for jobs, plans in sent:
        assert len(jobs) == 2 == len(plans)
        for job, plan in zip(jobs, plans, strict=True):
            _assert_same_group_plan(plan, solve_group_job(job))

    for a, b in zip(serial, on_cluster, strict=True):
        for o in (a, b):
            assert o.plan.report.fallback == "", (o.slot, o.plan.report.reason)
            assert o.plan.report.polish.startswith("horizon decomposed into 2 groups")
        if a.slot == 1:
            np.testing.assert_array_equal(a.plan.uav_xy_m, b.plan.uav_xy_m)
            np.testing.assert_array_equal(a.plan.bandwidth_share, b.plan.bandwidth_share)
        gap_m = float(np.max(np.abs(a.plan.uav_xy_m - b.plan.uav_xy_m)))
        gap_eta = float(np.max(np.abs(a.plan.bandwidth_share - b.plan.bandwidth_share)))
        assert gap_m <= POSITION_TOL_M and gap_eta <= SHARE_TOL, (a.slot, gap_m, gap_eta)


class _WorkerDiesInSlot(DaskGroupExecutor):
    """A DaskGroupExecutor whose `kill_at`-th slot's job of group 2 kills its worker process
    (os._exit(1): scene.die_if_flagged, by a flag file set for that slot only)."""

    def __init__(self, client: Client, flag: Path, kill_at: int) -> None:
        super().__init__(client, 60.0, partial(scene.die_if_flagged, str(flag), 1))
        self.flag, self.kill_at, self.calls = flag, kill_at, 0

    def map(self, jobs: Sequence[GroupJob]) -> list[SlotPlan]:
        self.calls += 1
        if self.calls == self.kill_at:
            self.flag.touch()
        try:
            return super().map(jobs)
        finally:
            self.flag.unlink(missing_ok=True)


async def test_a_worker_killed_mid_mission_costs_the_slot_in_flight_only(
    mission: Scenario, tmp_path: Path
) -> None:
    """Slot 5's job of group 2 kills its worker (a real process death): slot 5 flies the
    per-slot plan, fallback `horizon: decomposed worker lost` (KilledWorker), counted in the
    report; the nanny starts a new worker, and every other slot, the last included, is planned
    on the cluster; the fleet lands."""
    s = mission
    kill_at = 5
    with planner_client(None, workers=2) as client:
        before = set(client.run(os.getpid).values())
        executor = _WorkerDiesInSlot(client, tmp_path / "die", kill_at)
        result = await _fly(s, _options(s, tmp_path / "out"), executor=executor)
        client.wait_for_workers(2, timeout=60)
        after = set(client.run(os.getpid).values())
    slots = _assert_flown(result, s)

    lost = [o for o in slots if o.plan.report.fallback]
    assert [o.slot for o in lost] == [kill_at], [(o.slot, o.plan.report.reason) for o in lost]
    (dead,) = lost
    assert dead.plan.report.fallback == WORKER_LOST
    assert "KilledWorker" in dead.plan.report.reason
    assert dead.plan.horizon is None and dead.plan.report.status == "ok"
    for o in slots:
        if o.slot != kill_at:
            assert o.plan.report.polish.startswith("horizon decomposed into 2 groups"), o.slot
    assert executor.failures == 1 and executor.slots == SLOTS - 1
    assert result.report.counters[CLUSTER_FALLBACKS] == 1
    assert result.report.counters[CLUSTER_SLOTS] == SLOTS - 1
    assert len(after - before) == 1, (before, after)  # one worker died and was replaced


async def test_an_interrupted_mission_closes_its_planner_cluster(
    mission: Scenario, tmp_path: Path
) -> None:
    """Stopped after slot 2 (Ctrl-C's stop request): the fleet lands and the cluster the
    mission started is closed, its worker processes gone. Free-running: a world in lockstep
    would hold its clock for the plans the stopped ground loop no longer makes (30 s a slot),
    and the landing with it."""
    s = mission
    during: list[psutil.Process] = []

    def stop_at_2(o: TracksSlot, stop: asyncio.Event) -> None:
        if o.slot == 2:
            during.extend(_workers())
            stop.set()

    opts = _options(s, tmp_path / "out", PlannerCluster(workers=2))
    result = await _fly(s, dataclasses.replace(opts, lockstep=False), stop_at_2)
    assert result.interrupted
    assert result.fleet_counters["vehicles landed"] == s.M
    assert len(during) >= 2
    _, alive = psutil.wait_procs(during, timeout=30)
    assert alive == [], "the planner cluster's workers outlived the mission"
    assert result.report.counters[CLUSTER_FALLBACKS] == 0
