"""The operator's priority of each track: how much the planner cares about it (docs/model.md,
"Planning for several targets").

A priority is a number in [0, MAX_PRIORITY] per track ID, DEFAULT_PRIORITY (1) unless set: 0
means the track is not planned for (it adds nothing to the objective and is never the lead) but
is still kept clear of like every other confirmed track. The planner weighs the confirmed tracks
it plans for by their priorities relative to each other (`planning_weights`: the mean weight is
1, so equal priorities are the paper's plain sum). `Priorities` holds the table (immutable);
`PriorityChange` is one scripted change (the scenario's `priorities:` section) and
`apply_changes` plays a script forward. Pure: no numpy.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

DEFAULT_PRIORITY = 1.0
"""A track's priority until one is set."""

MAX_PRIORITY = 10.0
"""The largest priority."""


def priority_problem(track_id: object, priority: object) -> str | None:
    """What is wrong with giving track `track_id` the priority `priority` (None: nothing), in
    words that name both: "priority 12 for track 3: a priority is in [0, 10]"."""
    if isinstance(track_id, bool) or not isinstance(track_id, int):
        return f"track {track_id!r}: a track ID is an integer >= 1"
    if track_id < 1:
        return f"track {track_id}: a track ID is >= 1"
    if isinstance(priority, bool) or not isinstance(priority, (int, float)):
        return f"priority {priority!r} for track {track_id}: a priority is a number in [0, 10]"
    if not math.isfinite(priority):
        return f"priority {priority} for track {track_id}: a priority is a finite number in [0, 10]"
    if not 0.0 <= priority <= MAX_PRIORITY:
        return f"priority {priority:g} for track {track_id}: a priority is in [0, {MAX_PRIORITY:g}]"
    return None


def checked_priority(track_id: int, priority: float) -> float:
    """`priority` as a float; ValueError with `priority_problem`'s words when it is wrong."""
    problem = priority_problem(track_id, priority)
    if problem is not None:
        raise ValueError(problem)
    return float(priority)


@dataclass(frozen=True)
class Priorities:
    """Track ID -> priority; every track not listed has DEFAULT_PRIORITY. `entries`: the
    listed ones as (track ID, priority) pairs sorted by ID, none at the default (build with
    `of` or `with_priority`, which validate)."""

    entries: tuple[tuple[int, float], ...] = ()

    @classmethod
    def of(cls, table: Mapping[int, float] | Iterable[tuple[int, float]]) -> Priorities:
        """The table track ID -> priority; ValueError naming the first bad entry."""
        items = table.items() if isinstance(table, Mapping) else table
        out = cls()
        for track_id, priority in items:
            out = out.with_priority(track_id, priority)
        return out

    def __getitem__(self, track_id: int) -> float:
        """The priority of track `track_id` (DEFAULT_PRIORITY when not set)."""
        for key, value in self.entries:
            if key == track_id:
                return value
        return DEFAULT_PRIORITY

    def with_priority(self, track_id: int, priority: float) -> Priorities:
        """This table with track `track_id` at `priority`; ValueError (`priority_problem`) when
        it is not a track ID or not a priority."""
        value = checked_priority(track_id, priority)
        kept = {k: v for k, v in self.entries if k != track_id}
        if value != DEFAULT_PRIORITY:
            kept[track_id] = value
        return Priorities(tuple(sorted(kept.items())))

    def as_dict(self) -> dict[int, float]:
        """The tracks whose priority is not the default, ID -> priority."""
        return dict(self.entries)

    def planning_weights(self, track_ids: Sequence[int]) -> tuple[float, ...]:
        """The objective's weight of each of the tracks `track_ids` (docs/model.md, "Planning
        for several targets"): 0 for a track at priority 0; for the others their priorities
        scaled to a mean of 1 (n p_i / sum of the n priorities), so that equal priorities,
        whatever their value, weigh each track 1 (the plain sum of the bounds) and one track
        planned for alone weighs 1 (the paper's objective)."""
        values = [self[t] for t in track_ids]
        planned = [v for v in values if v > 0]
        if not planned:
            return tuple(0.0 for _ in values)
        if all(v == planned[0] for v in planned):
            return tuple(1.0 if v > 0 else 0.0 for v in values)
        scale = len(planned) / math.fsum(planned)
        return tuple(v * scale for v in values)

    def to_json(self) -> list[dict[str, float | int]]:
        """The listed entries as the trace writes them: [{"id", "priority"}, ...]."""
        return [{"id": k, "priority": v} for k, v in self.entries]

    @classmethod
    def from_json(cls, value: object, name: str = "priorities") -> Priorities:
        """The table `to_json` wrote; ValueError naming `name` and the entry at fault."""
        if not isinstance(value, list):
            raise ValueError(f"{name}: expected a list of {{id, priority}} objects")
        out = cls()
        for i, entry in enumerate(value):
            if not isinstance(entry, dict) or set(entry) != {"id", "priority"}:
                raise ValueError(f"{name}[{i}]: expected an object with id and priority")
            try:
                out = out.with_priority(entry["id"], entry["priority"])
            except ValueError as err:
                raise ValueError(f"{name}[{i}]: {err}") from None
        return out


@dataclass(frozen=True)
class PriorityChange:
    """One scripted change: from slot `slot`'s plan on, track `track_id` has `priority` (a
    track that does not exist yet takes it when it appears)."""

    slot: int
    track_id: int
    priority: float

    def __post_init__(self) -> None:
        if isinstance(self.slot, bool) or not isinstance(self.slot, int) or self.slot < 1:
            raise ValueError(f"slot {self.slot!r}: a priority change's slot is >= 1")
        checked_priority(self.track_id, self.priority)


def apply_changes(
    priorities: Priorities,
    changes: Sequence[PriorityChange],
    after_slot: int,
    through_slot: int,
) -> Priorities:
    """`priorities` with the changes of slots after_slot + 1 .. through_slot applied, by slot
    and, within a slot, in the script's order (a later one for the same track wins)."""
    due = [c for c in changes if after_slot < c.slot <= through_slot]
    for c in sorted(due, key=lambda c: c.slot):  # stable: the script's order within a slot
        priorities = priorities.with_priority(c.track_id, c.priority)
    return priorities


def scripted_priorities(changes: Sequence[PriorityChange], slot: int) -> Priorities:
    """The table slot `slot`'s plan is made with when only the script changes priorities."""
    return apply_changes(Priorities(), changes, 0, slot)
