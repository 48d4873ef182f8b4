"""A mission uploaded with a real MAVProxy's `wp load` (a QGC WPL 110 file) on the vehicle's
ground-station link, listed back with `wp list`, and flown in AUTO.MISSION; and the mission
protocol's other messages (MISSION_CURRENT, MISSION_ITEM_REACHED, MISSION_SET_CURRENT,
MISSION_CLEAR_ALL, a refused item) over pymavlink.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from isac_mission.frames import ned_to_geodetic
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from sim.autopilot.endpoint import Autopilot
from tests.support.autopilot_client import TAKEOFF_ALT_M, Client, make_settings
from tests.support.mavproxy import MavProxy
from tests.support.sim_harness import wait_until

pytestmark = pytest.mark.timeout(150)

MISSION = FlightMode.MISSION.px4_custom_mode
REL = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT


def wpl_line(seq: int, frame: int, command: int, lat: float, lon: float, alt: float) -> str:
    """One QGC WPL 110 line: seq, current, frame, command, p1-p4, lat, lon, alt, autocontinue."""
    current = 1 if seq == 0 else 0
    return f"{seq}\t{current}\t{frame}\t{command}\t0\t0\t0\t0\t{lat:.8f}\t{lon:.8f}\t{alt:.2f}\t1"


def geo(ap: Autopilot, north: float, east: float) -> tuple[float, float]:
    g = ned_to_geodetic(
        np.array([north, east, 0.0]), ap.settings.local_origin_xy_m, ap.settings.geo_origin
    )
    return g.lat_deg, g.lon_deg


def test_mavproxy_wp_load_and_list_then_the_vehicle_flies_the_plan(
    sim_runner, tmp_path: Path
) -> None:
    settings, _port, gcs_port = make_settings()
    runner = sim_runner([settings])
    ap = runner.autopilots[0]
    wp1, wp2 = geo(ap, 25.0, 0.0), geo(ap, 25.0, 20.0)
    plan = tmp_path / "plan.txt"
    plan.write_text(
        "\n".join(
            [
                "QGC WPL 110",
                wpl_line(0, REL, mavlink2.MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, TAKEOFF_ALT_M),
                wpl_line(1, REL, mavlink2.MAV_CMD_NAV_WAYPOINT, *wp1, TAKEOFF_ALT_M),
                wpl_line(2, REL, mavlink2.MAV_CMD_NAV_WAYPOINT, *wp2, 8.0),
                wpl_line(3, REL, mavlink2.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0.0, 0.0, 0.0),
            ]
        )
        + "\n"
    )
    with MavProxy(f"udpin:127.0.0.1:{gcs_port}") as mp:
        mp.wait_for(r"Detected vehicle 1:1", 30.0)
        mp.send("vehicle 1")
        mark = mp.mark()
        mp.send(f"wp load {plan}")
        mp.wait_for(r"Sent all 4 waypoints", 30.0, since=mark)
        wait_until(lambda: len(ap.mission_items) == 4, 10.0, "plan on the vehicle")
        mark = mp.mark()
        mp.send("wp list")
        mp.wait_for(r"Requesting 4 waypoints", 30.0, since=mark)
        mp.wait_for(r"^20 3 ", 30.0, since=mark)  # the last item printed: command, frame, ...
        listed = [line.split()[:2] for line in mp.lines[mark:] if re.match(r"^\d+ \d+ -?\d", line)]
        assert listed == [["22", "3"], ["16", "3"], ["16", "3"], ["20", "3"]]
        mark = mp.mark()
        mp.send("arm throttle")
        mp.wait_for(r"ARM_DISARM: ACCEPTED", 30.0, since=mark)
        mp.set_px4_mode(1, FlightMode.MISSION)
        mp.wait_for(r"DO_SET_MODE: ACCEPTED", 30.0, since=mark)
        wait_until(lambda: ap.state.mode is FlightMode.MISSION, 10.0, "MISSION")
        reached: set[int] = set()

        def flown() -> bool:
            p = tuple(ap.state.position_ned_m)
            targets = ((25.0, 0.0, -TAKEOFF_ALT_M), (25.0, 20.0, -8.0))
            reached.update(k for k, t in enumerate(targets) if math.dist(p, t) < 2.2)
            return ap.state.mode is FlightMode.RTL

        wait_until(flown, 90.0, "the plan flown up to its RTL item")
        assert reached == {0, 1}
        wait_until(lambda: ap.state.landed and not ap.state.armed, 90.0, "home and disarmed")
        assert math.hypot(*ap.state.position_ned_m[:2]) < 1.0


def test_mission_messages_current_reached_set_current_clear_and_refusal(fly) -> None:
    _runner, ap, client = fly()
    home = ap.settings.geo_origin
    items = [
        (mavlink2.MAV_CMD_NAV_TAKEOFF, 0, 0, 5.0),
        (
            mavlink2.MAV_CMD_NAV_WAYPOINT,
            round(home.lat_deg * 1e7) + 1000,
            round(home.lon_deg * 1e7),
            5.0,
        ),
        (mavlink2.MAV_CMD_NAV_LAND, 0, 0, 0.0),
    ]
    upload(client, items)
    assert client.recv("MISSION_ACK").type == mavlink2.MAV_MISSION_ACCEPTED
    current = client.recv("MISSION_CURRENT", lambda m: m.total == 3)
    assert current.seq == 0 and current.mission_state == mavlink2.MISSION_STATE_NOT_STARTED

    # MISSION_SET_CURRENT is answered by MISSION_CURRENT.
    client.clear("MISSION_CURRENT")
    client.send(mavlink2.MAVLink_mission_set_current_message(1, 1, 1))
    assert client.recv("MISSION_CURRENT").seq == 1
    client.send(mavlink2.MAVLink_mission_set_current_message(1, 1, 0))
    assert client.recv("MISSION_CURRENT", lambda m: m.seq == 0).seq == 0

    # A refused item (NAV_LOITER_TIME; then a bad frame) leaves the plan as it was.
    client.clear("MISSION_ACK")
    upload(client, [items[0], (mavlink2.MAV_CMD_NAV_LOITER_TIME, 0, 0, 5.0)])
    assert client.recv("MISSION_ACK").type == mavlink2.MAV_MISSION_UNSUPPORTED
    upload(client, [items[0]], frame=mavlink2.MAV_FRAME_LOCAL_NED)
    assert client.recv("MISSION_ACK").type == mavlink2.MAV_MISSION_UNSUPPORTED_FRAME
    client.send(mavlink2.MAVLink_mission_request_list_message(1, 1, 0))
    assert client.recv("MISSION_COUNT").count == 3

    # Flown with MAV_CMD_MISSION_START: each item reached in turn, then landed and disarmed.
    assert client.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
    client.clear("MISSION_ITEM_REACHED")
    assert client.command(mavlink2.MAV_CMD_MISSION_START, 0, 0) == 0
    client.recv("HEARTBEAT", lambda m: m.custom_mode == MISSION)
    seqs = [client.recv("MISSION_ITEM_REACHED", timeout_s=60.0).seq for _ in range(3)]
    assert seqs == [0, 1, 2]
    wait_until(lambda: ap.state.landed and not ap.state.armed, 30.0, "landed and disarmed")
    done = client.recv(
        "MISSION_CURRENT", lambda m: m.mission_state == mavlink2.MISSION_STATE_COMPLETE
    )
    assert done.total == 3

    client.clear("MISSION_ACK")
    client.send(mavlink2.MAVLink_mission_clear_all_message(1, 1, 0))
    assert client.recv("MISSION_ACK").type == mavlink2.MAV_MISSION_ACCEPTED
    client.send(mavlink2.MAVLink_mission_request_list_message(1, 1, 0))
    assert client.recv("MISSION_COUNT", lambda m: m.count == 0).count == 0
    assert client.set_mode(FlightMode.MISSION) == mavlink2.MAV_RESULT_DENIED


def upload(
    client: Client,
    items: list[tuple[int, int, int, float]],
    frame: int = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
) -> None:
    """MISSION_COUNT, then each MISSION_ITEM_INT as the vehicle requests it."""
    client.clear("MISSION_REQUEST_INT")
    client.send(mavlink2.MAVLink_mission_count_message(1, 1, len(items), 0))
    for seq, (command, x, y, z) in enumerate(items):
        # The next item's request (a repeat of the last one may come first: retries at 0.25 s).
        client.recv("MISSION_REQUEST_INT", lambda m, seq=seq: m.seq == seq)
        client.send(
            mavlink2.MAVLink_mission_item_int_message(
                1, 1, seq, frame, command, int(seq == 0), 1, 0, 0, 0, math.nan, x, y, z, 0
            )
        )


def test_advertised_mission_capabilities_are_honoured(fly) -> None:
    """AUTOPILOT_VERSION says MISSION_INT and MISSION_FLOAT: both item forms upload and
    download, and agree."""
    _runner, ap, client = fly()
    assert client.command(mavlink2.MAV_CMD_REQUEST_MESSAGE, 148) == mavlink2.MAV_RESULT_ACCEPTED
    caps = client.recv("AUTOPILOT_VERSION").capabilities
    for bit in ("MISSION_INT", "MISSION_FLOAT", "COMMAND_INT", "PARAM_FLOAT", "MAVLINK2"):
        assert caps & getattr(mavlink2, f"MAV_PROTOCOL_CAPABILITY_{bit}"), bit
    lat, lon = 47.3978, 8.5457
    client.send(mavlink2.MAVLink_mission_count_message(1, 1, 1, 0))
    assert client.recv("MISSION_REQUEST_INT").seq == 0
    client.send(  # answered in the float form
        mavlink2.MAVLink_mission_item_message(
            1, 1, 0, REL, mavlink2.MAV_CMD_NAV_WAYPOINT, 1, 1, 0, 0, 0, 0, lat, lon, 12.0, 0
        )
    )
    assert client.recv("MISSION_ACK").type == mavlink2.MAV_MISSION_ACCEPTED
    # MISSION_ITEM carries degrees in float32: half an ulp is 2^(e - 24) for a value in
    # [2^e, 2^(e+1)): 1.9e-6 deg at 47 deg (e = 5), 4.8e-7 deg at 8.5 deg (e = 3).
    ulp_half_e7 = 2.0 ** (5 - 24) * 1e7
    stored = ap.mission_items[0]
    assert abs(stored.x - lat * 1e7) <= ulp_half_e7
    assert abs(stored.y - lon * 1e7) <= 2.0 ** (3 - 24) * 1e7
    client.send(mavlink2.MAVLink_mission_request_message(1, 1, 0, 0))
    as_float = client.recv("MISSION_ITEM")
    client.send(mavlink2.MAVLink_mission_request_int_message(1, 1, 0, 0))
    as_int = client.recv("MISSION_ITEM_INT")
    assert (as_float.x, as_float.y) == pytest.approx((lat, lon), abs=ulp_half_e7 * 1e-7)
    assert (as_int.x, as_int.y, as_int.z) == (stored.x, stored.y, 12.0)
    assert as_float.command == as_int.command == mavlink2.MAV_CMD_NAV_WAYPOINT
    client.send(mavlink2.MAVLink_mission_request_int_message(1, 1, 1, 0))
    assert client.recv("MISSION_ACK").type == mavlink2.MAV_MISSION_INVALID_SEQUENCE


def test_an_unanswered_mission_request_is_repeated_and_a_stalled_upload_given_up(fly) -> None:
    _runner, ap, client = fly()
    wp = (mavlink2.MAV_CMD_NAV_WAYPOINT, 473_977_000, 85_456_000, 10.0)
    client.clear("MISSION_REQUEST_INT")
    client.send(mavlink2.MAVLink_mission_count_message(1, 1, 2, 0))
    assert client.recv("MISSION_REQUEST_INT").seq == 0
    assert client.recv("MISSION_REQUEST_INT").seq == 0, "sent again, unanswered"
    upload(client, [wp, wp])  # a fresh count restarts it, and it completes
    assert client.recv("MISSION_ACK").type == mavlink2.MAV_MISSION_ACCEPTED
    client.send(mavlink2.MAVLink_mission_count_message(1, 1, 3, 0))
    client.clear("MISSION_REQUEST_INT")
    wait_until(lambda: ap.rejected["mission_upload_timeout"] == 1, 15.0, "the upload given up")
    client.clear("MISSION_REQUEST_INT")
    with pytest.raises(AssertionError):
        client.recv("MISSION_REQUEST_INT", timeout_s=1.0)
    assert len(ap.mission_items) == 2, "the previous plan stays"


def test_mavproxy_sends_rtl_and_a_force_disarm_in_the_air(sim_runner) -> None:
    settings, _port, gcs_port = make_settings(rtl_return_alt_m=8.0, rtl_descend_alt_m=6.0)
    ap = sim_runner([settings]).autopilots[0]
    with MavProxy(f"udpin:127.0.0.1:{gcs_port}") as mp:
        mp.wait_for(r"Detected vehicle 1:1", 30.0)
        for attempt in range(2):
            mark = mp.mark()
            mp.send("vehicle 1")
            mp.send("arm throttle")
            mp.wait_for(r"ARM_DISARM: ACCEPTED", 30.0, since=mark)
            mp.set_px4_mode(1, FlightMode.TAKEOFF)
            wait_until(
                lambda: ap.state.mode is FlightMode.HOLD and ap.state.altitude_m > 4.8,
                30.0,
                "took off",
            )
            mark = mp.mark()
            if attempt == 0:
                mp.send("long NAV_RETURN_TO_LAUNCH")
                mp.wait_for(r"NAV_RETURN_TO_LAUNCH: ACCEPTED", 30.0, since=mark)
                assert ap.state.mode is FlightMode.RTL
                wait_until(lambda: ap.state.landed and not ap.state.armed, 60.0, "RTL done")
            else:
                mp.send("long COMPONENT_ARM_DISARM 0 21196")
                mp.wait_for(r"ARM_DISARM: ACCEPTED", 30.0, since=mark)
                assert not ap.state.armed
                wait_until(lambda: ap.state.landed, 10.0, "dropped")
                assert ap.state.altitude_m == 0.0
