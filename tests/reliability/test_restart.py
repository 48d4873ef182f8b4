"""A true record across starts and stalls, over the real processes (`serve` and `sim`).

- A two-process start: the ground loop plans slot 1 only once every vehicle has reported fresh
  telemetry (ground/startup.py), so slot 1 is planned (`ok`), never `no vehicles`.
- `serve` frozen with SIGSTOP for 5 s of wall time mid-mission, then SIGCONT: the vehicles take
  their offboard-loss hold, the service notices the stall, waits for fresh telemetry, re-enters
  OFFBOARD, traces the slots of the freeze as `held` (where the vehicles really were) and plans
  from where the vehicles are; no plan made before the freeze is applied after it.
Both runs pass the independent checker (14a-14j on telemetry positions at 1 m, PCRB recomputed).
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

from isac_mission.bus import tcp_loopback
from isac_mission.records import Trace, read_trace
from tests.support.independent.constraints import check_constraints
from tests.support.independent.pcrb import compare_pcrb
from tests.support.live_cli import (
    DEFAULT_TRACE,
    serve_argv,
    short_mission,
    sim_argv,
    start,
    wait_for_slots,
)
from tests.support.ports import free_port_block, sitl_ports

TOL_M = 1.0
"""Position tolerance of the check: the vehicles fly a first-order response to the setpoints."""

FREEZE_WALL_S = 5.0
"""How long `serve` is stopped: the fault itself (wall seconds), not a synchronisation."""


def _stop(procs: list[subprocess.Popen[str]]) -> None:
    for p in procs:
        if p.poll() is None:
            p.kill()
            p.wait(timeout=30)


def _finish(serve: subprocess.Popen[str], sim: subprocess.Popen[str]) -> tuple[str, str]:
    """Wait for serve to fly to slot N and land (generous bound), then stop the world."""
    out_text, err_text = serve.communicate(timeout=400)
    assert serve.returncode == 0, err_text[-3000:]
    sim.send_signal(signal.SIGINT)
    _, sim_err = sim.communicate(timeout=60)
    assert sim.returncode == 0, sim_err[-3000:]
    return out_text + err_text, sim_err


def _assert_true_record(trace: Trace, n_slots: int) -> None:
    assert [r.slot for r in trace.slots] == list(range(1, n_slots + 1))
    assert not trace.truncated
    assert [str(v) for v in check_constraints(trace, tol_m=TOL_M)] == []
    assert compare_pcrb(trace) == []


def _launch(
    tmp_path: Path, n_slots: int, *sim_extra: str
) -> tuple[subprocess.Popen[str], subprocess.Popen[str], Path]:
    config = short_mission(tmp_path, n_slots)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    ports = sitl_ports(3)
    out = tmp_path / "serve"
    serve = start(serve_argv(config, out, endpoint, ports.offboard_base))
    sim_cmd = sim_argv(config, endpoint, ports, "--speed", "3", *sim_extra)
    sim = start(sim_cmd, stdout=subprocess.DEVNULL)
    return serve, sim, out / DEFAULT_TRACE


def test_two_process_start_traces_slot_1_as_planned(tmp_path: Path) -> None:
    """`serve` + `sim --start offboard --speed 3 --lockstep`: slot 1 is planned for all three
    vehicles (status ok, a BS each, every detection in), and the whole record checks clean."""
    n_slots = 6
    serve, sim, path = _launch(tmp_path, n_slots, "--lockstep")
    try:
        log_text, _ = _finish(serve, sim)
    finally:
        _stop([serve, sim])
    trace = read_trace(path)
    first = trace.slots[0]
    waited = re.search(r"start: planning again after ([0-9.]+) s", log_text)
    print(f"slot 1: {first.status}; waited {waited.group(1) if waited else '?'} s of wall time")
    assert first.status == "ok", first.reason
    assert all(int(k) >= 0 for k in first.assoc)
    assert first.extra["received"] == 3
    assert "excluded" not in first.extra
    _assert_true_record(trace, n_slots)
    assert re.search(r"vehicle exclusions\s*│", log_text) is None, log_text[-3000:]


@pytest.mark.parametrize(
    "world",
    [("--lockstep", "--lockstep-timeout", "1"), ()],
    ids=["lockstep-1s-timeout", "free-running"],
)
def test_serve_frozen_with_sigstop_holds_then_replans_from_where_the_vehicles_are(
    tmp_path: Path, world: tuple[str, ...]
) -> None:
    """SIGSTOP `serve` for 5 s after a few slots, then SIGCONT. The world keeps running (in
    lockstep with a 1 s timeout, so that its time goes on without plans, or free-running at
    3x): the vehicles take their offboard-loss hold. The slots of the freeze are traced `held` with the positions the
    detections carry; the vehicles are back in OFFBOARD and the mission completes; the record
    checks clean on every slot."""
    n_slots = 24
    serve, sim, path = _launch(tmp_path, n_slots, *world)
    try:
        before = wait_for_slots(path, 6, serve, timeout_s=300)
        os.kill(serve.pid, signal.SIGSTOP)
        time.sleep(FREEZE_WALL_S)  # the fault: 5 s of wall time with the process stopped
        os.kill(serve.pid, signal.SIGCONT)
        log_text, sim_err = _finish(serve, sim)
    finally:
        for p in (serve, sim):
            if p.poll() is None:
                os.kill(p.pid, signal.SIGCONT)
        _stop([serve, sim])
    trace = read_trace(path)
    statuses = {r.slot: r.status for r in trace.slots}
    stall = re.search(r"ground loop stalled for ([0-9.]+) s", log_text)
    waited = re.search(r"stall of [0-9.]+ s: planning again after ([0-9.]+) s", log_text)
    print(
        f"frozen after slot {len(before.slots)}: statuses {statuses}; stall "
        f"{stall.group(1) if stall else '?'} s; replanned after "
        f"{waited.group(1) if waited else '?'} s"
    )
    counters = {
        name: re.search(rf"{name}\s*│\s*(\d+)\s*│", log_text)
        for name in ("plans dropped after a stall", "plans late", "link interruptions")
    }
    print({k: (v.group(1) if v else 0) for k, v in counters.items()})
    assert stall is not None and float(stall.group(1)) >= FREEZE_WALL_S - 0.5, log_text[-3000:]
    held = [n for n, st in statuses.items() if st == "held"]
    assert held, statuses
    assert all(n > len(before.slots) for n in held)
    assert held == list(range(held[0], held[-1] + 1))  # one stretch: the freeze
    assert all(st == "ok" for n, st in statuses.items() if n > held[-1])
    assert "offboard loss" in sim_err, sim_err[-3000:]
    reentries = re.search(r"offboard re-entries\s*│\s*(\d+)\s*│", log_text)
    assert reentries is not None and int(reentries.group(1)) >= 3, log_text[-3000:]
    _assert_true_record(trace, n_slots)
    assert re.search(r"vehicles landed\s*│\s*3\s*│", log_text), log_text[-2000:]
