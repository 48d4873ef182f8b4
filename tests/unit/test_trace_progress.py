"""How far a trace got (`records/progress.py`), for a single-target and a multi-target trace
alike: the slots on disk, how the last run ended, a torn last line not counted, the file never
written."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from isac_mission.errors import MessageError
from isac_mission.records import MissionEnd
from isac_mission.records.jsonlines import dumps_line
from isac_mission.records.progress import trace_progress
from tests.support.trace_files import write_multi_target_trace, write_single_target_trace

KINDS = [
    pytest.param("paper", write_single_target_trace, False, id="single-target"),
    pytest.param("multi-target", write_multi_target_trace, True, id="multi-target"),
]


@pytest.mark.parametrize(("scenario", "write", "multi"), KINDS)
def test_the_progress_is_the_last_slot_on_disk(
    tmp_path: Path, scenario: str, write: Callable[..., None], multi: bool
) -> None:
    trace = tmp_path / "trace.jsonl"
    write(trace, scenario, 12)
    before = trace.read_bytes()
    progress = trace_progress(trace)
    assert (progress.slots, progress.last_slot, not progress.labelled) == (12, 12, multi)
    assert progress.config["N"] == 60 and progress.path == trace
    assert progress.end == MissionEnd("interrupted", 12, 60)
    assert trace.read_bytes() == before


@pytest.mark.parametrize(("scenario", "write", "multi"), KINDS)
def test_a_resumed_trace_counts_its_slots_across_the_end_lines_between_runs(
    tmp_path: Path, scenario: str, write: Callable[..., None], multi: bool
) -> None:
    trace = tmp_path / "trace.jsonl"
    write(trace, scenario, 8, killed=True)
    lines = trace.read_bytes().splitlines(keepends=True)
    first_end = (dumps_line(MissionEnd("interrupted", 5, 60).to_dict()) + "\n").encode()
    trace.write_bytes(b"".join([*lines[:6], first_end, *lines[6:]]))  # run 1 stopped after 5
    progress = trace_progress(trace)
    assert (progress.slots, progress.last_slot, progress.end) == (8, 8, None)  # run 2 killed


@pytest.mark.parametrize(("scenario", "write", "multi"), KINDS)
def test_a_torn_last_line_does_not_count(
    tmp_path: Path, scenario: str, write: Callable[..., None], multi: bool
) -> None:
    trace = tmp_path / "trace.jsonl"
    write(trace, scenario, 12, killed=True)
    whole = trace.read_bytes()
    last = whole.rstrip(b"\n").rsplit(b"\n", 1)[1]
    trace.write_bytes(whole + last[: len(last) // 2])  # slot 13, killed mid-line
    assert trace_progress(trace).last_slot == 12


def test_a_file_without_a_complete_line_has_no_slots(tmp_path: Path) -> None:
    trace = tmp_path / "trace.jsonl"
    trace.write_bytes(b'{"config": {"M": 3, "N"')
    progress = trace_progress(trace)
    assert (progress.slots, progress.last_slot) == (0, 0)


def test_slots_out_of_order_name_the_line(tmp_path: Path) -> None:
    trace = tmp_path / "trace.jsonl"
    write_multi_target_trace(trace, "multi-target", 3, killed=True)
    lines = trace.read_bytes().splitlines(keepends=True)
    trace.write_bytes(b"".join([*lines, lines[2]]))  # slot 2 again after slot 3
    with pytest.raises(MessageError, match=r"line 5: slot 2 does not follow slot 3"):
        trace_progress(trace)
