"""`serve --resume` on a multi-target mission (docs/service.md, "Several intruders"): what it
refuses, with one line and exit 2 before anything opens, the trace left as it was (a trace
written before resume existed, naming what its line lacks; another mission's, method's or
configuration's trace; a single-target trace; a complete or corrupt one), and what the ground
loop does with a trace it may continue (the last complete slot's tracker, the gate closed for
"resume", a torn last line cut off, the `end` line appended after this run's last slot)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from isac_mission.cli import app
from isac_mission.cli.live import resume_problem
from isac_mission.config import Scenario, load_scenario
from isac_mission.errors import ConfigError
from isac_mission.planning.tracks import multi_target_kit
from isac_mission.records import MissionEnd
from isac_mission.records.header import header_line
from isac_mission.records.jsonlines import dumps_line, loads_line, to_jsonable
from isac_mission.records.progress import trace_progress
from isac_mission.records.tracks import resume_fields, slot_line
from isac_mission.service.assembly import LiveOptions, live_trace_limits, planning_scenario
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.mission import MissionState
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.service.ground.tracefile import live_trace_config
from isac_mission.wire import DetectionSetMsg
from sim.multi_target_scene import MultiTargetScene
from tests.support.ground_steps import plan_slot_of, processed
from tests.support.trace_files import write_multi_target_trace, write_single_target_trace

SCENARIO = "multi-target"
TRACE = "trace_proposed.jsonl"


@pytest.fixture(scope="module")
def multi() -> Scenario:
    return load_scenario(SCENARIO)


def _config(s: Scenario, method: str = "proposed") -> dict[str, object]:
    """The config line `serve` writes for `s` (it plans with the live settings)."""
    planning = planning_scenario(s, LiveOptions())
    return live_trace_config(planning, method, live_trace_limits(s, planning))


def _lines(s: Scenario, slots: int) -> list[str]:
    """The slot lines of a mission of `s` flown `slots` slots (method sd: the fleet parks),
    with what a restart needs (records/tracks.py `resume_fields`)."""
    scene = MultiTargetScene(s, 1)
    mission = MissionState(s, multi_target_kit(s), "sd")
    out = []
    for n in range(1, slots + 1):
        _, plan = plan_slot_of(mission, s.uav_start_xy)
        reports = scene.reports(n, plan.uav_xy_m, plan.bandwidth_share)
        msgs = {
            m: DetectionSetMsg(n, 0.0, m, r.measurements, plan.uav_xy_m[m], plan.bandwidth_share[m])
            for m, r in enumerate(reports)
        }
        o = processed(mission, n, msgs, None, plan.uav_xy_m)
        out.append(slot_line(o, {"latency_ms": 1.0, **resume_fields(o)}))
    return out


def _write(path: Path, config: dict[str, object], lines: list[str], tail: bytes = b"") -> None:
    path.write_bytes(("".join(f"{x}\n" for x in [header_line(config), *lines])).encode() + tail)


def _refused(tmp_path: Path, *, scenario: str = SCENARIO) -> str:
    """`serve SCENARIO --resume` on tmp_path: its one line (exit 2), the trace untouched."""
    trace = tmp_path / TRACE
    before = trace.read_bytes()
    result = CliRunner().invoke(app, ["serve", scenario, "--resume", "--out", str(tmp_path)])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and lines[0].startswith("--resume: "), result.stderr
    assert trace.read_bytes() == before
    return lines[0]


def test_a_trace_written_before_resume_existed_is_refused_naming_what_it_lacks(
    tmp_path: Path,
) -> None:
    write_multi_target_trace(tmp_path / TRACE, SCENARIO, 12)
    line = _refused(tmp_path)
    assert "slot 12's line has no `plan_eta` or `tracker`" in line, line
    assert str(tmp_path / TRACE) in line


@pytest.mark.parametrize(
    ("change", "said"),
    [
        ({"mission_id": "elsewhere"}, "is a trace of mission 'elsewhere', not 'multi-target'"),
        ({"method": "sd"}, "is a trace of method 'sd', not 'proposed'"),
        ({"d_safe": 35.0, "seed": 9}, "another configuration (it differs in d_safe, seed)"),
        ({"targets": []}, "another configuration (it differs in targets)"),
    ],
    ids=["mission", "method", "config", "targets"],
)
def test_another_mission_method_or_configuration_is_refused(
    multi: Scenario, tmp_path: Path, change: dict[str, Any], said: str
) -> None:
    _write(tmp_path / TRACE, _config(multi) | change, _lines(multi, 2))
    line = _refused(tmp_path)
    assert said in line, line


def test_a_single_target_trace_is_refused(tmp_path: Path) -> None:
    write_single_target_trace(tmp_path / TRACE, "paper", 5, killed=True)
    assert "is a single-target trace" in _refused(tmp_path)


def test_a_corrupt_trace_is_refused_naming_the_line(multi: Scenario, tmp_path: Path) -> None:
    _write(tmp_path / TRACE, _config(multi), _lines(multi, 2), b"not json\n")
    line = _refused(tmp_path)
    assert "cannot continue" in line and "line 4" in line, line


def test_the_trace_serve_writes_may_be_resumed(multi: Scenario, tmp_path: Path) -> None:
    trace = tmp_path / TRACE
    _write(trace, _config(multi), _lines(multi, 3))
    assert resume_problem(multi, trace, "proposed") is None
    assert resume_problem(multi, tmp_path / "absent.jsonl", "proposed") is None


# --------------------------------------------------------------------------- the ground loop


def _loop(s: Scenario, path: Path) -> GroundLoop:
    """The serve's multi-target ground loop with `--resume` on `path`, its trace opened (no bus:
    opening the trace does not use it)."""
    planning = planning_scenario(s, LiveOptions())
    settings = GroundSettings(
        trace_path=path,
        resume=True,
        wait_for_telemetry=True,
        trace_config=live_trace_limits(s, planning),
    )
    kit = multi_target_kit(planning)
    loop = GroundLoop(planning, None, settings, kit)  # type: ignore[arg-type]
    loop._open_trace()
    return loop


def test_the_ground_loop_goes_on_after_the_last_complete_slot(
    multi: Scenario, tmp_path: Path
) -> None:
    path = tmp_path / TRACE
    lines = _lines(multi, 4)
    torn = lines[-1].encode()[: len(lines[-1]) // 2]  # slot 4, killed inside its write
    _write(path, _config(multi), lines[:3], torn)
    loop = _loop(multi, path)
    last = json.loads(lines[2])
    st = loop.state
    assert (st.slot, st.pending, st.last_plan) == (3, None, None)
    assert loop.gate.closed and loop.gate.reason == "resume"
    assert [(t.track_id, t.confirmed) for t in st.tracker.saved().tracks] == [
        (t["id"], t["confirmed"]) for t in last["tracks"]
    ]
    assert st.tracker.saved().next_id == last["tracker"]["next_id"]
    np.testing.assert_array_equal(st.eta, last["plan_eta"])
    np.testing.assert_array_equal(st.assoc, last["assoc"])
    # The torn bytes are gone; the file goes on with the next line, then this run's end line.
    assert not path.read_bytes().endswith(torn)
    loop._close_trace()
    text = path.read_text().splitlines()
    assert text[1:4] == lines[:3]
    assert json.loads(text[-1]) == MissionEnd("interrupted", 3, multi.N).to_dict()
    progress = trace_progress(path)
    assert (progress.last_slot, progress.end) == (3, MissionEnd("interrupted", 3, multi.N))


def test_the_ground_loop_refuses_another_configuration_itself(
    multi: Scenario, tmp_path: Path
) -> None:
    """The command line refuses first; a loop opened some other way refuses too."""
    path = tmp_path / TRACE
    _write(path, _config(multi) | {"N": 90}, _lines(multi, 2))
    before = path.read_bytes()
    with pytest.raises(ConfigError, match=r"another configuration \(it differs in N\)"):
        _loop(multi, path)
    assert path.read_bytes() == before


def test_a_trace_killed_before_its_config_line_starts_afresh(
    multi: Scenario, tmp_path: Path
) -> None:
    path = tmp_path / TRACE
    path.write_bytes(b'{"format": "isac-mission multi-target trace 1", "config": {"M"')
    loop = _loop(multi, path)
    assert loop.state.slot == 0 and loop.gate.reason == "start"
    loop._close_trace()
    head = json.loads(path.read_text().splitlines()[0])
    assert head["config"] == loads_line(dumps_line(to_jsonable(_config(multi))))
