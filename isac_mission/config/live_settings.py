"""The live settings: what the live service (`run`, `serve`) plans with, in one place.

The vehicles of the live service have momentum: the live planner plans on their dynamics
(`planner.vehicle_model`, model/vehicle.py) and on a scenario with margins (docs/model.md, "Live
service"): V_max x speed_fraction (headroom to catch up), R_th x rate_factor, D_s +
safety_margin_m on top of the scenario's safety rule (`planner.safety_margin`; 0 by default: the
rule's margins, the same offline and live) and, without the vehicle model, each waypoint
reachable with accel_fraction x a_max (`planner.accel_limit_mps2`; 0: off).
`simulate --live-settings` plans on exactly this scenario, so that an offline study holds for the
service. The defaults were chosen by live missions (docs/decisions/0010-live-settings.md).

Pure: plain numbers in, a Scenario out (no CLI options, no I/O).
"""

from __future__ import annotations

from dataclasses import dataclass

from isac_mission.config.scenario import Scenario


@dataclass(frozen=True)
class LiveSettings:
    """The live planner's margins (dimensionless factors, m).

    speed_fraction: V_max multiplier (0, 1]; rate_factor: R_th multiplier >= 1; safety_margin_m:
    added to D_s (m); accel_fraction: the planner keeps each waypoint reachable with this
    fraction of a_max (0: off, the paper's kinematics), and with the vehicle model plans with
    a_max x accel_fraction; vehicle_model: plan on the vehicles' dynamics
    (`planner.vehicle_model`; on when either the scenario or these settings say so).
    """

    speed_fraction: float = 0.9
    rate_factor: float = 1.05
    safety_margin_m: float = 0.0
    accel_fraction: float = 0.8
    vehicle_model: bool = True

    def __post_init__(self) -> None:
        if not 0 < self.speed_fraction <= 1:
            raise ValueError(f"speed_fraction must be in (0, 1] (got {self.speed_fraction})")
        if self.rate_factor <= 0:
            raise ValueError(f"rate_factor must be > 0 (got {self.rate_factor})")
        if self.safety_margin_m < 0:
            raise ValueError(f"safety_margin_m must be >= 0 (got {self.safety_margin_m})")
        if self.accel_fraction < 0:
            raise ValueError(f"accel_fraction must be >= 0 (got {self.accel_fraction})")

    def apply(self, s: Scenario) -> Scenario:
        """The scenario the live planner plans with (docs/model.md, "Live service")."""
        vehicle_model = s.planner.vehicle_model or self.vehicle_model
        update: dict[str, object] = {"vehicle_model": vehicle_model}
        a_max = s.a_max
        if self.accel_fraction > 0:
            update["accel_limit_mps2"] = s.a_max * self.accel_fraction
            if vehicle_model:
                # The vehicle model plans with accel_fraction x a_max: the vehicles' controller
                # needs the rest to correct its error (a turn held at a_max is not flown: the
                # vehicle drifts off it; docs/model.md, "Vehicle model").
                a_max = s.a_max * self.accel_fraction
        return s.with_changes(
            a_max=a_max,
            v_max=s.v_max * self.speed_fraction,
            r_th=s.r_th * self.rate_factor,
            d_safe=s.d_safe + self.safety_margin_m,
            planner=s.planner.model_copy(update=update),
        )

    def changes(self, s: Scenario) -> list[tuple[str, str, str]]:
        """What `apply` changes, as (quantity, scenario value, live value) rows for a table."""
        live = self.apply(s)
        accel = live.planner.accel_limit_mps2
        return [
            ("V_max", f"{s.v_max:g} m/s", f"{live.v_max:g} m/s"),
            ("R_th", f"{s.r_th / 1e6:g} Mbit/s", f"{live.r_th / 1e6:g} Mbit/s"),
            ("D_s", f"{s.d_safe:g} m", f"{live.d_safe:g} m"),
            ("a_max (vehicle model)", f"{s.a_max:g} m/s^2", f"{live.a_max:g} m/s^2"),
            (
                "planner.accel_limit_mps2",
                _opt(s.planner.accel_limit_mps2),
                _opt(accel),
            ),
            (
                "planner.vehicle_model",
                str(s.planner.vehicle_model).lower(),
                str(live.planner.vehicle_model).lower(),
            ),
            ("planner.safety_margin", s.planner.safety_margin, live.planner.safety_margin),
        ]


LIVE_SETTINGS = LiveSettings()
"""The live service's defaults (`run` and `serve` plan with these unless told otherwise)."""


def _opt(value: float | None) -> str:
    return "null" if value is None else f"{value:g}"
