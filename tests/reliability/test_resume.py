"""Nothing lost: a killed service leaves every completed slot readable, and a restarted one
continues after the last of them from its `P`, `J` and estimate.

- A torn last line (the writer was killed inside `write`) is dropped by the reader and cut off
  by `TraceWriter.resume`, wherever the cut falls; the trace stays strict JSON Lines.
- `GroundLoop` opened with `resume=True` on such a trace starts from its last complete slot.
- In-process: a ground loop that stopped after slot L and a new one that resumes it, the world
  running on in lockstep, give one trace with every slot exactly once.
- End to end: `isac-mission serve` killed with SIGKILL mid-mission while `isac-mission sim` (its
  own process) keeps running; the vehicles hold (offboard-loss failsafe, then the datalink-loss
  one); `serve --resume` re-attaches to the airborne vehicles, continues at slot L+1 and lands
  them at the end.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import re
import signal
import socket
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

import isac_mission.records.writer as trace_mod
from isac_mission import __version__
from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import Scenario
from isac_mission.errors import MessageError
from isac_mission.planning.kit import SolverKit
from isac_mission.records import TRACE_FORMAT, SlotRecord, Trace, TraceWriter, read_trace
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.service.ground.tracefile import RecordOutput
from isac_mission.tracking.cycle import TrackState
from sim.world import run_world
from sim.world_options import WorldOptions
from tests.support.independent.constraints import check_constraints
from tests.support.independent.pcrb import bound_update, compare_pcrb, cv_model, jacobian
from tests.support.live_cli import DEFAULT_TRACE, serve_argv, sim_argv, start, wait_for_slots
from tests.support.ports import free_port_block, sitl_ports
from tests.support.trace_files import slot_record

ROOT = Path(__file__).resolve().parents[2]


# --------------------------------------------------------------------------- helpers


def _write(path: Path, config: dict[str, object], slots: range) -> list[SlotRecord]:
    records = [slot_record(n, int(config["M"])) for n in slots]  # type: ignore[call-overload]
    with TraceWriter(path, config, fsync=True) as w:
        for r in records:
            w.write_slot(r)
    return records


def _strict_json_lines(path: Path) -> list[dict[str, object]]:
    """Every line of the file parsed as strict JSON (no NaN tokens), and newline-terminated."""
    data = path.read_bytes()
    assert data.endswith(b"\n"), "the last line is not terminated"

    def no_constants(token: str) -> object:
        raise AssertionError(f"non-standard JSON constant {token}")

    return [json.loads(line, parse_constant=no_constants) for line in data.decode().splitlines()]


def _assert_every_slot_once(trace: Trace, n_slots: int) -> None:
    slots = [r.slot for r in trace.slots]
    assert slots == list(range(1, n_slots + 1)), f"slots in the trace: {slots}"
    assert not trace.truncated


def _assert_continues_from(trace: Trace, last: SlotRecord, dt: float, kappa: float) -> None:
    """Slot last+1 was computed from `last`'s estimate, P and J (the recursions of docs/model.md)."""
    nxt = next(r for r in trace.slots if r.slot == last.slot + 1)
    F, W = cv_model(dt, kappa)
    x_pred = F @ np.asarray(last.target_est)
    np.testing.assert_allclose(nxt.target_pred, x_pred, rtol=1e-9, atol=1e-9)
    P_pred = F @ np.asarray(last.P) @ F.T + W
    r = np.asarray(nxt.r_diag)
    H = jacobian(np.asarray(nxt.target_pred), np.asarray(nxt.uav_xy_m))
    keep = np.isfinite(r)
    info = np.linalg.inv(P_pred) + H[keep].T @ np.diag(1.0 / r[keep]) @ H[keep]
    # A one-iteration EKF's posterior information is the prediction's plus H^T R^-1 H.
    np.testing.assert_allclose(np.linalg.inv(np.asarray(nxt.P)), info, rtol=1e-6, atol=1e-9)
    _, J_next = bound_update(np.linalg.inv(np.asarray(last.J)), F, W, H, r)
    np.testing.assert_allclose(nxt.J, J_next, rtol=1e-6, atol=1e-12)


# --------------------------------------------------------------------------- torn lines


@pytest.mark.parametrize("cut", [1, 17, 0.5, 0.9, -1])
def test_torn_last_line_is_dropped_and_the_resumed_trace_is_clean_json_lines(
    tmp_path: Path, cut: float
) -> None:
    """Killed inside write(): the partial line is dropped on reading, cut off on resume, and
    the next slot is appended on a line of its own; every line is strict JSON afterwards."""
    path = tmp_path / "trace.jsonl"
    config: dict[str, object] = {"M": 3, "N": 10, "method": "proposed"}
    records = _write(path, config, range(1, 5))
    line = json.dumps(slot_record(5).to_dict(), separators=(",", ":")).encode()
    n = int(cut * len(line)) if isinstance(cut, float) else cut
    with path.open("ab") as f:
        f.write(line[:n])  # n < len(line): the closing brace is missing
    torn = read_trace(path)
    assert torn.truncated
    assert [r.slot for r in torn.slots] == [1, 2, 3, 4]
    with TraceWriter.resume(path, fsync=True) as w:
        assert w.last_record == records[-1]
        w.write_slot(slot_record(5))
        w.write_slot(slot_record(6))
    back = read_trace(path)
    _assert_every_slot_once(back, 6)
    assert back.slots[4] == slot_record(5)
    lines = _strict_json_lines(path)
    assert lines[0] == {
        "format": TRACE_FORMAT,
        "isac_mission_version": __version__,
        "config": config,
    }
    assert [ln["slot"] for ln in lines[1:]] == [1, 2, 3, 4, 5, 6]


def test_torn_multibyte_character_in_the_last_line_is_dropped(tmp_path: Path) -> None:
    """A cut inside a UTF-8 sequence (a reason text with a non-ASCII character)."""
    path = tmp_path / "trace.jsonl"
    _write(path, {"M": 3}, range(1, 3))
    rec = SlotRecord.from_dict(
        slot_record(3).to_dict() | {"status": "infeasible", "reason": "d ≥ D_s"}
    )
    line = json.dumps(rec.to_dict(), ensure_ascii=False, separators=(",", ":")).encode()
    cut = line.index("≥".encode()) + 1  # inside the three-byte character
    with path.open("ab") as f:
        f.write(line[:cut])
    assert [r.slot for r in read_trace(path).slots] == [1, 2]
    with TraceWriter.resume(path) as w:
        w.write_slot(rec)
    assert [r.slot for r in read_trace(path).slots] == [1, 2, 3]
    _strict_json_lines(path)


def test_resumed_ground_loop_starts_from_the_last_complete_slot(
    paper: Scenario, tmp_path: Path
) -> None:
    """GroundLoop(resume=True) on a trace with a torn last line: the state is the last complete
    slot's (slot, estimate, P, J, shares, association), and the torn bytes are gone."""
    path = tmp_path / "trace_proposed.jsonl"
    records = _write(path, paper.trace_config() | {"method": "proposed"}, range(1, 8))
    with path.open("ab") as f:
        f.write(json.dumps(slot_record(8).to_dict()).encode()[:200])
    size_torn = path.stat().st_size
    loop = _resumed_loop(paper, path)
    try:
        last = records[-1]
        st = loop.state
        assert st.slot == 7 and st.pending is None and not st.done
        track = st.tracker.saved()
        assert isinstance(track, TrackState)
        np.testing.assert_array_equal(track.belief.x, last.target_est)
        np.testing.assert_array_equal(track.belief.P, last.P)
        np.testing.assert_allclose(track.bound.J, last.J, rtol=1e-12)
        np.testing.assert_array_equal(st.eta, last.bandwidth_share)
        np.testing.assert_array_equal(st.assoc, last.assoc)
    finally:
        _writer(loop).close()
    assert path.stat().st_size < size_torn
    assert [r.slot for r in read_trace(path).slots] == list(range(1, 8))
    _strict_json_lines(path)


def test_resumed_ground_loop_fsyncs_every_slot(
    paper: Scenario, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "trace_proposed.jsonl"
    records = _write(path, paper.trace_config() | {"method": "proposed"}, range(1, 4))
    loop = GroundLoop(
        paper,
        None,  # type: ignore[arg-type]
        GroundSettings(trace_path=path, resume=True),
        SolverKit(paper),
    )
    loop._open_trace()
    synced: list[int] = []
    monkeypatch.setattr(trace_mod.os, "fsync", lambda fd: synced.append(fd))
    writer = _writer(loop)
    try:
        writer.write_slot(dataclasses.replace(records[-1], slot=4))
    finally:
        writer.close()
    assert synced, "the slot written after the resume was not fsynced"


# --------------------------------------------------------------------------- in process


async def _ground(s: Scenario, bus: ZenohBus, path: Path, resume: bool, timeout_s: float) -> int:
    loop = GroundLoop(s, bus, GroundSettings(trace_path=path, resume=resume))
    report = await asyncio.wait_for(loop.run(asyncio.Event()), timeout=timeout_s)
    return report.counters["slots"]


async def test_restarted_ground_loop_continues_with_the_next_slot(
    paper: Scenario, free_tcp_port: int, tmp_path: Path
) -> None:
    """The world (lockstep) waits at slot L for plan L+1; the first loop ends after slot L; a
    second loop resumes the trace, plans L+1 and flies to N: every slot once, slot L+1 computed
    from slot L's estimate, P and J, and the bound recursion unbroken (independent recompute)."""
    n_total, n_first = 8, 4
    world_s = dataclasses.replace(paper, N=n_total)
    endpoint = tcp_loopback(free_tcp_port)
    path = tmp_path / "trace_proposed.jsonl"
    opts = WorldOptions(
        speed=50.0,
        lockstep=True,
        lockstep_timeout_s=60.0,
        bus=BusSettings(connect=(endpoint,)),
        **sitl_ports(3).world_kwargs(),  # free ports, not PX4's own
        seed=3,
    )
    stop_world = asyncio.Event()
    with ZenohBus.open(BusSettings.hub(endpoint)) as bus:
        world = asyncio.create_task(run_world(world_s, opts, stop_world))
        try:
            first = dataclasses.replace(paper, N=n_first)
            assert await _ground(first, bus, path, resume=False, timeout_s=120) == n_first
            last = read_trace(path).slots[-1]
            assert last.slot == n_first
            done = await _ground(world_s, bus, path, resume=True, timeout_s=30)
            assert done == n_total - n_first
        finally:
            stop_world.set()
            await asyncio.wait_for(world, timeout=30)
    trace = read_trace(path)
    _assert_every_slot_once(trace, n_total)
    _assert_continues_from(trace, last, paper.dt, paper.kappa)
    assert trace.slots[n_first].extra["received"] == paper.M  # slot L+1 was fully measured
    assert compare_pcrb(trace) == []
    _strict_json_lines(path)


# --------------------------------------------------------------------------- end to end


@pytest.mark.parametrize(
    "lockstep", [("--lockstep-timeout", "3"), ()], ids=["3s-timeout", "default-timeout"]
)
def test_serve_killed_with_sigkill_resumes_and_completes_the_mission(
    tmp_path: Path, lockstep: tuple[str, ...]
) -> None:
    """serve + sim as two processes; SIGKILL the serve after a few slots; `serve --resume`
    continues from the trace's last complete slot (L+1 first, computed from L's estimate, P and
    J), re-attaches to the vehicles holding in the air, flies to slot N and lands them. The
    world runs in lockstep: with a short timeout, while no ground is up it moves on one slot per
    timeout, and those slots are traced `unobserved` (or `held`), not skipped; with the default
    (30 s) it holds its clock, and its vehicles send only heartbeats: the new bridges ask each
    for its position (REQUEST_MESSAGE), so the resumed loop plans at once."""
    cfg = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    n_slots = 24
    cfg["timing"]["duration_s"] = n_slots
    cfg["uavs"]["altitude_m"] = 40  # take-off and landing in seconds, not minutes
    config = tmp_path / "resume.yaml"
    config.write_text(yaml.safe_dump(cfg))
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    ports = sitl_ports(3)
    out = tmp_path / "serve"
    path = out / DEFAULT_TRACE
    serve_cmd = serve_argv(config, out, endpoint, ports.offboard_base)

    def start_serve(*extra: str) -> subprocess.Popen[str]:
        return start([*serve_cmd, *extra])

    first = start_serve()
    sim = start(
        sim_argv(config, endpoint, ports, "--lockstep", *lockstep),
        stdout=subprocess.DEVNULL,
    )
    procs = [first, sim]
    try:
        wait_for_slots(path, 6, first, timeout_s=240)
        first.kill()  # SIGKILL: no handler, no flush, no landing
        first.wait(timeout=30)
        before = read_trace(path)
        last = before.slots[-1]
        assert [r.slot for r in before.slots] == list(range(1, last.slot + 1))
        assert last.slot < n_slots
        second = start_serve("--resume")
        procs.append(second)
        # Fail fast (and not only at the end) when the restarted service does not go on.
        wait_for_slots(path, last.slot + 1, second, timeout_s=60)
        out_text, err_text = second.communicate(timeout=240)
        assert second.returncode == 0, err_text[-3000:]
        sim.send_signal(signal.SIGINT)
        _, sim_err = sim.communicate(timeout=60)
        assert sim.returncode == 0, sim_err[-3000:]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait(timeout=30)
    trace = read_trace(path)
    received = {r.slot: r.extra.get("received") for r in trace.slots}
    statuses = {r.slot: r.status for r in trace.slots}
    print(f"killed after slot {last.slot}; detections received per slot: {received}")
    print(f"statuses: {statuses}")
    _assert_every_slot_once(trace, n_slots)
    # The file still starts with the first run's config line, then every slot once.
    lines = _strict_json_lines(path)
    # ... and the line that says the resumed run ended complete (the killed one wrote none).
    assert lines[-1] == {"end": {"status": "complete", "last_slot": n_slots, "N": n_slots}}
    assert "config" in lines[0] and [ln["slot"] for ln in lines[1:-1]] == list(
        range(1, n_slots + 1)
    )
    for a, b in zip(before.slots, trace.slots, strict=False):
        assert a == b  # the completed slots are untouched
    s_dt, s_kappa = float(trace.config["dt"]), float(trace.config["kappa"])
    _assert_continues_from(trace, last, s_dt, s_kappa)
    assert compare_pcrb(trace) == []
    # A true record (docs/trace.md, "Statuses"): slot 1 planned; the slots the world ran while
    # no ground loop was up are `unobserved` (nothing arrived: positions null) or `held` (the
    # detections' positions), never the last plan's positions; then planned again. The whole
    # trace passes 14a-14j on those positions at 1 m.
    assert trace.slots[0].status == "ok"
    for r in trace.slots[last.slot :]:
        if r.status == "unobserved":
            assert r.extra.get("received") == 0 and np.isnan(np.asarray(r.uav_xy_m)).all()
    skipped = [n for n, st in statuses.items() if st in ("unobserved", "held")]
    if skipped:  # none when the new `serve` was up before the world's lockstep timeout
        assert skipped == list(range(last.slot + 1, skipped[-1] + 1)), statuses
    assert all(st == "ok" for n, st in statuses.items() if n > max(skipped, default=0)), statuses
    assert [str(v) for v in check_constraints(trace, tol_m=1.0)] == []
    assert re.search(r"vehicles landed\s*│\s*3\s*│", out_text), out_text[-2000:]
    # Back to measuring: the last slots got every detection.
    assert all(r.extra.get("received") == 3 for r in trace.slots[-3:])


@pytest.mark.parametrize("torn_header", [b"", b'{"config": {"M": 3, "K"'])
def test_resume_of_a_trace_killed_before_its_config_line_starts_afresh(
    paper: Scenario, tmp_path: Path, torn_header: bytes
) -> None:
    """Killed before the config line was complete: no slot can be lost, so `--resume` starts a
    new trace (it used to raise, and the restarted service did not run)."""
    path = tmp_path / "trace_proposed.jsonl"
    path.write_bytes(torn_header)
    loop = _resumed_loop(paper, path)
    writer = _writer(loop)
    writer.write_slot(slot_record(1))
    writer.close()
    assert loop.state.slot == 0
    trace = read_trace(path)
    assert trace.config["method"] == "proposed" and [r.slot for r in trace.slots] == [1]
    # A trace with a complete but corrupt first line is not overwritten.
    path.write_bytes(b"not json\n")
    with pytest.raises(MessageError):
        _resumed_loop(paper, path)


def _writer(loop: GroundLoop) -> TraceWriter:
    """The loop's trace writer (a labelled target's trace)."""
    assert isinstance(loop.output, RecordOutput) and loop.output.writer is not None
    return loop.output.writer


def _resumed_loop(s: Scenario, path: Path) -> GroundLoop:
    """A GroundLoop(resume=True) on `path` with its trace opened (no bus: _open_trace does not
    use it)."""
    loop = GroundLoop(
        s,
        None,  # type: ignore[arg-type]
        GroundSettings(trace_path=path, resume=True),
        SolverKit(s),
    )
    loop._open_trace()
    return loop
