"""The verdict that opens a live mission's summary (cli/verdict.py) and what Ctrl-C does
(cli/stopping.py): a mission flown on late plans is never called nominal, an operator's hold is
no degradation, an interrupted mission says where it stopped."""

from __future__ import annotations

import pytest

from isac_mission.cli.stopping import StopRequests, land_budget_s, landing_time_s
from isac_mission.cli.verdict import MissionFigures, mission_verdict


def figures(**changes: object) -> MissionFigures:
    base: dict[str, object] = {
        "slots": 60,
        "n_slots": 60,
        "statuses": {},
        "counters": {"slots": 60, "plans applied": 60, "vehicles landed": 3},
        "vehicles": 3,
        "landed": 3,
        "speed": 4.0,
    }
    return MissionFigures(**(base | changes))  # type: ignore[arg-type]


def test_a_clean_mission_is_nominal() -> None:
    v = mission_verdict(figures())
    assert v.word == "nominal" and v.reasons == () and v.advice == ()
    assert v.lines() == ["verdict: nominal"]


def test_late_plans_degrade_it_once_with_what_to_do() -> None:
    v = mission_verdict(
        figures(
            counters={"slots": 60, "plans late": 58, "vehicles landed": 3},
            compiled_meanwhile=True,
            load_1min=3.7,
            cores=2,
        )
    )
    assert v.word == "degraded"
    assert [r for r in v.reasons if "late" in r] == [
        "58 of 60 plans late: published more than a slot after their slot ended, so the "
        "vehicles flew on without them"
    ]
    (advice,) = v.advice
    assert "load was 3.7 on 2 cores" in advice and "--lockstep" in advice
    assert "--speed than 4" in advice and "isac-mission compile" in advice


def test_an_operator_hold_is_not_a_degradation_but_infeasible_slots_are() -> None:
    held = figures(statuses={"operator hold": 6})
    assert mission_verdict(held).word == "nominal"
    v = mission_verdict(figures(statuses={"operator hold": 6, "infeasible": 2}))
    assert v.word == "degraded" and v.reasons[0].startswith("2 slots infeasible")


def test_an_interrupted_mission_says_where_and_how_to_go_on() -> None:
    v = mission_verdict(figures(slots=37, interrupted=True))
    assert v.word == "interrupted"
    assert v.reasons[0] == "stopped at slot 37 of 60"
    assert any("--resume" in a for a in v.advice)
    unfinished = mission_verdict(figures(slots=37))
    assert unfinished.word == "degraded" and "only 37 of 60" in unfinished.reasons[0]


def test_vehicles_not_landed_are_named() -> None:
    v = mission_verdict(figures(landed=1))
    assert v.word == "degraded" and "2 of 3 vehicles did not land" in v.reasons
    left = mission_verdict(figures(landed=1, interrupted=True, landing_abandoned=True))
    assert any("stopped waiting (they were sent LAND)" in r for r in left.reasons)


def test_landing_time_follows_px4s_descent_profile() -> None:
    # 90 m at 1.5 m/s, 10 m at 0.7 m/s, then the 2 s disarm.
    assert landing_time_s(100.0) == pytest.approx(60.0 + 10.0 / 0.7 + 2.0)
    assert landing_time_s(5.0) == pytest.approx(5.0 / 0.7 + 2.0)
    assert land_budget_s(100.0, 2.0) == pytest.approx(210.0)


def test_ctrl_c_stops_then_leaves_then_refuses_and_says_each() -> None:
    r = StopRequests(height_m=100.0, speed=2.0, embedded=True)
    action, line = r.on_signal("SIGINT", 37, 60)
    assert action == "stop"
    assert line.startswith("Ctrl-C: stopping the mission after slot 37 of 60; landing the fleet")
    assert f"about {landing_time_s(100.0) / 2.0:.0f} s" in line and "Ctrl-C again" in line
    action, line = r.on_signal("SIGINT", 37, 60)
    assert action == "leave" and "world ends with this command" in line
    assert r.on_signal("SIGINT", 37, 60)[0] == "refuse"
    served = StopRequests(height_m=100.0, speed=1.0, embedded=False)
    assert "before slot 1" in served.on_signal("SIGTERM", 0, 60)[1]
    assert "land on their own" in served.on_signal("SIGTERM", 0, 60)[1]


def test_a_resumed_run_is_judged_by_the_trace_s_last_slot() -> None:
    """A resumed run flew slots 31..60: it is complete, and an interrupted one says the slot
    of the trace, not its own count."""
    assert mission_verdict(figures(slots=30, last_slot=60)).word == "nominal"
    v = mission_verdict(figures(slots=5, last_slot=35, interrupted=True))
    assert v.reasons[0] == "stopped at slot 35 of 60"


def test_vehicles_never_heard_are_named_as_such_not_as_not_landed() -> None:
    """A `serve` stopped while it waited for a world that never came: nothing flew."""
    v = mission_verdict(
        figures(
            slots=0,
            landed=0,
            interrupted=True,
            counters={"slots": 0, "vehicles landed": 0, "vehicles never heard": 3},
        )
    )
    assert v.word == "interrupted" and v.reasons[0] == "stopped at slot 0 of 60"
    assert any(r.startswith("3 of 3 vehicles never heard") for r in v.reasons)
    assert not any("did not land" in r for r in v.reasons)


def test_ctrl_c_before_the_take_off_says_there_is_nothing_to_land() -> None:
    """A `serve` still waiting for its world and vehicles: no landing to announce."""
    r = StopRequests(height_m=100.0, speed=1.0, embedded=False)
    action, line = r.on_signal("SIGINT", 0, 60, flying=False)
    assert action == "stop" and line.endswith("nothing to land") and "about" not in line
    assert r.on_signal("SIGINT", 0, 60, flying=False)[0] == "leave"
