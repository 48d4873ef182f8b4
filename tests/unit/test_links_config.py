"""The scenario's `links` section (MAVLink ports, PX4 SITL's layout) and how the CLI resolves it."""

from __future__ import annotations

import pytest

from isac_mission.cli.ports import port_options
from isac_mission.config import LinksConfig, parse_scenario
from isac_mission.errors import ConfigError
from isac_mission.mavwire import ports


def test_the_defaults_are_px4_sitl_s_layout_as_in_mavwire() -> None:
    links = LinksConfig()
    assert links.offboard_base_port == ports.OFFBOARD_BASE_PORT == 14540
    assert links.offboard_local_base_port == ports.OFFBOARD_LOCAL_BASE_PORT == 14580
    assert links.gcs_port == ports.GCS_PORT == 14550
    assert links.gcs_local_base_port == ports.GCS_LOCAL_BASE_PORT == 18570


def test_the_scenario_s_ports_apply_unless_an_option_is_given() -> None:
    s = parse_scenario({"links": {"gcs_port": 24550, "offboard_local_base_port": 0}})
    assert port_options(s) == {
        "mavlink_base_port": 14540,
        "mavlink_local_base_port": 0,
        "gcs_port": 24550,
        "gcs_local_base_port": 18570,
    }
    assert port_options(s, gcs_port=30000, mavlink_base_port=31000)["gcs_port"] == 30000
    assert port_options(s, mavlink_base_port=31000)["mavlink_base_port"] == 31000


def test_a_bad_port_names_the_field() -> None:
    with pytest.raises(ConfigError, match=r"links\.gcs_port"):
        parse_scenario({"links": {"gcs_port": 70000}})
    with pytest.raises(ConfigError, match=r"links\.offboard_base_port"):
        parse_scenario({"links": {"offboard_base_port": 65500}})  # no room for 254 vehicles
