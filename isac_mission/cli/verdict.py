"""The verdict that opens `run`'s and `serve`'s summary: nominal, interrupted or degraded, with
the reasons and what to do about each.

A live mission is nominal when it flew every slot on plans made in time, with every vehicle
heard, and landed them all. Anything else is named, once, with its count: a summary that says
"status ok" over late plans is the surprise this module exists to prevent. Pure: the figures in,
the lines out (`tests/unit/test_verdict.py`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

DEGRADED_STATUSES = {
    "infeasible": "no plan met every constraint (14a-14j): the best effort was flown",
    "timeout": "planning passed its budget: the vehicles held",
    "solver error": "the planner raised: the fallback plan was flown",
    "no vehicles": "every vehicle was out of the plan (lost links or overrides): they held",
    "held": "the world ran the slot without a plan of this ground loop",
    "unobserved": "the world ran the slot without a plan, and no detection arrived",
}
"""Slot statuses that degrade a mission, and what each means (docs/trace.md, "Statuses"); an
operator's hold (`operator hold`) is the operator's word, not a degradation."""

COUNTER_REASONS = {
    "planner errors": "the planner raised",
    "internal errors": "the ground loop hit a bug and went on (its log has the traceback)",
    "plans dropped after a stall": "the ground loop's process stalled",
    "plans invalid": "plans the bridges could not apply",
    "link losses": "vehicle links lost",
    "link interruptions": "gaps in a vehicle's position stream or in the bridge's setpoints to it",
}
"""Counters (ground loop's and fleet's) that degrade a mission when non-zero."""


@dataclass(frozen=True)
class MissionFigures:
    """What the verdict reads of one live mission.

    slots: slots traced by this run; last_slot: the last slot in the trace (a resumed run's
    slots follow an earlier run's; None: `slots`); n_slots: the mission's N; statuses: slots by status; counters: the
    ground loop's and the fleet's counters by name (`plans late`, `link losses`, ...);
    vehicles, landed: vehicles in the mission and landed at the end; interrupted: asked to stop
    before slot N; landing_abandoned: a second request stopped the wait for touchdown; speed:
    simulation seconds per wall second; lockstep: the world waited for each plan;
    compiled_meanwhile: planner problems compiled in the background during the mission;
    load_1min: the host's 1-minute load average at the end (None: unknown); cores: its CPUs.
    """

    slots: int
    n_slots: int
    statuses: Mapping[str, int]
    counters: Mapping[str, int]
    vehicles: int
    landed: int
    interrupted: bool = False
    landing_abandoned: bool = False
    speed: float = 1.0
    lockstep: bool = False
    compiled_meanwhile: bool = False
    load_1min: float | None = None
    cores: int = 1
    last_slot: int | None = None


@dataclass(frozen=True)
class Verdict:
    """word: "nominal", "interrupted" or "degraded"; reasons: one line each, with its count;
    advice: what to do, one line each."""

    word: str
    reasons: tuple[str, ...] = ()
    advice: tuple[str, ...] = field(default_factory=tuple)

    def lines(self) -> list[str]:
        """The verdict as printed: `verdict: <word>`, then `  - reason` and `  -> advice`."""
        return [
            f"verdict: {self.word}",
            *(f"  - {r}" for r in self.reasons),
            *(f"  -> {a}" for a in self.advice),
        ]


def _pace_advice(f: MissionFigures) -> str:
    """What to do when the planner could not keep the world's pace."""
    busy = ""
    if f.load_1min is not None and f.load_1min > f.cores:
        busy = f" (the host's load was {f.load_1min:.1f} on {f.cores} cores)"
    options = "--lockstep (the world waits for each plan)"
    if not f.lockstep:
        options += f", or a lower --speed than {f.speed:g}"
    compiled = (
        "; run `isac-mission compile CONFIG` once so the planner does not compile while it flies"
        if f.compiled_meanwhile
        else ""
    )
    return f"the machine could not keep the pace{busy}: use {options}{compiled}"


def mission_verdict(f: MissionFigures) -> Verdict:
    """The verdict on one live mission (see the module doc)."""
    reasons: list[str] = []
    advice: list[str] = []
    late = f.counters.get("plans late", 0)
    if late:
        reasons.append(
            f"{late} of {f.slots} plans late: published more than a slot after their slot ended, "
            "so the vehicles flew on without them"
        )
        advice.append(_pace_advice(f))
    for status, meaning in DEGRADED_STATUSES.items():
        n = f.statuses.get(status, 0)
        if n:
            reasons.append(f"{n} slots {status}: {meaning}")
    if f.statuses.get("timeout", 0) and not late:
        advice.append(_pace_advice(f))
    for name, meaning in COUNTER_REASONS.items():
        n = f.counters.get(name, 0)
        if n:
            reasons.append(f"{n} {name}: {meaning}")
    rejected = sum(n for k, n in f.counters.items() if k.startswith("rejected "))
    if rejected:
        reasons.append(f"{rejected} messages rejected (the counters below name why)")
    never = f.counters.get("vehicles never heard", 0)
    if never:
        reasons.append(
            f"{never} of {f.vehicles} vehicles never heard on their links (nothing was "
            "commanded to them): check the vehicles' links and ports (docs/service.md, 'Ports')"
        )
    not_landed = f.vehicles - f.landed - never
    if not_landed > 0:
        if f.landing_abandoned:
            reasons.append(
                f"{not_landed} of {f.vehicles} vehicles not seen landed: the service stopped "
                "waiting (they were sent LAND)"
            )
        else:
            reasons.append(f"{not_landed} of {f.vehicles} vehicles did not land")
            advice.append("check the vehicles with a ground station (docs/service.md)")
    last = f.slots if f.last_slot is None else f.last_slot
    if f.interrupted:
        word = "interrupted"
        reasons.insert(0, f"stopped at slot {last} of {f.n_slots}")
        advice.append("`serve --resume` continues a trace from its last slot (docs/service.md)")
    elif last < f.n_slots:
        word = "degraded"
        reasons.insert(0, f"only {last} of {f.n_slots} slots traced")
    else:
        word = "degraded" if reasons else "nominal"
    return Verdict(word, tuple(reasons), tuple(dict.fromkeys(advice)))
