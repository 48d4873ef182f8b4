"""Operator override in the bridge, pure: who took the vehicle (override.py, operator.py)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import numpy as np

from isac_mission.mavwire.status import VehicleStatus
from isac_mission.service.bridge.counters import BridgeCounters
from isac_mission.service.bridge.operator import OverrideKeeper
from isac_mission.service.bridge.override import KILLED, OverrideWatch, is_offboard_loss
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.supervision import LinkWatch
from isac_mission.timebase import FuncTime

IN_AIR, ON_GROUND = 2, 1  # MAV_LANDED_STATE_*


def status(
    mode: str = "offboard", t: float = 10.0, armed: bool = True, landed_state: int = IN_AIR
) -> VehicleStatus:
    return VehicleStatus(
        time_s=t,
        system_id=2,
        address=("127.0.0.1", 14541),
        heartbeat_s=t,
        lost=False,
        mode=mode,
        custom_mode=0,
        armed=armed,
        landed_state=landed_state,
        position_ned_m=np.array([1.0, 2.0, -20.0]),
        velocity_ned_mps=np.zeros(3),
        position_s=t,
        yaw_rad=0.0,
        home_amsl_m=488.0,
    )


class Rig:
    """An OverrideKeeper on a real LinkWatch, with a stand-in stream and OFFBOARD entry."""

    def __init__(self) -> None:
        self.now = 10.0
        self.counters = BridgeCounters()
        self.watch = LinkWatch(BridgeSettings(index=1, interruption_after_s=1.0), self.counters)
        self.stream: Any = SimpleNamespace(follow_vehicle=False, reanchored=0, streaming=True)
        self.stream.stop = lambda: setattr(self.stream, "streaming", False)
        self.stream.reanchor = lambda st: setattr(
            self.stream, "reanchored", self.stream.reanchored + 1
        )
        self.offboard: Any = SimpleNamespace(want=True, awaiting=False)
        self.reentries = 0

        def reenter() -> None:
            self.reentries += 1

        self.keeper = OverrideKeeper(
            1,
            FuncTime(lambda: self.now),
            self.stream,
            self.offboard,
            self.watch,
            self.counters,
            reenter,
        )

    def see(self, st: VehicleStatus) -> str:
        self.now = st.time_s
        if self.watch.observe(st, self.now, self.offboard.want, True):
            self.keeper.after_gap(st, self.now)
        else:
            self.keeper.check(st, self.now, True, True)
        return self.keeper.reason


def flying(rig: Rig, until: float) -> None:
    for t in np.arange(10.0, until, 0.1):
        assert rig.see(status(t=float(t))) == ""


def test_a_ground_stations_hold_with_the_link_up_is_an_override() -> None:
    rig = Rig()
    flying(rig, 20.0)
    assert rig.see(status("hold", 20.0)) == "operator: HOLD"
    assert rig.stream.follow_vehicle and not rig.offboard.want and rig.counters.overrides == 1
    assert rig.see(status("rtl", 21.0)) == "operator: RTL"  # re-worded as the mode changes
    # The operator switches it back to OFFBOARD: the service's again, no command needed.
    assert rig.see(status("offboard", 22.0)) == ""
    assert rig.offboard.want and not rig.stream.follow_vehicle and rig.stream.reanchored == 1
    assert rig.reentries == 0


def test_a_failsafe_names_its_cause_from_the_statustext() -> None:
    rig = Rig()
    flying(rig, 20.0)
    rig.keeper.texts.on_statustext(19.5, "Critical battery level, executing RTL in 5 seconds")
    assert rig.see(status("rtl", 25.0)) == "RTL: low battery"
    assert rig.see(status("land", 45.0)) == "LAND: low battery"  # the cause is kept
    rig2 = Rig()
    flying(rig2, 20.0)
    rig2.keeper.texts.on_statustext(19.8, "Geofence breached")
    assert rig2.see(status("hold", 20.0)) == "HOLD: geofence"


def test_the_offboard_loss_hold_after_a_gap_is_no_override() -> None:
    rig = Rig()
    flying(rig, 20.0)
    # 2 s without a position (> interruption_after_s), then the vehicle reports the loss hold.
    st = replace(status("hold", 22.0))
    assert rig.see(st) == ""
    assert rig.counters.link_interruptions == 1 and rig.counters.overrides == 0
    # Announced by the vehicle itself (a one-way gap the bridge did not see): no override either.
    rig2 = Rig()
    flying(rig2, 20.0)
    rig2.keeper.texts.on_statustext(20.0, "Offboard lost: HOLD")
    assert rig2.see(status("hold", 20.1)) == ""
    assert is_offboard_loss("Offboard lost: LAND") and not is_offboard_loss("Low battery")


def test_an_rtl_after_a_gap_is_the_vehicles_own_and_respected() -> None:
    rig = Rig()
    flying(rig, 20.0)
    rig.keeper.texts.on_statustext(21.5, "Connection to ground station lost")
    assert rig.see(status("rtl", 22.0)) == "RTL: datalink loss"
    assert not rig.offboard.want


def test_landing_and_a_kill_take_it_out_for_good() -> None:
    rig = Rig()
    flying(rig, 20.0)
    assert rig.see(status("offboard", 20.0, armed=False)) == "killed: disarmed in the air"
    assert rig.see(status("offboard", 21.0, armed=True)) == "killed: disarmed in the air"
    rig2 = Rig()
    flying(rig2, 20.0)
    assert rig2.see(status("land", 20.0, landed_state=ON_GROUND)) == "landed"
    assert not rig2.stream.streaming and rig.stream.streaming is False
    rig3 = Rig()  # an RTL of its own that ends on the ground
    flying(rig3, 20.0)
    assert rig3.see(status("rtl", 20.0)) == "operator: RTL" and rig3.stream.streaming
    assert rig3.see(status("rtl", 80.0, landed_state=ON_GROUND)) == "landed"
    assert not rig3.stream.streaming


def test_no_override_while_waiting_for_its_own_offboard_command() -> None:
    rig = Rig()
    flying(rig, 20.0)
    rig.offboard.awaiting = True
    assert rig.see(status("hold", 20.0)) == ""
    rig.offboard.want = False  # nor when the bridge does not fly the mission
    rig.offboard.awaiting = False
    assert rig.see(status("hold", 20.1)) == ""


def test_statustext_is_forgotten_after_ten_seconds() -> None:
    w = OverrideWatch()
    w.on_statustext(0.0, "Low battery level, return advised")
    assert w.cause(5.0) == "low battery" and w.cause(10.5) is None


def test_a_ground_station_taking_a_vehicle_held_on_control_is_an_override() -> None:
    rig = Rig()
    flying(rig, 20.0)
    rig.keeper.take("control: hold")
    assert rig.see(status("hold", 20.5)) == "control: hold"  # the hold asked for
    assert rig.see(status("rtl", 21.0)) == "operator: RTL"  # then MAVProxy's RTL
    assert rig.counters.overrides == 2


def test_the_vehicles_word_on_the_offboard_loss_brings_a_reentry() -> None:
    """ "Offboard lost: HOLD" with no gap the bridge saw (a one-way gap): the hold is taken back
    to OFFBOARD (it used to be no override for the text's 10 s, then "operator: HOLD")."""
    rig = Rig()
    flying(rig, 20.0)
    rig.now = 20.0
    rig.keeper.on_statustext(SimpleNamespace(text=b"Offboard lost: HOLD\x00\x00"))
    held = status("hold", 20.1)
    rig.now = 20.1
    assert rig.watch.observe(held, 20.1, True, True)  # supervision asks for the re-entry
    assert rig.keeper.after_gap(held, 20.1)  # the loss hold: re-enter
    assert rig.keeper.reason == "" and rig.counters.overrides == 0
    assert rig.counters.link_interruptions == 1


def test_a_kill_read_after_the_fall_or_during_a_gap_is_a_kill() -> None:
    """Disarmed straight from IN_AIR is a kill even when the first disarmed status already says
    ON_GROUND (the fall was faster than the status), or comes right after a link gap, whose
    grace would otherwise hold the verdict until the vehicle lies on the ground ("landed")."""
    rig = Rig()
    flying(rig, 20.0)
    assert rig.see(status("offboard", 20.5, armed=False, landed_state=ON_GROUND)) == KILLED
    after_gap = Rig()
    flying(after_gap, 20.0)
    fallen = status("offboard", 22.0, armed=False, landed_state=ON_GROUND)  # 2 s unheard
    assert after_gap.see(fallen) == KILLED
    # Landing first (ON_GROUND while armed), then disarming, is a landing; so is a vehicle whose
    # landed state is unknown (no EXTENDED_SYS_STATE): its disarm says nothing of the air.
    landing = Rig()
    flying(landing, 20.0)
    assert landing.see(status("land", 20.5, landed_state=ON_GROUND)) == "landed"
    assert landing.see(status("land", 21.0, armed=False, landed_state=ON_GROUND)) == "landed"
    unknown = Rig()
    flying(unknown, 20.0)
    assert unknown.see(status("offboard", 20.5, landed_state=0)) == ""
    assert unknown.see(status("offboard", 21.0, armed=False, landed_state=0)) != KILLED
