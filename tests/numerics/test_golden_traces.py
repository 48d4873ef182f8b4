"""`simulate` through the one offline loop reproduces traces recorded before it existed.

tests/unit/data/golden-0.1/ holds traces that `isac-mission simulate --runs 1` wrote at
version 0.1.0, when the paper's target and several targets had an offline loop each:
`paper/` (paper.yaml cut to 15 slots; proposed and horizon) and `multi-target/`
(multi-target.yaml cut to 20 slots; proposed and sd). The scenarios were given in the old
`target:` form then and are given in the `targets:` form here. Every field a recorded line has is
compared, except the planner's wall time (`solve_ms`) and line 1's `format` (a trace names its
format now: docs/trace.md); a line may have gained fields (the slot's tracks, the plan's start).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from isac_mission.config import load_scenario
from isac_mission.experiment.montecarlo import run_monte_carlo
from isac_mission.records import TRACE_FORMAT

GOLDEN = Path(__file__).resolve().parents[1] / "unit" / "data" / "golden-0.1"
WALL_TIME = {"solve_ms"}


def _lines(path: Path) -> list[Any]:
    def strip(obj: Any) -> Any:
        if isinstance(obj, dict):
            return {k: strip(v) for k, v in obj.items() if k not in WALL_TIME}
        if isinstance(obj, list):
            return [strip(v) for v in obj]
        return obj

    return [strip(json.loads(line)) for line in path.read_text().splitlines()]


@pytest.mark.parametrize(
    ("name", "slots", "methods"),
    [("paper", 15, ("proposed", "horizon")), ("multi-target", 20, ("proposed", "sd"))],
)
def test_simulate_reproduces_the_recorded_traces(
    name: str, slots: int, methods: tuple[str, ...], tmp_path: Path
) -> None:
    s = load_scenario(name).with_changes(N=slots)
    # planned as at 0.1.0: tentative tracks only kept clear of (no `planner.newcomer_weight`)
    s = s.with_changes(planner=s.planner.model_copy(update={"newcomer_weight": 0.0}))
    run_monte_carlo(s, methods, 1, s.seed, tmp_path)  # type: ignore[arg-type]
    for method in methods:
        recorded = _lines(GOLDEN / name / f"{method}_run000.jsonl")
        flown = _lines(tmp_path / f"{method}_run000.jsonl")
        assert len(flown) == len(recorded) == slots + 1
        assert flown[0]["format"] == TRACE_FORMAT
        for line, (got, want) in enumerate(zip(flown, recorded, strict=True)):
            kept = {k: got.get(k) for k in want if k != "format"}
            assert kept == {k: v for k, v in want.items() if k != "format"}, (
                f"{name} {method}: line {line + 1} differs"
            )
