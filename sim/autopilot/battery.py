"""The simulated vehicle's battery: a constant-plus-speed energy model and PX4's warning levels
(pure: no I/O).

Power drawn, W (docs/service.md, "Battery and the low-battery failsafe"):

    P = idle_power_w                                   disarmed (avionics only)
    P = hover_power_w + speed_power_w_per_mps * |v_h|  armed (motors spinning)
        + climb_power_w_per_mps * max(0, climb rate)

with |v_h| the horizontal speed and the climb rate the upward speed, m/s. The energy drawn is
integrated over simulation time; `remaining` = 1 - energy drawn / capacity (from
`start_remaining`), down to `min_remaining` (50 % by default, where PX4 SITL's simulated battery
stops draining: SIM_BAT_MIN_PCT), below which nothing more is drawn. The pack voltage falls linearly with the charge from `cells * cell_full_v`
to `cells * cell_empty_v` (no sag); the current is P / V.

Warning levels as PX4's battery module sets them (src/lib/battery/battery.cpp,
`determineWarning`): LOW below BAT_LOW_THR, CRITICAL below BAT_CRIT_THR, EMERGENCY below
BAT_EMERGEN_THR, and a level once reached is kept (the warning never goes back down).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar

from pydantic import Field, model_validator

from isac_mission.config.validation import Settings
from isac_mission.errors import ConfigError


class BatterySettings(Settings):
    """The energy model of one vehicle (see the module docstring). Units: Wh, W, V, W/(m/s).

    Attributes:
        capacity_wh: Usable energy of a full pack, Wh.
        start_remaining: Charge at start, fraction of the capacity in (0, 1].
        min_remaining: Floor of the charge, as PX4 SITL's simulated battery stops draining at
            SIM_BAT_MIN_PCT (50 %): so a default run never meets the low-battery failsafe; 0
            lets the battery run out.
        cells: Cells in series (PX4 BAT1_N_CELLS).
        cell_full_v: Voltage of a full cell, V (PX4 BAT1_V_CHARGED).
        cell_empty_v: Voltage of an empty cell, V (PX4 BAT1_V_EMPTY).
        idle_power_w: Power drawn while disarmed, W.
        hover_power_w: Power drawn armed at rest (hover), W.
        speed_power_w_per_mps: Extra power per m/s of horizontal speed, W/(m/s).
        climb_power_w_per_mps: Extra power per m/s of climb rate, W/(m/s).
    """

    settings_name: ClassVar[str] = "BatterySettings"

    capacity_wh: float = Field(80.0, gt=0, description="Usable energy of a full pack, Wh.")
    start_remaining: float = Field(1.0, gt=0, le=1, description="Charge at start, (0, 1].")
    min_remaining: float = Field(
        0.5,
        ge=0,
        lt=1,
        description="The charge never falls below this (PX4 SITL's SIM_BAT_MIN_PCT, 50 %): "
        "0 lets the battery run out.",
    )
    cells: int = Field(4, ge=1, le=14, description="Cells in series (BAT1_N_CELLS).")
    cell_full_v: float = Field(4.05, gt=0, description="Full cell voltage (BAT1_V_CHARGED), V.")
    cell_empty_v: float = Field(3.6, gt=0, description="Empty cell voltage (BAT1_V_EMPTY), V.")
    idle_power_w: float = Field(5.0, ge=0, description="Power drawn disarmed, W.")
    hover_power_w: float = Field(250.0, gt=0, description="Power drawn armed at rest, W.")
    speed_power_w_per_mps: float = Field(
        4.0, ge=0, description="Extra power per m/s of horizontal speed, W/(m/s)."
    )
    climb_power_w_per_mps: float = Field(
        30.0, ge=0, description="Extra power per m/s of climb rate, W/(m/s)."
    )

    @model_validator(mode="after")
    def _voltages_ordered(self) -> BatterySettings:
        if not self.cell_empty_v < self.cell_full_v:
            raise ConfigError(
                f"BatterySettings: cell_empty_v ({self.cell_empty_v}) must be below cell_full_v"
                f" ({self.cell_full_v})"
            )
        return self


class BatteryWarning(IntEnum):
    """PX4's battery warning levels (battery_status.warning; MAV_BATTERY_CHARGE_STATE - 1)."""

    NONE = 0
    LOW = 1
    CRITICAL = 2
    EMERGENCY = 3


@dataclass(frozen=True)
class Thresholds:
    """BAT_LOW_THR, BAT_CRIT_THR, BAT_EMERGEN_THR: remaining fractions in [0, 1]."""

    low: float
    critical: float
    emergency: float


class Battery:
    """One vehicle's battery, stepped on simulation time (`step`)."""

    def __init__(self, settings: BatterySettings) -> None:
        self.settings = settings
        self.energy_used_wh = settings.capacity_wh * (1.0 - settings.start_remaining)
        """Energy drawn from a full pack, Wh."""
        self.energy_drawn_wh = 0.0
        """Energy drawn since start, Wh (BATTERY_STATUS.energy_consumed)."""
        self.charge_drawn_mah = 0.0
        """Charge drawn since start, mAh (BATTERY_STATUS.current_consumed)."""
        self.power_w = settings.idle_power_w
        """Power drawn over the last step, W."""
        self.warning = BatteryWarning.NONE

    @property
    def remaining(self) -> float:
        """Charge left, fraction of the capacity in [0, 1]."""
        return max(0.0, 1.0 - self.energy_used_wh / self.settings.capacity_wh)

    @property
    def voltage_v(self) -> float:
        """Pack voltage, V (linear in the charge left)."""
        s = self.settings
        return s.cells * (s.cell_empty_v + (s.cell_full_v - s.cell_empty_v) * self.remaining)

    @property
    def current_a(self) -> float:
        """Current drawn, A (P / V)."""
        return self.power_w / self.voltage_v

    @property
    def time_remaining_s(self) -> float:
        """Time to empty at the present power, s."""
        left_wh = self.remaining * self.settings.capacity_wh
        return 3600.0 * left_wh / self.power_w if self.power_w > 0 else float("inf")

    def power_for(self, armed: bool, speed_h_mps: float, climb_mps: float) -> float:
        """Power drawn, W, armed or not at horizontal speed `speed_h_mps` and climb rate
        `climb_mps` (m/s, up positive)."""
        s = self.settings
        if not armed:
            return s.idle_power_w
        return (
            s.hover_power_w
            + s.speed_power_w_per_mps * speed_h_mps
            + s.climb_power_w_per_mps * max(0.0, climb_mps)
        )

    def step(
        self,
        dt_s: float,
        armed: bool,
        speed_h_mps: float,
        climb_mps: float,
        thresholds: Thresholds,
    ) -> BatteryWarning | None:
        """Draw energy for `dt_s` seconds; the new warning level if it rose, else None."""
        self.power_w = self.power_for(armed, speed_h_mps, climb_mps)
        voltage = self.voltage_v
        s = self.settings
        floor_wh = s.capacity_wh * (1.0 - min(s.min_remaining, s.start_remaining))
        drawn_wh = min(self.power_w * dt_s / 3600.0, max(0.0, floor_wh - self.energy_used_wh))
        self.energy_used_wh += drawn_wh
        self.energy_drawn_wh += drawn_wh
        self.charge_drawn_mah += 1000.0 * drawn_wh / voltage
        level = warning_for(self.remaining, thresholds)
        if level > self.warning:
            self.warning = level
            return level
        return None


def warning_for(remaining: float, t: Thresholds) -> BatteryWarning:
    """The warning level of charge `remaining` (fraction) under thresholds `t`."""
    if remaining < t.emergency:
        return BatteryWarning.EMERGENCY
    if remaining < t.critical:
        return BatteryWarning.CRITICAL
    if remaining < t.low:
        return BatteryWarning.LOW
    return BatteryWarning.NONE
