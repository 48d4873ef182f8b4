"""The JSON Lines trace: round trip, crash tolerance, corrupt lines, flushing, resuming."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import isac_mission.records.writer as trace_mod
from isac_mission.errors import MessageError
from isac_mission.records import (
    CONTRACT_KEYS,
    SlotRecord,
    TraceWriter,
    read_trace,
)

M = 3


def make_config() -> dict[str, object]:
    return {
        "M": M,
        "K": 2,
        "dt": 1.0,
        "bs_xy": np.array([[0.0, 0.0], [1000.0, 0.0]]),
        "P0": np.diag([100.0, 100.0, 4.0, 4.0]),
        "gamma_th": 12.589254117941675,
        "method": "proposed",
        "nested": {"alpha": np.float64(0.5), "n": np.int64(3)},
    }


def make_record(slot: int, **changes: object) -> SlotRecord:
    rng = np.random.default_rng(slot)
    fields: dict[str, object] = {
        "slot": slot,
        "method": "proposed",
        "status": "ok",
        "uav_xy_m": rng.uniform(0, 3000, size=(M, 2)),
        "bandwidth_share": np.array([0.2, 0.3, 0.5]),
        "assoc": np.array([0, 1, 1]),
        "target_true": rng.uniform(0, 3000, size=4),
        "target_est": rng.uniform(0, 3000, size=4),
        "target_pred": rng.uniform(0, 3000, size=4),
        "r_diag": rng.uniform(1e-20, 1.0, size=2 * M),
        "pcrb_trace": 0.1 / 3.0,
        "solve_ms": 12.5,
        "P": np.eye(4) * 1.0 / 7.0,
        "J": np.eye(4) * 1e20 / 3.0,
    }
    fields.update(changes)
    return SlotRecord(**fields)  # type: ignore[arg-type]


def write_trace(path: Path, n_slots: int) -> list[SlotRecord]:
    records = [make_record(n) for n in range(1, n_slots + 1)]
    with TraceWriter(path, make_config()) as writer:
        for rec in records:
            writer.write_slot(rec)
    return records


def test_round_trip_keeps_every_field_including_nan_and_none(tmp_path: Path) -> None:
    r_diag = np.array([1e-20, np.nan, 3.0, 4.0, np.nan, 6.0])
    rec = make_record(
        1,
        target_true=None,
        r_diag=r_diag,
        pcrb_trace=float("nan"),
        plan_xy=np.ones((M, 2)),
        plan_pcrb_trace=2.5,
        reason="14h and 14j conflict",
        status="infeasible",
        extra={"objective_history": np.array([3.0, 2.0, np.inf]), "iterations": np.int64(4)},
    )
    path = tmp_path / "run.jsonl"
    with TraceWriter(path, make_config()) as writer:
        writer.write_slot(rec)
        writer.write_slot(make_record(2))
    back = read_trace(path)
    assert back.config["bs_xy"] == [[0.0, 0.0], [1000.0, 0.0]]
    assert back.config["nested"] == {"alpha": 0.5, "n": 3}
    assert back.method == "proposed"
    assert not back.truncated
    assert [r.slot for r in back.slots] == [1, 2]
    got = back.slots[0]
    assert got == rec
    assert got.target_true is None
    np.testing.assert_array_equal(got.r_diag, r_diag)  # NaN positions survive
    assert math.isnan(got.pcrb_trace)
    assert got.reason == "14h and 14j conflict"
    assert got.extra == {"objective_history": [3.0, 2.0, None], "iterations": 4}
    assert back.slots[1] == make_record(2)
    # floats survive bit for bit (1/3, 1e20/3)
    assert got.J[0, 0] == rec.J[0, 0]
    assert got.P[1, 1] == 1.0 / 7.0


def test_file_is_strict_json_with_null_for_missing_numbers(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    rec = make_record(1, r_diag=np.array([1.0, np.nan, 1.0, 1.0, 1.0, np.inf]), target_true=None)
    with TraceWriter(path, make_config()) as writer:
        writer.write_slot(rec)
    lines = path.read_text().splitlines()
    assert len(lines) == 2
    assert list(json.loads(lines[0])) == ["format", "isac_mission_version", "config"]
    assert "NaN" not in lines[1] and "Infinity" not in lines[1]
    slot = json.loads(lines[1], parse_constant=lambda c: pytest.fail(f"token {c}"))
    assert list(slot)[: len(CONTRACT_KEYS)] == list(CONTRACT_KEYS)
    assert slot["r_diag"][1] is None and slot["r_diag"][5] is None
    assert slot["target_true"] is None
    assert slot["assoc"] == [0, 1, 1]


def test_truncated_last_line_is_dropped_and_flagged(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    records = write_trace(path, 3)
    partial = json.dumps(make_record(4).to_dict())[:57]
    with path.open("a") as f:
        f.write(partial)
    back = read_trace(path)
    assert back.truncated
    assert back.slots == records


def test_corrupt_middle_line_raises_naming_the_line(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    write_trace(path, 4)
    lines = path.read_text().splitlines(keepends=True)
    lines[2] = lines[2][:40] + "\n"  # slot 2 is on line 3
    path.write_text("".join(lines))
    with pytest.raises(MessageError, match=r"line 3:"):
        read_trace(path)


def test_wrong_shape_in_a_line_raises_naming_line_and_field(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    write_trace(path, 2)
    lines = path.read_text().splitlines(keepends=True)
    obj = json.loads(lines[1])
    obj["P"] = [[1.0, 0.0], [0.0, 1.0]]
    lines[1] = json.dumps(obj) + "\n"
    path.write_text("".join(lines))
    with pytest.raises(MessageError, match=r"line 2: P: expected shape \[4, 4\]"):
        read_trace(path)


def test_nan_token_in_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    write_trace(path, 2)
    text = path.read_text().replace('"solve_ms":12.5', '"solve_ms":NaN', 1)
    path.write_text(text)
    with pytest.raises(MessageError, match=r"line 2: non-standard JSON constant NaN"):
        read_trace(path)


def test_out_of_order_slot_is_refused_by_writer_and_reader(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    with TraceWriter(path, make_config()) as writer:
        writer.write_slot(make_record(2))
        with pytest.raises(MessageError, match="does not follow slot 2"):
            writer.write_slot(make_record(2))
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join([*lines, lines[1]]))
    with pytest.raises(MessageError, match=r"line 3: slot 2 does not follow slot 2"):
        read_trace(path)


def test_record_with_other_m_than_config_is_refused(tmp_path: Path) -> None:
    rec = make_record(
        1, uav_xy_m=np.zeros((2, 2)), bandwidth_share=[0.5, 0.5], assoc=[0, 1], r_diag=np.ones(4)
    )
    with (
        TraceWriter(tmp_path / "run.jsonl", make_config()) as writer,
        pytest.raises(MessageError, match="config M is 3"),
    ):
        writer.write_slot(rec)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"bandwidth_share": [0.5, 0.5]}, r"eta: expected shape \[3\]"),
        ({"assoc": [0, 1.5, 1]}, r"assoc\[1\]: expected an integer"),
        ({"r_diag": np.ones(3)}, r"r_diag: expected shape \[6\]"),
        ({"uav_xy_m": [[1, 2], [3, "x"], [5, 6]]}, r"uav_xy: expected numbers"),
        ({"extra": {"J": 1}}, r"extra: keys \['J'\] are reserved"),
        ({"status": 3}, r"status: expected a string"),
        ({"pcrb_trace": "1"}, r"pcrb_trace: expected a number or null"),
    ],
)
def test_malformed_record_raises_naming_the_field(change: dict[str, object], message: str) -> None:
    with pytest.raises(MessageError, match=message):
        make_record(1, **change)


def test_each_slot_is_on_disk_right_after_write_slot(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    writer = TraceWriter(path, make_config())
    try:
        assert len(path.read_text().splitlines()) == 1
        for n in (1, 2, 3):
            writer.write_slot(make_record(n))
            # another reader sees the slot while the writer is still open
            assert [r.slot for r in read_trace(path).slots] == list(range(1, n + 1))
    finally:
        writer.close()
    assert writer.closed


def test_fsync_flag_syncs_every_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[int] = []
    monkeypatch.setattr(trace_mod.os, "fsync", lambda fd: calls.append(fd))
    with TraceWriter(tmp_path / "a.jsonl", make_config(), fsync=True) as writer:
        writer.write_slot(make_record(1))
        writer.write_slot(make_record(2))
    assert len(calls) == 3  # config line + 2 slots
    calls.clear()
    with TraceWriter(tmp_path / "b.jsonl", make_config()) as writer:
        writer.write_slot(make_record(1))
    assert calls == []


def test_resume_drops_partial_line_and_appends_cleanly(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    records = write_trace(path, 2)
    with path.open("a") as f:
        f.write(json.dumps(make_record(3).to_dict())[:80])  # killed while writing slot 3
    with TraceWriter.resume(path) as writer:
        assert writer.last_record == records[-1]
        assert writer.config["M"] == M
        np.testing.assert_array_equal(writer.last_record.J, records[-1].J)  # type: ignore[union-attr]
        with pytest.raises(MessageError, match="does not follow"):
            writer.write_slot(make_record(2))
        writer.write_slot(make_record(3))
        writer.write_slot(make_record(4))
        assert writer.slots_written == 2
    back = read_trace(path)
    assert not back.truncated
    assert [r.slot for r in back.slots] == [1, 2, 3, 4]
    assert back.slots[2] == make_record(3)


def test_resume_keeps_a_complete_last_line_without_newline(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    write_trace(path, 2)
    path.write_bytes(path.read_bytes().rstrip(b"\n"))
    assert [r.slot for r in read_trace(path).slots] == [1, 2]
    with TraceWriter.resume(path) as writer:
        writer.write_slot(make_record(3))
    assert [r.slot for r in read_trace(path).slots] == [1, 2, 3]


def test_resume_of_a_corrupt_trace_raises(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    write_trace(path, 3)
    lines = path.read_text().splitlines(keepends=True)
    lines[1] = "{not json}\n"
    path.write_text("".join(lines))
    with pytest.raises(MessageError, match="line 2"):
        TraceWriter.resume(path)


def test_empty_or_config_less_file_raises(tmp_path: Path) -> None:
    empty = tmp_path / "empty.jsonl"
    empty.write_text("")
    with pytest.raises(MessageError, match="no config line"):
        read_trace(empty)
    half = tmp_path / "half.jsonl"
    half.write_text('{"config": {"M": 3')
    with pytest.raises(MessageError, match="line 1: incomplete config line"):
        read_trace(half)
    wrong = tmp_path / "wrong.jsonl"
    wrong.write_text('{"slot": 1}\n')
    with pytest.raises(MessageError, match=r"line 1: the first line must be"):
        read_trace(wrong)


def test_stack_gives_per_slot_arrays(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    records = write_trace(path, 3)
    back = read_trace(path)
    assert back.stack("uav_xy").shape == (3, M, 2)
    np.testing.assert_array_equal(back.stack("pcrb_trace"), [r.pcrb_trace for r in records])
    assert back.stack("plan_xy").shape == (3, M, 2)
    assert np.isnan(back.stack("plan_xy")).all()


def test_an_interrupted_run_says_so_and_a_resumed_one_reads_through_it(tmp_path: Path) -> None:
    """A live run that stops before slot N ends its trace with `{"end": {"status":
    "interrupted", "last_slot": k, "N": N}}`; the reader keeps the slots, the ends in order,
    and says how the last run ended only when nothing was traced after its end line."""
    from isac_mission.records import MissionEnd

    path = tmp_path / "run.jsonl"
    write_trace(path, 2)
    with TraceWriter.resume(path) as writer:
        writer.write_end(MissionEnd("interrupted", 2, 5))
    first = read_trace(path)
    assert [r.slot for r in first.slots] == [1, 2]
    assert first.end == MissionEnd("interrupted", 2, 5)
    assert json.loads(path.read_text().splitlines()[-1]) == {
        "end": {"status": "interrupted", "last_slot": 2, "N": 5}
    }
    with TraceWriter.resume(path) as writer:
        assert writer.last_record is not None and writer.last_record.slot == 2
        writer.write_slot(make_record(3))
    resumed = read_trace(path)
    assert [r.slot for r in resumed.slots] == [1, 2, 3]
    assert resumed.ends == [MissionEnd("interrupted", 2, 5)] and resumed.end is None
    with path.open("a") as f:
        f.write('{"end": {"status": "paused", "last_slot": 3, "N": 5}}\n')
    with pytest.raises(MessageError, match=r"line 6: end\.status: 'paused'"):
        read_trace(path)
