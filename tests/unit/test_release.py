"""The release a user runs is named where they meet it: `isac_mission.__version__` (and
`isac-mission --version`, tests/packaging), every trace's config line, the CHANGELOG's section for
it, and each deprecation's warning with the release that removes the old name.
"""

from __future__ import annotations

import dataclasses
import json
import re
import warnings
from pathlib import Path

import pytest

import isac_mission
from isac_mission import wire
from isac_mission.config import load_scenario
from isac_mission.deprecation import REMOVAL_VERSION
from isac_mission.errors import MessageError
from isac_mission.planning.problem import SlotInput
from isac_mission.records import SlotRecord, TraceWriter, read_trace
from isac_mission.records.header import TRACE_FORMAT, VERSION_KEY, parse_header, written_by
from tests.support.trace_files import slot_record

ROOT = Path(__file__).resolve().parents[2]


def _minor_after(version: str) -> str:
    major, minor, _ = (int(p) for p in version.split("."))
    return f"{major}.{minor + 1}.0"


def test_the_version_is_semantic_and_deprecations_go_in_the_next_minor() -> None:
    assert re.fullmatch(r"\d+\.\d+\.\d+", isac_mission.__version__)
    assert REMOVAL_VERSION == _minor_after(isac_mission.__version__)


def test_a_trace_names_the_release_that_wrote_it(tmp_path: Path) -> None:
    """Line 1 carries the package's release beside the format's version; the config is the
    run's alone, so a trace resumes and replays across releases as it did."""
    s = load_scenario("paper")
    config = s.trace_config() | {"seed": 1, "method": "proposed"}
    path = tmp_path / "trace.jsonl"
    with TraceWriter(path, config) as writer:
        writer.write_slot(slot_record(1))
    line_1 = json.loads(path.read_text().splitlines()[0])
    assert line_1["format"] == TRACE_FORMAT
    assert line_1[VERSION_KEY] == isac_mission.__version__
    assert written_by(line_1) == isac_mission.__version__
    assert VERSION_KEY not in line_1["config"]
    back = read_trace(path)
    assert back.config == json.loads(json.dumps(config)) and len(back.slots) == 1
    assert back.written_by == isac_mission.__version__


def test_a_trace_without_the_release_reads_and_a_bad_one_is_refused(tmp_path: Path) -> None:
    config = {"M": 3, "N": 10, "method": "proposed"}
    assert written_by({"format": TRACE_FORMAT, "config": config}) is None
    assert parse_header({"format": TRACE_FORMAT, "config": config}) == (TRACE_FORMAT, config)
    with pytest.raises(MessageError, match="isac_mission_version: 4 is not a version string"):
        parse_header({"format": TRACE_FORMAT, VERSION_KEY: 4, "config": config})
    with pytest.raises(MessageError, match="the first line must be"):
        parse_header({"format": TRACE_FORMAT, VERSION_KEY: "0.4.0", "config": config, "x": 1})


def test_a_renamed_field_warns_and_its_doc_names_the_release_that_removes_it() -> None:
    record = slot_record(1)
    with pytest.warns(
        DeprecationWarning, match="SlotRecord.uav_xy is deprecated: use SlotRecord.uav_xy_m"
    ):
        old = record.uav_xy  # type: ignore[attr-defined]
    assert old is record.uav_xy_m
    with pytest.warns(DeprecationWarning, match="SlotRecord.eta is deprecated"):
        changed = dataclasses.replace(record, eta=record.bandwidth_share * 0.5)  # type: ignore[call-arg]
    assert changed.bandwidth_share[0] == pytest.approx(record.bandwidth_share[0] * 0.5)
    for cls, old_name in ((SlotRecord, "uav_xy"), (SlotRecord, "eta"), (SlotInput, "prev_xy")):
        doc = getattr(cls, old_name).__doc__
        assert doc.startswith(f"Deprecated, removed in {REMOVAL_VERSION}: "), (cls, old_name, doc)


def test_a_deprecated_wire_call_warns_and_its_doc_names_the_release_that_removes_it() -> None:
    msg = wire.ControlMsg(-1, 0.0, "op-1", "hold", uav=1)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert wire.encode_control(msg) == wire.encode(msg)
    assert [str(w.message) for w in caught] == [
        "wire.encode_control is deprecated: use wire.encode"
    ]
    for fn in (wire.encode_control, wire.decode_control_reply):
        assert (fn.__doc__ or "").startswith(f"Deprecated, removed in {REMOVAL_VERSION}: "), fn


def test_the_changelog_lists_what_the_next_minor_removes() -> None:
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    current = text.split(f"## [{isac_mission.__version__}]", 1)[1].split("\n## [", 1)[0]
    deprecated = current.split("### Deprecated", 1)[1].split("\n### ", 1)[0]
    for name in ("target:", "multi_target:", "uav_xy", "encode_control"):
        assert name in deprecated, name
    assert REMOVAL_VERSION in deprecated
