"""The intruders: the `targets:` list of a scenario file and the detection model
(`detection:`), as written (docs/model.md, "Several targets").

`targets:` is the one way to give targets: a list, one entry for the paper's single target. How
every target may move, scenario-wide (the process noise kappa, the manoeuvre bound a_T), is
`target_motion:` (config/sections.py); the deprecated `target:` section is read as a list of one
(config/scenario.py). Resolved into SI units as `TargetSpec`s on `Scenario.targets`
(config/resolve.py).

A target's truth moves by one of four models (`TargetEntry.motion`; model/targets.py):
constant_velocity and coordinated_turn with the scenario's process noise, and two noiseless
scripted ones: waypoints (straight legs through points at the initial speed) and legs (`legs:`, a
list of `LegEntry`: straight, turn or accelerate for a duration each, one after another from the
initial state, then straight on), resolved as `Leg`s on `TargetSpec.legs`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from pydantic import Field, model_validator

from isac_mission.config.sections import MultiTrackerConfig, Section

__all__ = [
    "DetectionConfig",
    "DetectionSpec",
    "Leg",
    "LegEntry",
    "MultiTrackerConfig",
    "TargetEntry",
    "TargetSpec",
    "accelerate_problem",
]
"""MultiTrackerConfig lives in config/sections.py (`tracker.multi:`); importable here as before."""


LegKind = Literal["straight", "turn", "accelerate"]
"""How a target flies one of its `legs:` (motion legs)."""

LEG_PARAMETERS = {"turn": "turn_rate_radps", "accelerate": "accel_mps2"}
"""The one parameter of each kind of leg that has one (a straight leg has none)."""


class LegEntry(Section):
    """One leg of a target's `legs:` (motion legs): flown for duration_s from where the leg
    before it ended (the first from initial_state), as one of: straight (constant velocity),
    turn (a coordinated turn at turn_rate_radps, constant speed) or accelerate (accel_mps2 along
    the track, heading constant)."""

    kind: LegKind = Field(
        description="straight: constant velocity; turn: a coordinated turn at turn_rate_radps "
        "at constant speed; accelerate: accel_mps2 along the track, heading constant."
    )
    duration_s: float = Field(gt=0, description="How long the leg lasts, s.")
    turn_rate_radps: float | None = Field(
        None,
        allow_inf_nan=False,
        description="turn only: omega, rad/s (positive: counter-clockwise); the lateral "
        "acceleration is speed * omega.",
    )
    accel_mps2: float | None = Field(
        None,
        allow_inf_nan=False,
        description="accelerate only: the along-track acceleration, m/s^2 (negative slows; "
        "the speed must stay > 0 through the leg).",
    )

    @model_validator(mode="after")
    def _one_parameter(self) -> LegEntry:
        for kind, name in LEG_PARAMETERS.items():
            given = getattr(self, name) is not None
            if kind == self.kind and not given:
                raise ValueError(f"kind {self.kind} needs {name}")
            if kind != self.kind and given:
                raise ValueError(f"{name} is for kind {kind}, not {self.kind}")
        return self


def accelerate_problem(speed_mps: float, accel_mps2: float, duration_s: float) -> str | None:
    """Why an accelerate leg from speed_mps (> 0) at accel_mps2 for duration_s cannot be flown
    (its speed would reach 0: the heading is lost), or None. The speed at its end is
    speed_mps + accel_mps2 * duration_s (linear in time, so the end is the lowest)."""
    end = speed_mps + accel_mps2 * duration_s
    if end > 0:
        return None
    at = -speed_mps / accel_mps2
    return (
        f"the speed falls from {speed_mps:.6g} m/s to 0 at {at:.6g} s into the leg "
        f"(of {duration_s:.6g} s; {end:.6g} m/s at its end): it must stay > 0"
    )


class TargetEntry(Section):
    """One intruder of `targets:`."""

    name: str | None = Field(
        None, max_length=64, description="A label for reports; default target-<index>."
    )
    initial_state: tuple[float, float, float, float] = Field(
        description="[x, y, vx, vy] (m, m/s) when it appears (x_0 for the paper's one target)."
    )
    rcs_dbsm: float = Field(-10.0, description="sigma_RCS of this target, dBsm.")
    motion: Literal["constant_velocity", "coordinated_turn", "waypoints", "legs"] = Field(
        "constant_velocity",
        description="constant_velocity: eq. 3 with the scenario's process noise "
        "(target_motion.process_noise_intensity); "
        "coordinated_turn: turning at turn_rate_radps, with the same noise; waypoints: "
        "straight legs through waypoints_xy_m at the initial speed, no noise; legs: the "
        "manoeuvres of legs: one after another from the initial state, then straight on, "
        "no noise.",
    )
    turn_rate_radps: float | None = Field(
        None, description="coordinated_turn only: omega, rad/s (positive: counter-clockwise)."
    )
    waypoints_xy_m: list[tuple[float, float]] | None = Field(
        None, min_length=1, description="waypoints only: where it flies after its start, m."
    )
    legs: list[LegEntry] | None = Field(
        None,
        min_length=1,
        description="legs only: [{kind, duration_s, turn_rate_radps | accel_mps2}, ...] flown "
        "one after another from the initial state (LegEntry); straight on after the last.",
    )
    appears_s: float = Field(0.0, ge=0, description="When it enters the scene (s).")
    leaves_s: float | None = Field(None, description="When it leaves (s); null: never.")
    prior: Literal["known", "unknown"] = Field(
        "known",
        description="known: a confirmed track starts from its state with P0 when it appears; "
        "unknown: the tracker must find it.",
    )

    @model_validator(mode="after")
    def _motion_parameters(self) -> TargetEntry:
        if self.motion == "coordinated_turn" and self.turn_rate_radps is None:
            raise ValueError("motion coordinated_turn needs turn_rate_radps")
        if self.motion != "coordinated_turn" and self.turn_rate_radps is not None:
            raise ValueError(f"turn_rate_radps is for motion coordinated_turn, not {self.motion}")
        if self.motion == "waypoints" and not self.waypoints_xy_m:
            raise ValueError("motion waypoints needs waypoints_xy_m")
        if self.motion != "waypoints" and self.waypoints_xy_m is not None:
            raise ValueError(f"waypoints_xy_m is for motion waypoints, not {self.motion}")
        if self.motion == "waypoints" and self.initial_state[2:] == (0.0, 0.0):
            raise ValueError("motion waypoints flies at the initial speed: it must be > 0")
        if self.motion == "legs":
            self._legs_flyable()
        elif self.legs is not None:
            raise ValueError(f"legs is for motion legs, not {self.motion}")
        if self.leaves_s is not None and self.leaves_s <= self.appears_s:
            raise ValueError(f"leaves_s {self.leaves_s} must be after appears_s {self.appears_s}")
        return self

    def _legs_flyable(self) -> None:
        """motion legs: legs given, the initial speed > 0 and every accelerate leg's speed
        > 0 throughout (the speed changes on accelerate legs only)."""
        if not self.legs:
            raise ValueError("motion legs needs legs")
        speed = math.hypot(self.initial_state[2], self.initial_state[3])
        if not speed > 0:
            raise ValueError(
                "motion legs flies from the initial velocity: the initial speed must be > 0"
            )
        for i, leg in enumerate(self.legs):
            if leg.kind != "accelerate":
                continue
            assert leg.accel_mps2 is not None
            why = accelerate_problem(speed, leg.accel_mps2, leg.duration_s)
            if why is not None:
                raise ValueError(f"legs[{i}].accel_mps2: {leg.accel_mps2:g} m/s^2: {why}")
            speed += leg.accel_mps2 * leg.duration_s


class DetectionConfig(Section):
    """`detection:`: whether an echo is detected, and the false alarms."""

    model: Literal["fixed", "snr"] = Field(
        "fixed",
        description="fixed: detected with probability 1 - sensing.missed_detection_prob; snr: "
        "a Swerling-I echo against a threshold, P_d = exp(-threshold / SNR) with SNR the "
        "echo's over the CPI (docs/model.md, 'Several targets').",
    )
    snr_threshold_db: float | None = Field(None, description="snr only: the threshold, dB.")
    false_alarms_per_slot: float = Field(
        0.0, ge=0, description="Poisson mean of each UAV's false alarms per slot."
    )
    range_window_m: tuple[float, float] | None = Field(
        None,
        description="Where false alarms fall in range, m; null: 0 to the area's diagonal "
        "at the UAVs' altitude.",
    )
    doppler_window_mps: tuple[float, float] | None = Field(
        None, description="... and in radial velocity, m/s; null: +-60 m/s."
    )

    @model_validator(mode="after")
    def _consistent(self) -> DetectionConfig:
        if self.model == "snr" and self.snr_threshold_db is None:
            raise ValueError("model snr needs snr_threshold_db")
        if self.model == "fixed" and self.snr_threshold_db is not None:
            raise ValueError("snr_threshold_db is for model snr")
        for name in ("range_window_m", "doppler_window_mps"):
            window = getattr(self, name)
            if window is not None and not window[0] < window[1]:
                raise ValueError(f"{name}: [low, high] with low < high (got {list(window)})")
        if self.range_window_m is not None and self.range_window_m[0] < 0:
            raise ValueError("range_window_m: ranges are >= 0")
        return self


@dataclass(frozen=True)
class Leg:
    """One resolved leg of motion legs (SI units): kind ("straight", "turn", "accelerate"),
    duration_s (> 0), turn_rate_radps (turn: omega, rad/s, positive counter-clockwise; else 0),
    accel_mps2 (accelerate: along-track, m/s^2; else 0)."""

    kind: str
    duration_s: float
    turn_rate_radps: float = 0.0
    accel_mps2: float = 0.0


@dataclass(frozen=True)
class TargetSpec:
    """One resolved target (SI units): name; x0 [4] (m, m/s) at its first slot; rcs_m2; motion,
    turn_rate_radps, waypoints_xy_m [W, 2] as in `TargetEntry`; first_slot, last_slot: the slots
    n it is in the scene (first_slot..last_slot, slot 0 the start); prior_known; legs: motion
    legs' `Leg`s in order, timed from its first slot (() for the other motions)."""

    name: str
    x0: tuple[float, float, float, float]
    rcs_m2: float
    motion: str
    turn_rate_radps: float
    waypoints_xy_m: tuple[tuple[float, float], ...]
    first_slot: int
    last_slot: int
    prior_known: bool
    legs: tuple[Leg, ...] = ()

    def is_plain(self, n_slots: int) -> bool:
        """The paper's one target: constant velocity, known, in the scene for all n_slots (or
        longer: a study that shortens the mission keeps its target to the end)."""
        return (
            self.motion == "constant_velocity"
            and self.prior_known
            and self.first_slot == 0
            and self.last_slot >= n_slots
        )


@dataclass(frozen=True)
class DetectionSpec:
    """The resolved detection model: model ("fixed" or "snr"), detection_prob (fixed),
    snr_threshold (linear, snr), false_alarms_per_slot, range_window_m and doppler_window_mps
    (low, high)."""

    model: str
    detection_prob: float
    snr_threshold: float
    false_alarms_per_slot: float
    range_window_m: tuple[float, float]
    doppler_window_mps: tuple[float, float]

    @property
    def clutter_density(self) -> float:
        """lambda: the false alarms' mean number per unit of the window, per m * (m/s)."""
        (r_lo, r_hi), (v_lo, v_hi) = self.range_window_m, self.doppler_window_mps
        return self.false_alarms_per_slot / ((r_hi - r_lo) * (v_hi - v_lo))

    @property
    def is_default(self) -> bool:
        """The single-target model as before: a fixed probability and no false alarms."""
        return self.model == "fixed" and self.false_alarms_per_slot == 0
