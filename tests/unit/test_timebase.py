"""isac_mission/timebase.py: time sources and the one slot timeline with its one epsilon."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from isac_mission.timebase import (
    EPS_S,
    UNPACED_SPEED,
    FuncTime,
    SimTime,
    SlotTimeline,
    WallTime,
    reached,
)


def test_func_time_maps_infinite_speed_to_a_large_number() -> None:
    assert FuncTime(lambda: 3.0, math.inf).speed == 1e6
    assert FuncTime(lambda: 3.0, lambda: 4.0).speed == 4.0
    assert FuncTime(lambda: 3.0).now_s() == 3.0


def test_func_time_maps_a_non_positive_speed_to_unpaced() -> None:
    assert FuncTime(lambda: 0.0, 0.0).speed == UNPACED_SPEED
    assert FuncTime(lambda: 0.0, math.nan).speed == UNPACED_SPEED


def test_wall_time_runs_at_speed_one_from_its_epoch() -> None:
    t: SimTime = WallTime(epoch_s=1000.0)
    a, b = t.now_s(), t.now_s()
    assert t.speed == 1.0
    assert b >= a  # monotonic
    assert abs(WallTime().now_s() - a - 1000.0) < 60.0  # the same clock, shifted by the epoch


def test_reached_allows_one_epsilon_and_no_more() -> None:
    assert reached(1.0, 1.0)
    assert reached(1.0 - 0.5 * EPS_S, 1.0)
    assert not reached(1.0 - 2 * EPS_S, 1.0)


def test_slot_ends_and_starts() -> None:
    tl = SlotTimeline(t0_s=11.0, dt_s=2.0)
    assert tl.slot_end_s(0) == 11.0
    assert tl.slot_end_s(3) == 17.0
    assert tl.slot_start_s(3) == 15.0
    assert tl.slot_start_s(1) == tl.slot_end_s(0)


def test_slot_of_counts_reached_boundaries() -> None:
    tl = SlotTimeline(t0_s=11.0, dt_s=2.0)
    assert tl.slot_of(10.0) == -1  # before the mission start
    assert tl.slot_of(11.0) == 0
    assert tl.slot_of(12.999) == 0
    assert tl.slot_of(13.0) == 1
    assert tl.slot_of(16.5) == 2


def test_slot_of_takes_a_boundary_missed_by_rounding_as_reached() -> None:
    # A 50 Hz clock (start + k x 0.02 s) at tick 15 is 0.3 s, and 0.3 / 0.1 is 2.9999999999999996:
    # without the epsilon the clock would be one slot late at the very boundary.
    tl = SlotTimeline(t0_s=0.0, dt_s=0.1)
    tick_time = 15 * 0.02
    assert tick_time / tl.dt_s < 3
    assert tl.slot_of(tick_time) == 3
    below = tl.slot_end_s(3) - 0.5 * EPS_S * tl.dt_s
    assert tl.slot_of(below) == 3  # within the one epsilon
    assert tl.slot_of(tl.slot_end_s(3) - 2 * EPS_S * tl.dt_s) == 2  # beyond it


@given(
    st.floats(min_value=-1e4, max_value=1e4, allow_nan=False),
    st.floats(min_value=0.01, max_value=100.0, allow_nan=False),
    st.integers(min_value=-1000, max_value=100_000),
)
def test_every_slot_end_is_in_its_own_slot(t0: float, dt: float, n: int) -> None:
    # The rounding of t0 + n dt - t0 stays below EPS_S of a slot over these ranges (slots of
    # 10 ms and more, missions of up to 1e5 slots).
    tl = SlotTimeline(t0, dt)
    assert tl.slot_of(tl.slot_end_s(n)) == n
    assert reached(tl.slot_end_s(n), tl.slot_end_s(n))


@pytest.mark.parametrize(("t0", "dt"), [(0.0, 0.0), (0.0, -1.0), (math.nan, 1.0), (0.0, math.inf)])
def test_slot_timeline_rejects_a_bad_grid(t0: float, dt: float) -> None:
    with pytest.raises(ValueError, match="SlotTimeline"):
        SlotTimeline(t0, dt)
