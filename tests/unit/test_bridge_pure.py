"""The bridge's pure parts: the carrot, the Zenoh-fed clock, settings."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from isac_mission.config import MavlinkSigningKey
from isac_mission.errors import ConfigError, IsacError
from isac_mission.service.bridge.clock_time import ClockSimTime
from isac_mission.service.bridge.legs import CarrotLeg, plan_leg
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.telemetry import telemetry_mode
from isac_mission.wire import TELEMETRY_MODES, ClockMsg


def test_telemetry_modes_are_codec_modes() -> None:
    for px4 in ("offboard", "hold", "land", "takeoff", "posctl", "ready", "auto", "unknown"):
        assert telemetry_mode(px4) in TELEMETRY_MODES
    assert telemetry_mode("posctl") == "manual"
    assert telemetry_mode("follow_target") == "other"


def test_carrot_moves_at_the_speed_that_arrives_on_time() -> None:
    leg = plan_leg([0.0, 0.0], [30.0, 40.0], now_s=10.0, arrive_by_s=20.0, max_speed_mps=25.0)
    assert leg.speed_mps == pytest.approx(5.0)  # 50 m in 10 s
    xy, v = leg.sample(15.0)
    np.testing.assert_allclose(xy, [15.0, 20.0])
    np.testing.assert_allclose(v, [3.0, 4.0])  # velocity feed-forward along the leg
    xy, v = leg.sample(20.0)
    np.testing.assert_allclose(xy, [30.0, 40.0])
    np.testing.assert_allclose(v, [0.0, 0.0])
    xy, _ = leg.sample(5.0)  # before the start: at the start
    np.testing.assert_allclose(xy, [0.0, 0.0])


def test_carrot_never_exceeds_v_max() -> None:
    late = plan_leg([0.0, 0.0], [100.0, 0.0], now_s=0.0, arrive_by_s=1.0, max_speed_mps=25.0)
    assert late.speed_mps == 25.0
    assert late.end_s == pytest.approx(4.0)
    past = plan_leg([0.0, 0.0], [10.0, 0.0], now_s=5.0, arrive_by_s=4.0, max_speed_mps=25.0)
    assert past.speed_mps == 25.0
    none = plan_leg([0.0, 0.0], [10.0, 0.0], now_s=5.0, arrive_by_s=None, max_speed_mps=7.0)
    assert none.speed_mps == 7.0


def test_zero_length_leg_rests_at_the_goal() -> None:
    leg = CarrotLeg(np.array([1.0, 2.0]), np.array([1.0, 2.0]), 0.0, 5.0)
    xy, v = leg.sample(3.0)
    np.testing.assert_allclose(xy, [1.0, 2.0])
    np.testing.assert_allclose(v, [0.0, 0.0])


def test_plan_leg_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="max_speed"):
        plan_leg([0.0, 0.0], [1.0, 0.0], 0.0, None, 0.0)
    with pytest.raises(ValueError, match="goal_xy_m"):
        plan_leg([0.0, 0.0], [math.nan, 0.0], 0.0, None, 1.0)


def clock_msg(t_s: float, speed: float = 10.0, t0: float | None = None, slot: int = -1) -> ClockMsg:
    return ClockMsg(slot=slot, t_s=t_s, slot_s=2.0, speed=speed, mission_t0_s=t0)


def test_clock_sim_time_extrapolates_with_speed_and_caps_it() -> None:
    wall = [100.0]
    t = ClockSimTime(max_extrapolation_s=0.3, wall=lambda: wall[0])
    assert not t.ready
    assert t.now_s() == 0.0
    t.update(clock_msg(50.0, speed=10.0))
    assert t.speed == 10.0
    wall[0] = 100.02
    assert t.now_s() == pytest.approx(50.2)  # 0.02 wall s x 10
    wall[0] = 101.0
    assert t.now_s() == pytest.approx(50.3)  # capped: the world's clock stopped


def test_clock_sim_time_never_goes_back_unless_the_world_restarts() -> None:
    wall = [0.0]
    t = ClockSimTime(max_extrapolation_s=0.5, restart_jump_s=5.0, wall=lambda: wall[0])
    t.update(clock_msg(10.0))
    wall[0] = 0.04
    assert t.now_s() == pytest.approx(10.4)
    t.update(clock_msg(10.1))  # arrived late: time holds instead of going back
    assert t.now_s() == pytest.approx(10.4)
    t.update(clock_msg(1.0))  # far behind: a new world
    assert t.now_s() == pytest.approx(1.0)


def test_clock_sim_time_slots_follow_the_mission_start() -> None:
    wall = [0.0]
    t = ClockSimTime(wall=lambda: wall[0])
    t.update(clock_msg(10.0))
    assert t.current_slot() == -1
    assert t.slot_end_s(3) is None
    t.update(clock_msg(15.0, t0=11.0, slot=2))
    assert t.current_slot() == 2
    assert t.slot_end_s(3) == 17.0


def test_bridge_settings_defaults_follow_px4_sitl_ports() -> None:
    s = BridgeSettings(index=2)
    assert s.listen_port == 14542
    assert s.vehicle_system_id == 3
    assert BridgeSettings(index=2, port=5000, system_id=9).listen_port == 5000


def test_bridge_settings_name_every_bad_value() -> None:
    with pytest.raises(IsacError, match=r"setpoint_rate_hz.*\n.*command_attempts"):
        BridgeSettings(setpoint_rate_hz=0.0, command_attempts=0)


def test_bridge_settings_name_an_unknown_or_mistyped_field() -> None:
    with pytest.raises(ConfigError, match=r"BridgeSettings: v_max: unknown key"):
        BridgeSettings(v_max=3.0)  # type: ignore[call-arg]
    with pytest.raises(ConfigError, match=r"BridgeSettings: index: .*integer.*'two'"):
        BridgeSettings(index="two")  # type: ignore[arg-type]


def test_bridge_settings_are_frozen_and_keep_the_signing_key_object() -> None:
    key = MavlinkSigningKey(bytes(range(32)), link_id=3)
    s = BridgeSettings(signing=key, origin_xy_m=[1.0, 2.0])  # type: ignore[arg-type]
    assert s.signing is key
    assert s.origin_xy_m == (1.0, 2.0)
    with pytest.raises(ValidationError, match="frozen"):
        s.index = 4  # type: ignore[misc]
