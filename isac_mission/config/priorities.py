"""The scenario's scripted priority changes (`priorities:`): from a given slot's plan on, a track
has another priority (docs/model.md, "Planning for several targets"; tracking/priorities.py).

    priorities:
      - {slot: 12, track: 2, weight: 5.0}   # from slot 12's plan on, track 2 weighs 5
      - {slot: 30, track: 1, weight: 0}     # from slot 30 on, track 1 is not planned for

`slot` is 1..N (checked against N when the scenario is resolved), `track` a track ID (the
labelled target is track 1; a track that does not exist yet takes its priority when it
appears), `weight` the priority in [0, 10]. Both `simulate` and the live mission apply the
script; an operator's `priority` command changes priorities at run time.
"""

from __future__ import annotations

from pydantic import Field

from isac_mission.config.sections import Section
from isac_mission.tracking.priorities import MAX_PRIORITY, PriorityChange


class PriorityEntry(Section):
    """One scripted change of a track's priority."""

    slot: int = Field(ge=1, description="The first slot whose plan uses the new priority (1..N).")
    track: int = Field(
        ge=1,
        description="The track ID (the labelled target: 1; a later track takes the priority "
        "when it appears).",
    )
    weight: float = Field(
        ge=0.0,
        le=MAX_PRIORITY,
        allow_inf_nan=False,
        description="The track's priority, 0 (not planned for, still kept clear of) to 10; "
        "1 by default.",
    )

    def change(self) -> PriorityChange:
        """The change as the planner's script holds it."""
        return PriorityChange(self.slot, self.track, self.weight)


def priority_problems(entries: list[PriorityEntry], n_slots: int) -> list[str]:
    """One message per entry whose slot is after the mission's last slot N."""
    return [
        f"priorities[{i}].slot: {e.slot} is after the mission's last slot (N = {n_slots})"
        for i, e in enumerate(entries)
        if e.slot > n_slots
    ]
