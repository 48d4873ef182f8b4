"""AutopilotSettings (sim/autopilot/settings.py): pydantic, frozen, no unknown keys; every bad
value raises ConfigError with one `AutopilotSettings: ...` line naming the field."""

from __future__ import annotations

import math

import pytest

from isac_mission.errors import ConfigError
from isac_mission.frames import PX4_SITL_ORIGIN
from sim.autopilot.settings import AutopilotSettings
from sim.vehicle import VehicleLimits


def test_defaults_are_px4_sitl_instance_m() -> None:
    s = AutopilotSettings(index=2)
    assert s.system_id == 3
    # PX4 multi-vehicle SITL: offboard 14580 + i -> 14540 + i, GCS 18570 + i -> 14550 (shared).
    assert (s.offboard_local_port, s.offboard_dest_port) == (14582, 14542)
    assert (s.gcs_local_port, s.gcs_dest_port) == (18572, 14550)
    assert AutopilotSettings(index=0).gcs_dest_port == 14550
    ephemeral = AutopilotSettings(index=2, bind_port=0, gcs_bind_port=0)
    assert (ephemeral.offboard_local_port, ephemeral.gcs_local_port) == (0, 0)
    assert s.geo_origin == PX4_SITL_ORIGIN
    assert s.limits == VehicleLimits()
    assert AutopilotSettings(index=2, offboard_port=20000, gcs_port=20001).gcs_dest_port == 20001


def test_every_bad_value_is_one_line_naming_the_field() -> None:
    with pytest.raises(ConfigError) as err:
        AutopilotSettings(
            index=300,
            gcs_port=70000,
            takeoff_alt_m=math.nan,
            status_rate_hz=0.0,
            min_altitude_m=600.0,
            area_min_xy_m=(0.0, 0.0),
            area_max_xy_m=(0.0, 10.0),
            heartbeat_keepalive_wall_s=0.0,
        )
    assert str(err.value).splitlines() == [
        "AutopilotSettings: index must be in [0, 253] (got 300)",
        "AutopilotSettings: gcs_port must be a UDP port (got 70000)",
        "AutopilotSettings: takeoff_alt_m must be finite and > 0 (got nan)",
        "AutopilotSettings: status_rate_hz must be finite and > 0 (got 0.0)",
        "AutopilotSettings: min_altitude_m must be in [0, max_altitude_m) (got 600.0)",
        "AutopilotSettings: area_min_xy_m (0.0, 0.0) must be below area_max_xy_m (0.0, 10.0)",
        "AutopilotSettings: heartbeat_keepalive_wall_s must be > 0 or None",
    ]


def test_type_errors_and_unknown_keys_are_config_errors_naming_the_field() -> None:
    with pytest.raises(ConfigError, match=r"^AutopilotSettings: offboard_loss_action: .*'crash'"):
        AutopilotSettings(offboard_loss_action="crash")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"^AutopilotSettings: limits: .*VehicleLimits"):
        AutopilotSettings(limits={"max_horizontal_speed_mps": 3.0})  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"^AutopilotSettings: spawn_xyz_m: unknown key"):
        AutopilotSettings(spawn_xyz_m=(1.0, 2.0))  # type: ignore[call-arg]


def test_settings_are_frozen() -> None:
    s = AutopilotSettings()
    with pytest.raises(ValueError, match="frozen"):
        s.index = 1  # type: ignore[misc]
