"""A multi-target mission outlives its service: `serve` (the multi-target ground loop and the
bridges) killed with SIGKILL mid-mission while `sim` (its own process, in lockstep) keeps the
vehicles in the air; `serve --resume` continues the trace after its last complete slot, with the
tracker of that slot: every track goes on with its ID (no ID reused, the same targets followed),
the mission completes and lands the fleet, and the trace reads end to end (the single-target
version: test_resume.py)."""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from isac_mission.bus import tcp_loopback
from isac_mission.experiment.plots import read_tracks_trace
from isac_mission.experiment.track_metrics import follow
from isac_mission.records.header import TRACE_FORMAT
from isac_mission.records.progress import TraceProgress, trace_progress
from isac_mission.tracking.gospa import UNASSIGNED
from isac_mission.tracking.pcrb import Bound
from isac_mission.tracking.tracker import TrackEstimate
from isac_mission.types import Gaussian
from tests.support.live_cli import ROOT, serve_argv, sim_argv, start
from tests.support.ports import free_port_block, sitl_ports

pytestmark = pytest.mark.timeout(900)

SLOTS = 24  # the entering target comes in at slot 20, after the resume: a new ID
KILLED_AFTER = 8  # the turning target is confirmed by then (about slot 4)


def _wait_for_slots(path: Path, n: int, proc: subprocess.Popen[str], timeout_s: float) -> None:
    """Poll the multi-target trace (a generous wall bound, not a timing assertion) until it
    holds n complete slots; AssertionError with the process's stderr if it exits first."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            err = proc.stderr.read() if proc.stderr else ""
            raise AssertionError(f"process exited with {proc.returncode}: {err[-3000:]}")
        if path.exists() and trace_progress(path).slots >= n:
            return
        time.sleep(0.2)
    raise AssertionError(f"fewer than {n} slots in {path} after {timeout_s} s")


def _strict_json_lines(path: Path) -> list[dict[str, Any]]:
    """Every line of the file, parsed as strict JSON (no NaN tokens) and newline-terminated."""
    data = path.read_bytes()
    assert data.endswith(b"\n"), "the last line is not terminated"

    def no_constants(token: str) -> object:
        raise AssertionError(f"non-standard JSON constant {token}")

    return [json.loads(line, parse_constant=no_constants) for line in data.decode().splitlines()]


def _followed(line: dict[str, Any]) -> dict[int, int]:
    """Target index -> the ID of the confirmed track following it in a slot line (the metrics'
    rule, experiment/track_metrics.py `follow`)."""
    confirmed = [
        TrackEstimate(
            t["id"],
            True,
            Gaussian(np.asarray(t["x"]), np.asarray(t["P"])),
            Bound.from_covariance(np.asarray(t["P"])),
            t["weight"],
        )
        for t in line["tracks"]
        if t["confirmed"]
    ]
    targets = line["targets"]
    truth = np.array([t["state"][:2] for t in targets]).reshape(-1, 2)
    idx = follow(truth, confirmed)
    return {
        int(t["index"]): confirmed[i].track_id
        for t, i in zip(targets, idx, strict=True)
        if i != UNASSIGNED
    }


def test_serve_killed_mid_mission_resumes_every_track_with_its_id(tmp_path: Path) -> None:
    cfg = yaml.safe_load((ROOT / "config" / "multi-target.yaml").read_text())
    cfg["timing"]["duration_s"] = SLOTS
    cfg["uavs"]["altitude_m"] = 40  # take-off and landing in seconds, not minutes
    config = tmp_path / "multi.yaml"
    config.write_text(yaml.safe_dump(cfg))
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    n_uavs = len(cfg["uavs"]["start_xy_m"])
    ports = sitl_ports(n_uavs)
    out = tmp_path / "serve"
    path = out / "trace_proposed.jsonl"
    serve_cmd = serve_argv(config, out, endpoint, ports.offboard_base)

    first = start(serve_cmd)
    # Lockstep with the default timeout: while no ground is up the world holds its clock.
    sim = start(sim_argv(config, endpoint, ports, "--lockstep"), stdout=subprocess.DEVNULL)
    procs = [first, sim]
    try:
        _wait_for_slots(path, KILLED_AFTER, first, timeout_s=400)
        first.kill()  # SIGKILL: no handler, no flush, no end line, no landing
        first.wait(timeout=30)
        before: TraceProgress = trace_progress(path)
        data = path.read_bytes()
        kept = data[: data.rfind(b"\n") + 1]  # the complete lines (a torn one is cut)
        last = before.last_slot
        assert before.last_line is not None and KILLED_AFTER <= last < SLOTS
        second = start([*serve_cmd, "--resume"])
        procs.append(second)
        # Fail fast (and not only at the end) when the restarted service does not go on.
        _wait_for_slots(path, last + 1, second, timeout_s=120)
        out_text, err_text = second.communicate(timeout=500)
        assert second.returncode == 0, err_text[-3000:]
        sim.send_signal(signal.SIGINT)
        _, sim_err = sim.communicate(timeout=60)
        assert sim.returncode == 0, sim_err[-3000:]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait(timeout=30)

    # The trace reads end to end: the killed run's lines untouched, then every slot once, then
    # the line that says the resumed run ended complete (the killed one wrote none).
    assert path.read_bytes().startswith(kept)
    lines = _strict_json_lines(path)
    assert lines[0]["format"] == TRACE_FORMAT
    slots = [d for d in lines[1:] if "end" not in d]
    assert [d["slot"] for d in slots] == list(range(1, SLOTS + 1))
    assert [d for d in lines if "end" in d] == [lines[-1]]
    assert lines[-1] == {"end": {"status": "complete", "last_slot": SLOTS, "N": SLOTS}}
    config_line, read = read_tracks_trace(path)
    assert len(read) == SLOTS and config_line["N"] == SLOTS
    assert trace_progress(path).last_slot == SLOTS

    statuses = {d["slot"]: d["status"] for d in slots}
    print(f"killed after slot {last}; statuses: {statuses}")
    # The slots the world ran while no ground loop was up: `held` or `unobserved` (nobody knows
    # where the vehicles were: null positions), one stretch right after the kill; planned again
    # after it.
    skipped = [n for n, st in statuses.items() if st in ("held", "unobserved")]
    if skipped:
        assert skipped == list(range(last + 1, skipped[-1] + 1)), statuses
    for d in slots:
        if d["status"] == "unobserved":
            assert all(xy == [None, None] for xy in d["uav_xy"]), d["uav_xy"]
    after = [d for d in slots if d["slot"] > max(skipped, default=last)]
    assert after and all(d["status"] in ("ok", "infeasible") for d in after), statuses

    # Every ID after the resume is a track alive at the kill, or a new one: never one reused.
    at_kill = slots[last - 1]
    alive = {t["id"] for t in at_kill["tracks"]}
    next_id = at_kill["tracker"]["next_id"]
    earlier = {t["id"] for d in slots[:last] for t in d["tracks"]}
    assert max(earlier, default=0) < next_id
    for d in slots[last:]:
        for t in d["tracks"]:
            assert t["id"] in alive or t["id"] >= next_id, (d["slot"], t["id"], alive, next_id)
    new = {t["id"] for d in slots[last:] for t in d["tracks"]} - alive
    print(f"IDs at the kill {sorted(alive)}, next {next_id}; new after the resume {sorted(new)}")
    assert not new or min(new) == next_id  # the next new track takes the ID the kill left
    # The confirmed tracks at the kill go on with their IDs, following the same targets: at the
    # first slot measured after the resume and at the end.
    followed = _followed(at_kill)
    assert followed, f"no target followed at slot {last}: {at_kill['tracks']}"
    resumed = after[0]
    confirmed_then = {t["id"] for t in at_kill["tracks"] if t["confirmed"]}
    assert confirmed_then <= {t["id"] for t in resumed["tracks"] if t["confirmed"]}
    now = _followed(resumed)
    assert {i: now.get(i) for i in followed} == followed, (followed, now, resumed["slot"])
    final = _followed(slots[-1])
    assert {i: final.get(i) for i in followed} == followed, (followed, final)

    assert re.search(rf"vehicles landed\s*│\s*{n_uavs}\s*│", out_text), out_text[-2000:]
    assert not re.search(r"(rejected|internal errors)", out_text), out_text[-3000:]
