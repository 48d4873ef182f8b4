"""The operator's priorities (tracking/priorities.py): the table, its weights, the scripted
changes; the scenario's `priorities:` section (config/priorities.py), refused with the field, the
value and the reason where wrong; and the trace's `priority` of each track and `priorities`
(records/tracks.py), written only where a priority is not 1 and read back."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from isac_mission.config import load_scenario, parse_scenario
from isac_mission.errors import ConfigError, MessageError
from isac_mission.model.detections import UavReport
from isac_mission.records.tracks import (
    TracksLine,
    priorities_field,
    read_priorities,
    tracks_fields,
)
from isac_mission.tracking.pcrb import Bound
from isac_mission.tracking.priorities import (
    DEFAULT_PRIORITY,
    Priorities,
    PriorityChange,
    apply_changes,
    scripted_priorities,
)
from isac_mission.tracking.tracker import TrackEstimate
from isac_mission.types import Gaussian

ROOT = Path(__file__).resolve().parents[2]

# --------------------------------------------------------------------------------------------
# The table


def test_every_track_has_the_default_until_set() -> None:
    p = Priorities()
    assert p[1] == p[99] == DEFAULT_PRIORITY == 1.0
    q = p.with_priority(3, 5).with_priority(1, 0.0)
    assert (q[1], q[2], q[3]) == (0.0, 1.0, 5.0)
    assert q.as_dict() == {1: 0.0, 3: 5.0}
    assert p.entries == ()  # the table it came from is unchanged
    # Back at the default, a track is no longer listed: equal tables compare equal.
    assert q.with_priority(3, 1.0) == Priorities.of({1: 0.0})
    assert Priorities.of([(2, 4.0), (1, 2.0)]).entries == ((1, 2.0), (2, 4.0))


@pytest.mark.parametrize(
    ("track", "priority", "message"),
    [
        (3, 12, r"^priority 12 for track 3: a priority is in \[0, 10\]$"),
        (3, -0.5, r"^priority -0.5 for track 3: a priority is in \[0, 10\]$"),
        (2, math.nan, r"^priority nan for track 2: a priority is a finite number in \[0, 10\]$"),
        (2, math.inf, r"^priority inf for track 2: a priority is a finite number"),
        (2, "5", r"^priority '5' for track 2: a priority is a number"),
        (2, True, r"^priority True for track 2: a priority is a number"),
        (0, 1.0, r"^track 0: a track ID is >= 1$"),
        (1.5, 1.0, r"^track 1.5: a track ID is an integer >= 1$"),
    ],
)
def test_a_bad_priority_or_track_is_refused_by_name(
    track: Any, priority: Any, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        Priorities().with_priority(track, priority)
    with pytest.raises(ValueError, match=message):
        Priorities.of({track: priority})


def test_the_bounds_are_priorities() -> None:
    assert Priorities().with_priority(1, 0)[1] == 0.0
    assert Priorities().with_priority(1, 10)[1] == 10.0


@pytest.mark.parametrize(
    ("table", "ids", "weights"),
    [
        ({}, [1, 2, 3], (1.0, 1.0, 1.0)),  # none set: the plain sum
        ({1: 7.0, 2: 7.0}, [1, 2], (1.0, 1.0)),  # equal priorities: the plain sum, exactly
        ({2: 5.0}, [1, 2], (1 / 3, 5 / 3)),  # n p_i / sum p: mean weight 1
        ({1: 3.0, 2: 0.0}, [1, 2, 3], (1.5, 0.0, 0.5)),  # priority 0 weighs 0, the rest mean 1
        ({1: 9.0}, [1], (1.0,)),  # a track planned alone weighs 1 whatever its priority
        ({1: 0.0, 2: 0.0}, [1, 2], (0.0, 0.0)),  # nothing to plan for
        ({}, [], ()),
    ],
)
def test_planning_weights_are_the_priorities_relative_to_each_other(
    table: dict[int, float], ids: list[int], weights: tuple[float, ...]
) -> None:
    got = Priorities.of(table).planning_weights(ids)
    assert got == pytest.approx(weights, rel=1e-15)
    planned = [w for w in got if w > 0]
    if planned:
        assert math.fsum(planned) == pytest.approx(len(planned))
    values = {Priorities.of(table)[i] for i in ids}
    if len(values) == 1 and 0.0 not in values:
        assert all(w == 1.0 for w in got)  # exactly: the objective of before


def test_json_round_trip_and_refusals() -> None:
    p = Priorities.of({4: 2.5, 1: 0.0})
    assert p.to_json() == [{"id": 1, "priority": 0.0}, {"id": 4, "priority": 2.5}]
    assert Priorities.from_json(p.to_json()) == p
    assert Priorities.from_json([]) == Priorities()
    with pytest.raises(ValueError, match=r"priorities: expected a list"):
        Priorities.from_json({"1": 2.0})
    with pytest.raises(
        ValueError, match=r"priorities\[0\]: expected an object with id and priority"
    ):
        Priorities.from_json([{"id": 1}])
    with pytest.raises(ValueError, match=r"priorities\[1\]: priority 11 for track 2"):
        Priorities.from_json([{"id": 1, "priority": 2}, {"id": 2, "priority": 11}])


# --------------------------------------------------------------------------------------------
# The script


def test_changes_apply_from_their_slot_in_the_scripts_order() -> None:
    script = (
        PriorityChange(5, 2, 3.0),
        PriorityChange(2, 1, 0.0),
        PriorityChange(5, 2, 4.0),  # a later one for the same track and slot wins
        PriorityChange(9, 7, 2.0),  # a track that does not exist yet: kept for when it appears
    )
    assert scripted_priorities(script, 1) == Priorities()
    assert scripted_priorities(script, 2) == Priorities.of({1: 0.0})
    assert scripted_priorities(script, 4) == Priorities.of({1: 0.0})
    assert scripted_priorities(script, 5) == Priorities.of({1: 0.0, 2: 4.0})
    assert scripted_priorities(script, 60) == Priorities.of({1: 0.0, 2: 4.0, 7: 2.0})
    # Played on from slot 4, over a table an operator changed since: only slots 5.. apply.
    operator = Priorities.of({1: 6.0})
    assert apply_changes(operator, script, 4, 9) == Priorities.of({1: 6.0, 2: 4.0, 7: 2.0})
    assert apply_changes(operator, script, 9, 60) == operator


@pytest.mark.parametrize(
    ("args", "message"),
    [((0, 1, 1.0), r"slot 0: a priority change's slot is >= 1"), ((3, 1, 10.5), r"priority 10.5")],
)
def test_a_bad_change_is_refused(args: tuple[Any, ...], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PriorityChange(*args)


# --------------------------------------------------------------------------------------------
# The scenario's section


def _paper(**update: Any) -> dict[str, Any]:
    data = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    assert isinstance(data, dict)
    return data | update


def test_the_section_resolves_to_the_script_and_is_traced() -> None:
    s = parse_scenario(
        _paper(
            priorities=[
                {"slot": 12, "track": 2, "weight": 5.0},
                {"slot": 1, "track": 1, "weight": 0},
                {"slot": 60, "track": 1, "weight": 10},
            ]
        )
    )
    assert s.priority_changes == (
        PriorityChange(12, 2, 5.0),
        PriorityChange(1, 1, 0.0),
        PriorityChange(60, 1, 10.0),
    )
    assert s.trace_config()["priorities"] == [
        {"slot": 12, "track": 2, "weight": 5.0},
        {"slot": 1, "track": 1, "weight": 0.0},
        {"slot": 60, "track": 1, "weight": 10.0},
    ]


@pytest.mark.parametrize("name", ["paper", "multi-target", "constrained"])
def test_a_scenario_without_the_section_has_no_script_and_traces_as_before(name: str) -> None:
    s = load_scenario(name)
    assert s.priority_changes == ()
    assert "priorities" not in s.trace_config()


@pytest.mark.parametrize(
    ("entry", "expected"),
    [
        (
            {"slot": 0, "track": 1, "weight": 1},
            "priorities.0.slot: Input should be greater than or",
        ),
        (
            {"slot": 61, "track": 1, "weight": 1},
            "priorities[0].slot: 61 is after the mission's last",
        ),
        ({"slot": 3, "track": 0, "weight": 1}, "priorities.0.track: Input should be greater than"),
        (
            {"slot": 3, "track": 1, "weight": 12},
            "priorities.0.weight: Input should be less than or",
        ),
        (
            {"slot": 3, "track": 1, "weight": -1},
            "priorities.0.weight: Input should be greater than",
        ),
        (
            {"slot": 3, "track": 1, "weight": math.nan},
            "priorities.0.weight: Input should be a finite",
        ),
        ({"slot": 3, "track": 1, "weight": 1, "when": 2}, "priorities.0.when: unknown key"),
        ({"slot": 3, "weight": 1}, "priorities.0.track: Field required"),
    ],
)
def test_a_bad_entry_names_field_value_and_reason(entry: dict[str, Any], expected: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_scenario(_paper(priorities=[{"slot": 2, "track": 1, "weight": 2}, entry]).copy())
    assert expected.replace(".0.", ".1.").replace("[0]", "[1]") in str(err.value)


def test_the_last_slot_is_the_missions() -> None:
    """slot <= N with N from the timing: a 30-slot mission refuses slot 31, takes 30."""
    timing = {"duration_s": 30, "slot_s": 1.0}
    s = parse_scenario(_paper(timing=timing, priorities=[{"slot": 30, "track": 1, "weight": 2}]))
    assert s.N == 30 and s.priority_changes == (PriorityChange(30, 1, 2.0),)
    with pytest.raises(ConfigError, match=r"slot: 31 is after the mission's last slot \(N = 30\)"):
        parse_scenario(_paper(timing=timing, priorities=[{"slot": 31, "track": 1, "weight": 2}]))


# --------------------------------------------------------------------------------------------
# The trace


def _track(track_id: int) -> TrackEstimate:
    P = np.diag([4.0, 4.0, 1.0, 1.0])
    return TrackEstimate(
        track_id, True, Gaussian(np.array([1.0, 2.0, 3.0, 4.0]), P), Bound.from_covariance(P), 2.0
    )


def _line(fields: dict[str, Any]) -> dict[str, Any]:
    empty = UavReport(np.zeros((0, 2)), np.zeros(0, dtype=np.int64))
    return {
        "slot": 4,
        "method": "proposed",
        "status": "ok",
        "uav_xy": [[0.0, 0.0]],
        "eta": [1.0],
        "assoc": [0],
        **fields,
    } | {"measurements": [empty.measurements.tolist()], "origins": [[]]}


def test_each_track_records_its_priority_only_where_it_is_not_one() -> None:
    tracks = (_track(1), _track(2), _track(3))
    truth = np.full((0, 4), np.nan)
    plain = tracks_fields(1, truth, tracks, ())
    assert all("priority" not in t for t in plain["tracks"])  # the lines of before
    assert tracks_fields(1, truth, tracks, (), Priorities()) == plain
    fields = tracks_fields(1, truth, tracks, (), Priorities.of({2: 0.0, 3: 4.5, 9: 2.0}))
    assert [t.get("priority") for t in fields["tracks"]] == [None, 0.0, 4.5]
    line = TracksLine.parse(_line(fields))
    assert [t.priority for t in line.tracks] == [1.0, 0.0, 4.5]
    assert line.priorities() == Priorities.of({2: 0.0, 3: 4.5})
    assert [t.priority for t in TracksLine.parse(_line(plain)).tracks] == [1.0, 1.0, 1.0]


def test_a_bad_recorded_priority_is_refused_by_name() -> None:
    fields = tracks_fields(1, np.full((0, 4), np.nan), (_track(1), _track(2)), ())
    fields["tracks"][1]["priority"] = 12.0
    with pytest.raises(MessageError, match=r"tracks\[1\]\.priority: priority 12 for track 2"):
        TracksLine.parse(_line(fields))


def test_the_resume_field_round_trips() -> None:
    assert priorities_field(None) == priorities_field(Priorities()) == {}
    table = Priorities.of({1: 3.0, 8: 0.0})  # track 8: not there yet
    field = priorities_field(table)
    assert field == {"priorities": [{"id": 1, "priority": 3.0}, {"id": 8, "priority": 0.0}]}
    assert read_priorities({"slot": 3, **field}) == table
    assert read_priorities({"slot": 3}) == Priorities()
    with pytest.raises(MessageError, match=r"slot 3: priorities\[0\]: priority -1 for track 1"):
        read_priorities({"slot": 3, "priorities": [{"id": 1, "priority": -1}]})
