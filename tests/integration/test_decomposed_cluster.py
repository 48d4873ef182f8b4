"""The decomposed horizon's groups solved on a real local Dask cluster of 2 worker processes on
127.0.0.1 (isac_mission/planner_cluster.py, planning/decomposed.py "Where the groups are
solved"): the same plans as the serial path, to the bit, over consecutive slots; a worker
killed mid-slot costs that slot the per-slot plan, and the next slot plans on the cluster
again; a slot past its deadline likewise; `simulate --planner-workers 2` flies the mission the
serial path flies. The serial path itself: tests/numerics/test_decomposed.py."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from distributed import Client
from typer.testing import CliRunner

from isac_mission.cli import app
from isac_mission.model.channel import rate
from isac_mission.planner_cluster import (
    DaskGroupExecutor,
    group_executor,
    is_loopback,
    planner_client,
)
from isac_mission.planning.decomposed import use_group_executor, worker_kit_count
from isac_mission.planning.horizon import proposed_plan
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import plan_slot
from isac_mission.types import SlotPlan
from tests.support import two_clusters as scene
from tests.support.ports import listening_hosts

SLOTS = 4
"""Consecutive slots flown on each path."""

WORKER_LOST = "horizon: decomposed worker lost"


@pytest.fixture(scope="module")
def client() -> Iterator[Client]:
    """A LocalCluster of 2 single-threaded worker processes on 127.0.0.1 (planner_client)."""
    with planner_client(None, workers=2) as c:
        yield c


def _fly(kit: SolverKit, slots: int = SLOTS, manoeuvre: bool = False) -> list[SlotPlan]:
    """`slots` consecutive slots of the two-clusters scene planned with `kit` (`horizon`),
    each flown exactly; manoeuvre: the targets' beliefs carry an IMM path (ImmPath)."""
    s = kit.scenario
    plans: list[SlotPlan] = []
    inp = scene.first_input(s, manoeuvre=manoeuvre)
    for slot in range(1, slots + 1):
        plans.append(plan_slot(inp, kit, "horizon"))
        inp = scene.next_input(s, slot + 1, plans[-1], manoeuvre=manoeuvre)
    return plans


@pytest.mark.timeout(120)
@pytest.mark.parametrize(
    ("vehicle_model", "manoeuvre"),
    [(False, False), (True, False), (False, True)],
    ids=["paper kinematics", "vehicle model", "IMM manoeuvre"],
)
def test_two_workers_plan_every_slot_as_the_serial_path_does(
    client: Client, vehicle_model: bool, manoeuvre: bool
) -> None:
    """Four consecutive slots of two groups of two UAVs: the serial path and the jobs on two
    worker processes give the same plans to the bit (a worker builds the groups' sub-kit once,
    by its fingerprint, and plans every later slot with it: the two groups share one, as in
    the serial path), and every socket of the cluster is on 127.0.0.1. On the paper's
    kinematics, the vehicle model (end velocities), and with targets whose beliefs carry an
    IMM's turning path (TargetBelief.manoeuvre, pickled with the job)."""
    s = scene.scenario(vehicle_model=vehicle_model)
    serial = _fly(SolverKit(s), manoeuvre=manoeuvre)
    assert all(p.report.fallback == "" for p in serial)
    assert all(p.report.polish.startswith("horizon decomposed into 2 groups") for p in serial)

    kits_before = client.run(worker_kit_count)
    executor = DaskGroupExecutor(client, deadline_s=60.0)
    kit = SolverKit(s)
    use_group_executor(kit, executor)
    on_cluster = _fly(kit, manoeuvre=manoeuvre)
    assert executor.slots == SLOTS and executor.failures == 0
    for a, b in zip(serial, on_cluster, strict=True):
        scene.assert_same_plan(a, b)

    # The jobs ran in the worker processes, which built one sub-kit each at most for the four
    # slots (the groups' sub-scenarios differ in their UAVs' start points only; none where an
    # earlier case of the same scenario built it); this process built none.
    kits_after = client.run(worker_kit_count)
    built = {w: n - kits_before[w] for w, n in kits_after.items()}
    pids = set(client.run(os.getpid).values())
    assert len(pids) == 2 and os.getpid() not in pids
    assert sum(kits_after.values()) >= 1 and max(built.values()) <= 1, built
    assert worker_kit_count() == 0

    info = client.scheduler_info()
    assert all(w["nthreads"] == 1 for w in info["workers"].values())
    assert is_loopback(info["address"]) and info["address"].startswith("tcp://127.0.0.1:")
    assert all(a.startswith("tcp://127.0.0.1:") for a in info["workers"])
    assert listening_hosts() == {"127.0.0.1"}


@pytest.mark.timeout(60)
def test_a_scheduler_given_by_its_address_plans_as_the_serial_path(client: Client) -> None:
    """`group_executor(ADDRESS)`: a client of an existing scheduler (here the fixture's, on
    loopback) instead of a cluster of its own; two slots as the serial path plans them."""
    address = client.scheduler_info()["address"]
    assert is_loopback(address) and not is_loopback("tcp://10.1.2.3:8786")
    s = scene.scenario()
    serial = _fly(SolverKit(s), slots=2)
    with group_executor(address, deadline_s=60.0) as executor:
        assert executor.client.scheduler_info()["address"] == address
        kit = SolverKit(s)
        use_group_executor(kit, executor)
        on_scheduler = _fly(kit, slots=2)
    assert executor.slots == 2 and executor.failures == 0
    for a, b in zip(serial, on_scheduler, strict=True):
        scene.assert_same_plan(a, b)


@pytest.mark.timeout(60)
def test_an_operators_new_rate_reaches_the_workers_sub_kits(client: Client) -> None:
    """A fleet kit renewed with 3 R_th (an operator's `set`) plans its groups on the workers
    at that rate (their sub-kits renewed, as the serial path's): the serial path's plan."""
    s = scene.scenario()
    inp = scene.first_input(s)
    kit, serial_kit = SolverKit(s), SolverKit(s)
    use_group_executor(kit, DaskGroupExecutor(client, deadline_s=60.0))
    for k in (kit, serial_kit):
        assert plan_slot(inp, k, "horizon").report.fallback == ""
    faster = s.with_changes(r_th=3 * s.r_th)
    plan = plan_slot(inp, kit.renewed(faster), "horizon")
    assert plan.report.fallback == ""
    scene.assert_same_plan(plan, plan_slot(inp, serial_kit.renewed(faster), "horizon"))
    distance = np.linalg.norm(plan.uav_xy_m - s.bs_xy[plan.bs_of_uav], axis=1)
    assert np.all(rate(plan.bandwidth_share, distance, s.dH, s.rho0, s.B) >= faster.r_th)


@pytest.mark.timeout(120)
def test_a_worker_killed_mid_slot_costs_that_slot_the_per_slot_plan_only(
    client: Client, tmp_path: Path
) -> None:
    """Slot 2's job of group 2 kills its worker process (os._exit(1)). That slot flies the
    centralized per-slot plan with the fallback `horizon: decomposed worker lost` and
    KilledWorker as the reason (the job is not retried on the other worker); the nanny
    starts a new worker, and slots 3 and 4 are planned on the cluster again, as the serial
    path plans them."""
    s = scene.scenario()
    flag = tmp_path / "die"
    executor = DaskGroupExecutor(client, 60.0, partial(scene.die_if_flagged, str(flag), 1))
    kit = SolverKit(s)
    use_group_executor(kit, executor)
    before = client.run(os.getpid)

    first = plan_slot(scene.first_input(s), kit, "horizon")
    assert first.report.fallback == ""
    inp = scene.next_input(s, 2, first)
    flag.touch()
    lost = plan_slot(inp, kit, "horizon")
    flag.unlink()
    assert lost.report.fallback == WORKER_LOST
    assert "KilledWorker" in lost.report.reason
    assert lost.report.reason.startswith("horizon: decomposed: the groups' executor failed")
    assert lost.horizon is None and lost.report.status == "ok"
    per_slot = proposed_plan(inp, SolverKit(s))
    np.testing.assert_array_equal(lost.uav_xy_m, per_slot.uav_xy_m)
    np.testing.assert_array_equal(lost.bandwidth_share, per_slot.bandwidth_share)
    assert executor.failures == 1 and executor.slots == 1

    # The cluster recovers: the nanny restarts the dead worker (a new process).
    client.wait_for_workers(2, timeout=60)
    after = client.run(os.getpid)
    assert len(after) == 2 and len(set(after.values()) - set(before.values())) == 1

    serial_kit = SolverKit(s)
    plan = lost
    for slot in (3, 4):
        inp = scene.next_input(s, slot, plan)
        plan = plan_slot(inp, kit, "horizon")
        assert plan.report.fallback == "", plan.report.reason
        scene.assert_same_plan(plan, plan_slot(inp, serial_kit, "horizon"))
    assert executor.slots == 3 and executor.failures == 1


@pytest.mark.timeout(60)
def test_a_slot_past_its_deadline_flies_the_per_slot_plan(client: Client) -> None:
    """A deadline shorter than any solve: the slot flies the per-slot plan, its reason naming
    the deadline; with the deadline restored the next slot plans on the cluster."""
    s = scene.scenario()
    kit = SolverKit(s)
    executor = DaskGroupExecutor(client, deadline_s=1e-6)
    use_group_executor(kit, executor)
    inp = scene.first_input(s)
    late = plan_slot(inp, kit, "horizon")
    assert late.report.fallback == WORKER_LOST
    assert "TimeoutError" in late.report.reason and "deadline of 1e-06 s" in late.report.reason
    np.testing.assert_array_equal(late.uav_xy_m, proposed_plan(inp, SolverKit(s)).uav_xy_m)
    executor.deadline_s = 60.0
    plan = plan_slot(scene.next_input(s, 2, late), kit, "horizon")
    assert plan.report.fallback == ""
    use_group_executor(kit, None)
    assert plan_slot(inp, kit, "horizon").report.fallback == ""
    assert executor.slots == 1 and executor.failures == 1


TWO_TARGETS = scene.two_targets_config(5)


def _trace_slots(path: Path) -> list[dict[str, Any]]:
    """A trace's slot lines without their plan times."""
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    return [{k: v for k, v in line.items() if k != "solve_ms"} for line in lines if "slot" in line]


@pytest.mark.timeout(120)
def test_simulate_on_two_planner_workers_flies_the_serial_mission(tmp_path: Path) -> None:
    """`simulate --planner-workers 2`: a local cluster on 127.0.0.1, every slot's groups solved
    on it, and the trace the serial run writes (but the plan times); a scenario whose horizon
    is not decomposed is refused before any cluster starts."""
    config = tmp_path / "two.yaml"
    config.write_text(yaml.safe_dump(TWO_TARGETS))
    args = ["simulate", str(config), "--runs", "1", "--methods", "horizon", "--no-plots"]
    env = {"COLUMNS": "200"}
    serial = CliRunner().invoke(
        app, [*args, "--workers", "1", "--out", str(tmp_path / "a")], env=env
    )
    assert serial.exit_code == 0, serial.output
    parallel = CliRunner().invoke(
        app, [*args, "--planner-workers", "2", "--out", str(tmp_path / "b")], env=env
    )
    assert parallel.exit_code == 0, parallel.output
    said = " ".join(parallel.output.split())  # the console wraps at its width
    assert "local cluster of 2 workers on 127.0.0.1" in said
    assert "5 slots' groups solved on it, 0 flew the per-slot plan" in said
    trace = Path("traces") / "horizon_run000.jsonl"
    a, b = _trace_slots(tmp_path / "a" / trace), _trace_slots(tmp_path / "b" / trace)
    assert len(a) == 5 and a == b
    assert not any(line["fallback"] for line in b)

    centralized = dict(TWO_TARGETS, planner={"horizon": {"length": 3}})
    config.write_text(yaml.safe_dump(centralized))
    refused = CliRunner().invoke(app, [*args, "--planner-workers", "2"], env=env)
    assert refused.exit_code == 2
    assert "planner.horizon.decompose: none" in " ".join(refused.output.split())
