"""The simulated vehicle's parameter table and the MAVLink parameter protocol.

A small PX4-like table (MIS_TAKEOFF_ALT, COM_OF_LOSS_T, COM_OBL_RC_ACT, COM_DL_LOSS_T, NAV_DLL_ACT,
COM_DISARM_LAND, COM_DISARM_PRFLT, MPC_* limits and MPC_XY_CRUISE, RTL_*, NAV_ACC_RAD,
NAV_MC_ALT_RAD, BAT_*_THR, COM_LOW_BAT_ACT, COM_BAT_ACT_T, BAT1_* (read only), ...); PARAM_REQUEST_LIST, PARAM_REQUEST_READ and
PARAM_SET are answered with PARAM_VALUE. Integer parameters travel bytewise in the float field,
as PX4 encodes them. A bad value is refused (counted `bad_param_value`) and answered with the
value in force, as PX4 does; an unknown name or index is counted `unknown_param`.
"""

from __future__ import annotations

import logging
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.ports import Address

if TYPE_CHECKING:
    from sim.autopilot.link import VehicleLink
    from sim.autopilot.settings import AutopilotSettings

logger = logging.getLogger(__name__)

LIMIT_FIELDS: Final[dict[str, str]] = {
    "MPC_XY_VEL_MAX": "max_horizontal_speed_mps",
    "MPC_ACC_HOR_MAX": "max_horizontal_accel_mps2",
    "MPC_Z_VEL_MAX_UP": "max_climb_rate_mps",
    "MPC_Z_VEL_MAX_DN": "max_descent_rate_mps",
}
"""Parameters that set a field of the live `VehicleLimits`."""

Reject = Callable[[str, str], None]
"""Counts bad input: (reason, detail for the log)."""


@dataclass
class Param:
    """One parameter: its value in force, MAV_PARAM_TYPE_REAL32 or _INT32, and its check."""

    value: float
    param_type: int
    check: Callable[[float], bool]


def _positive(v: float) -> bool:
    return math.isfinite(v) and v > 0.0


def _finite(v: float) -> bool:
    return math.isfinite(v)


def _non_negative(v: float) -> bool:
    return math.isfinite(v) and v >= 0.0


def _fraction(v: float) -> bool:
    return 0.0 <= v < 1.0


def make_params(s: AutopilotSettings) -> dict[str, Param]:
    """The parameter table of a vehicle with settings `s`, in PARAM_VALUE index order."""
    lim = s.limits
    sysid = s.system_id
    real, int32 = mavlink2.MAV_PARAM_TYPE_REAL32, mavlink2.MAV_PARAM_TYPE_INT32
    obl = {"hold": 5.0, "land": 4.0}[s.offboard_loss_action]
    dll = {"none": 0.0, "hold": 1.0, "land": 3.0}[s.gcs_loss_action]
    low_bat = {"warn": 0.0, "return": 1.0, "land": 2.0, "return_then_land": 3.0}[
        s.low_battery_action
    ]
    return {
        "MAV_SYS_ID": Param(float(sysid), int32, lambda v: v == sysid),
        "MIS_TAKEOFF_ALT": Param(s.takeoff_alt_m, real, _positive),
        "COM_OF_LOSS_T": Param(s.offboard_loss_timeout_s, real, _positive),
        "COM_OBL_RC_ACT": Param(obl, int32, lambda v: v in (4.0, 5.0)),
        "COM_DL_LOSS_T": Param(s.gcs_loss_timeout_s, real, _positive),
        "NAV_DLL_ACT": Param(dll, int32, lambda v: v in (0.0, 1.0, 3.0)),
        "COM_DISARM_LAND": Param(s.disarm_after_land_s, real, _finite),
        "COM_DISARM_PRFLT": Param(s.disarm_preflight_s, real, _finite),
        "MPC_XY_VEL_MAX": Param(lim.max_horizontal_speed_mps, real, _positive),
        "MPC_ACC_HOR_MAX": Param(lim.max_horizontal_accel_mps2, real, _positive),
        "MPC_Z_VEL_MAX_UP": Param(lim.max_climb_rate_mps, real, _positive),
        "MPC_Z_VEL_MAX_DN": Param(lim.max_descent_rate_mps, real, _positive),
        "MPC_LAND_SPEED": Param(s.land_speed_mps, real, _positive),
        "MPC_XY_CRUISE": Param(s.cruise_speed_mps, real, _positive),
        "RTL_RETURN_ALT": Param(s.rtl_return_alt_m, real, _positive),
        "RTL_DESCEND_ALT": Param(s.rtl_descend_alt_m, real, _positive),
        "RTL_LAND_DELAY": Param(s.rtl_land_delay_s, real, _finite),
        "NAV_ACC_RAD": Param(s.acceptance_radius_m, real, _positive),
        "NAV_MC_ALT_RAD": Param(s.altitude_acceptance_m, real, _positive),
        "BAT_LOW_THR": Param(s.battery_low_thr, real, _fraction),
        "BAT_CRIT_THR": Param(s.battery_crit_thr, real, _fraction),
        "BAT_EMERGEN_THR": Param(s.battery_emergen_thr, real, _fraction),
        "COM_LOW_BAT_ACT": Param(low_bat, int32, lambda v: v in (0.0, 1.0, 2.0, 3.0)),
        "COM_BAT_ACT_T": Param(s.battery_action_delay_s, real, _non_negative),
        "BAT1_N_CELLS": Param(float(s.battery.cells), int32, lambda v: v == s.battery.cells),
        "BAT1_V_CHARGED": Param(s.battery.cell_full_v, real, lambda v: v == s.battery.cell_full_v),
        "BAT1_V_EMPTY": Param(s.battery.cell_empty_v, real, lambda v: v == s.battery.cell_empty_v),
    }


def param_name(raw: Any) -> str:
    """A param_id field (bytes or str, NUL-padded) as a name."""
    if isinstance(raw, bytes):
        raw = raw.split(b"\x00", 1)[0].decode("ascii", errors="replace")
    return str(raw).rstrip("\x00")


class ParamProtocol:
    """The parameter protocol of one vehicle.

    Args:
        params: The live table (`make_params`).
        reject: Counts refused requests.
        on_change: Called with a parameter's name after its value changed.
        system_id: The vehicle's MAVLink system id, for log messages.
    """

    def __init__(
        self,
        params: dict[str, Param],
        reject: Reject,
        on_change: Callable[[str], None],
        system_id: int,
    ) -> None:
        self._params = params
        self._reject = reject
        self._on_change = on_change
        self._sysid = system_id

    def value_msg(self, name: str) -> Any:
        """PARAM_VALUE of `name` (integers bytewise in the float field, as PX4 encodes them)."""
        names = list(self._params)
        p = self._params[name]
        if p.param_type == mavlink2.MAV_PARAM_TYPE_INT32:
            wire = struct.unpack("<f", struct.pack("<i", int(p.value)))[0]
        else:
            wire = p.value
        return mavlink2.MAVLink_param_value_message(
            name.encode("ascii"), wire, p.param_type, len(names), names.index(name)
        )

    def on_request_list(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """PARAM_REQUEST_LIST: every parameter, in index order."""
        for name in self._params:
            link.send(self.value_msg(name), addr)

    def on_request_read(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """PARAM_REQUEST_READ by index (>= 0) or by name."""
        names = list(self._params)
        index = int(msg.param_index)
        if index >= 0:
            if index >= len(names):
                self._reject("unknown_param", f"index {index} from {addr}")
                return
            name = names[index]
        else:
            name = param_name(msg.param_id)
            if name not in self._params:
                self._reject("unknown_param", f"{name!r} from {addr}")
                return
        link.send(self.value_msg(name), addr)

    def on_set(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """PARAM_SET: the new value if its check passes; answered with the value in force."""
        name = param_name(msg.param_id)
        p = self._params.get(name)
        if p is None:
            self._reject("unknown_param", f"set {name!r} from {addr}")
            return
        wire = float(msg.param_value)
        if (
            p.param_type == mavlink2.MAV_PARAM_TYPE_INT32
            and msg.param_type != mavlink2.MAV_PARAM_TYPE_REAL32
        ):
            value = float(struct.unpack("<i", struct.pack("<f", wire))[0])
        else:
            value = wire
        if p.check(value):
            p.value = value
            self._on_change(name)
            logger.info("vehicle %d: param %s = %g", self._sysid, name, value)
        else:
            self._reject("bad_param_value", f"{name} = {value!r} from {addr}")
        # Answered either way with the value in force, as PX4 does.
        link.send(self.value_msg(name), addr)
