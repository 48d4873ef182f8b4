"""The intruders: the `targets:` list of a scenario file and the detection model
(`detection:`), as written (docs/model.md, "Several targets").

`targets:` is the one way to give targets: a list, one entry for the paper's single target. How
every target may move, scenario-wide (the process noise kappa, the manoeuvre bound a_T), is
`target_motion:` (config/sections.py); the deprecated `target:` section is read as a list of one
(config/scenario.py). Resolved into SI units as `TargetSpec`s on `Scenario.targets`
(config/resolve.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from pydantic import Field, model_validator

from isac_mission.config.sections import MultiTrackerConfig, Section

__all__ = [
    "DetectionConfig",
    "DetectionSpec",
    "MultiTrackerConfig",
    "TargetEntry",
    "TargetSpec",
]
"""MultiTrackerConfig lives in config/sections.py (`tracker.multi:`); importable here as before."""


class TargetEntry(Section):
    """One intruder of `targets:`."""

    name: str | None = Field(
        None, max_length=64, description="A label for reports; default target-<index>."
    )
    initial_state: tuple[float, float, float, float] = Field(
        description="[x, y, vx, vy] (m, m/s) when it appears (x_0 for the paper's one target)."
    )
    rcs_dbsm: float = Field(-10.0, description="sigma_RCS of this target, dBsm.")
    motion: Literal["constant_velocity", "coordinated_turn", "waypoints"] = Field(
        "constant_velocity",
        description="constant_velocity: eq. 3 with the scenario's process noise "
        "(target_motion.process_noise_intensity); "
        "coordinated_turn: turning at turn_rate_radps, with the same noise; waypoints: "
        "straight legs through waypoints_xy_m at the initial speed, no noise.",
    )
    turn_rate_radps: float | None = Field(
        None, description="coordinated_turn only: omega, rad/s (positive: counter-clockwise)."
    )
    waypoints_xy_m: list[tuple[float, float]] | None = Field(
        None, min_length=1, description="waypoints only: where it flies after its start, m."
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
        if self.leaves_s is not None and self.leaves_s <= self.appears_s:
            raise ValueError(f"leaves_s {self.leaves_s} must be after appears_s {self.appears_s}")
        return self


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
class TargetSpec:
    """One resolved target (SI units): name; x0 [4] (m, m/s) at its first slot; rcs_m2; motion,
    turn_rate_radps, waypoints_xy_m [W, 2] as in `TargetEntry`; first_slot, last_slot: the slots
    n it is in the scene (first_slot..last_slot, slot 0 the start); prior_known."""

    name: str
    x0: tuple[float, float, float, float]
    rcs_m2: float
    motion: str
    turn_rate_radps: float
    waypoints_xy_m: tuple[tuple[float, float], ...]
    first_slot: int
    last_slot: int
    prior_known: bool

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
