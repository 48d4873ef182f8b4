"""PX4 custom modes in isac_mission/mavwire/modes.py: one encoding for the service's decoding
(`px4_mode_name`) and the simulated vehicle's modes (`FlightMode`, `mode_from_px4`)."""

from __future__ import annotations

import pytest

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import (
    FlightMode,
    heartbeat_mode_name,
    mode_from_px4,
    px4_custom_mode,
    px4_main_sub,
    px4_mode_name,
)

# PX4's custom_mode = (sub_mode << 24) | (main_mode << 16), as documented by PX4.
DOCUMENTED = {
    FlightMode.OFFBOARD: 0x00060000,
    FlightMode.TAKEOFF: 0x02040000,
    FlightMode.HOLD: 0x03040000,
    FlightMode.LAND: 0x06040000,
    FlightMode.RTL: 0x05040000,
    FlightMode.MISSION: 0x04040000,
}


@pytest.mark.parametrize("mode", list(FlightMode), ids=lambda m: m.value)
def test_simulated_modes_encode_as_px4_documents_them(mode: FlightMode) -> None:
    assert mode.px4_custom_mode == DOCUMENTED[mode]


@pytest.mark.parametrize("mode", list(FlightMode), ids=lambda m: m.value)
def test_a_simulated_mode_decodes_to_itself_and_to_its_px4_name(mode: FlightMode) -> None:
    assert mode_from_px4(*px4_main_sub(mode.px4_custom_mode)) is mode
    assert px4_mode_name(mode.px4_custom_mode) == mode.px4_name == mode.value.lower()


def test_main_and_sub_mode_round_trip_through_the_custom_mode() -> None:
    for main in range(256):
        for sub in (0, 1, 3, 6, 128, 255):
            assert px4_main_sub(px4_custom_mode(main, sub)) == (main, sub)


def test_offboard_takes_any_sub_mode_and_other_modes_are_not_simulated() -> None:
    for sub in (-1, 0, 7, 255, 300):
        assert mode_from_px4(6, sub) is FlightMode.OFFBOARD
    assert mode_from_px4(4, 1) is None  # AUTO.READY
    assert mode_from_px4(4, 300) is None
    assert mode_from_px4(3, 0) is None  # POSCTL
    assert mode_from_px4(262, 0) is None  # not a byte: not OFFBOARD


def test_unknown_modes_decode_as_auto_or_unknown() -> None:
    assert px4_mode_name(px4_custom_mode(4, 99)) == "auto"
    assert px4_mode_name(px4_custom_mode(99)) == "unknown"
    assert px4_mode_name(px4_custom_mode(4, 5)) == "rtl"


def test_heartbeat_mode_is_decoded_only_for_px4_with_the_custom_mode_flag() -> None:
    custom = FlightMode.OFFBOARD.px4_custom_mode
    flag = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert heartbeat_mode_name(mavlink2.MAV_AUTOPILOT_PX4, flag, custom) == "offboard"
    assert heartbeat_mode_name(mavlink2.MAV_AUTOPILOT_PX4, 0, custom) == "unknown"
    assert heartbeat_mode_name(mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, flag, custom) == "unknown"


@pytest.mark.parametrize(
    ("custom_mode", "name"),
    [
        (0x00060000, "offboard"),
        (0x02040000, "takeoff"),
        (0x03040000, "hold"),
        (0x06040000, "land"),
        (0x04040000, "mission"),
        (0x05040000, "rtl"),
        (0x00030000, "posctl"),
        (0x00010000, "manual"),
        (0x07040000, "auto"),
        (0x00000000, "unknown"),
        (0x00630000, "unknown"),
    ],
)
def test_px4_custom_mode_decodes(custom_mode: int, name: str) -> None:
    assert px4_mode_name(custom_mode) == name


def test_px4_modes_agree_with_the_simulated_vehicle() -> None:
    for mode in FlightMode:
        assert px4_mode_name(mode.px4_custom_mode) == mode.value.lower()
    assert px4_custom_mode(6) == FlightMode.OFFBOARD.px4_custom_mode
    assert px4_custom_mode(4, 3) == FlightMode.HOLD.px4_custom_mode


def test_heartbeat_mode_needs_px4_and_the_custom_mode_flag() -> None:
    custom = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert heartbeat_mode_name(mavlink2.MAV_AUTOPILOT_PX4, custom, 0x00060000) == "offboard"
    assert heartbeat_mode_name(mavlink2.MAV_AUTOPILOT_PX4, 0, 0x00060000) == "unknown"
    assert heartbeat_mode_name(mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, custom, 4) == "unknown"
