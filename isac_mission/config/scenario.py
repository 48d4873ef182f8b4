"""The scenario: `ScenarioFile` (the YAML as written) and `Scenario` (resolved, SI units, named
after the paper's symbols)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, replace
from typing import Any

from pydantic import Field, model_validator

from isac_mission.config.impairment import ImpairmentConfig
from isac_mission.config.links import LinksConfig
from isac_mission.config.sections import (
    AreaConfig,
    BaseStationConfig,
    BatteryConfig,
    PlannerConfig,
    RadioConfig,
    Section,
    SensingConfig,
    TargetConfig,
    TimingConfig,
    TrackerConfig,
    UavConfig,
)
from isac_mission.config.security import SecurityConfig
from isac_mission.config.signing import MavlinkSigningKey
from isac_mission.config.targets import (
    DetectionConfig,
    DetectionSpec,
    MultiTrackerConfig,
    TargetEntry,
    TargetSpec,
)
from isac_mission.types import FloatArray


class ScenarioFile(Section):
    """The YAML file as written (dB units). See config/paper.yaml for every key."""

    mission_id: str = Field("paper", pattern=r"^[A-Za-z0-9_-]+$")
    seed: int = Field(1, ge=0, description="Base seed of the Monte Carlo runs.")
    timing: TimingConfig = TimingConfig()
    area: AreaConfig = AreaConfig()
    radio: RadioConfig = RadioConfig()
    base_stations: BaseStationConfig = BaseStationConfig()
    uavs: UavConfig = UavConfig()
    target: TargetConfig = TargetConfig()
    targets: list[TargetEntry] | None = Field(
        None,
        min_length=1,
        description="Several intruders (config/targets.py); null: the one under target:.",
    )
    sensing: SensingConfig = SensingConfig()
    detection: DetectionConfig = DetectionConfig()
    tracker: TrackerConfig = TrackerConfig()
    multi_target: MultiTrackerConfig = MultiTrackerConfig()
    planner: PlannerConfig = PlannerConfig()
    security: SecurityConfig = SecurityConfig()
    impairment: ImpairmentConfig = ImpairmentConfig()
    links: LinksConfig = LinksConfig()

    @model_validator(mode="after")
    def _one_way_to_give_targets(self) -> ScenarioFile:
        if self.targets is not None:
            both = {"initial_state", "rcs_dbsm"} & self.target.model_fields_set
            if both:
                raise ValueError(
                    f"target.{sorted(both)[0]}: give the targets under targets: (a list) or one "
                    "under target:, not both (target.process_noise_intensity stays the "
                    "scenario's process noise)"
                )
        return self


@dataclass(frozen=True)
class Scenario:
    """A resolved scenario in SI units, named after the paper's symbols.

    Arrays: bs_xy [K, 2], uav_start_xy [M, 2], x0 [4], P0 [4, 4], area [2].
    """

    mission_id: str
    seed: int
    M: int
    K: int
    N: int
    dt: float
    area: FloatArray
    B: float
    fc: float
    wavelength: float
    Pu: float
    P_bs: float
    noise_w: float
    beta0: float
    rho0: float
    r_th: float
    gamma_th: float
    n_a: int
    d_th: float
    H: float
    H_bs: float
    dH: float
    bs_xy: FloatArray
    uav_start_xy: FloatArray
    v_max: float
    d_safe: float
    a_max: float
    x0: FloatArray
    kappa: float
    rcs_m2: float
    a_target: float
    """target.max_accel_mps2 (m/s^2): the target's manoeuvre bound (docs/model.md, "Safety")."""
    sensing_model: str
    Ts: float
    alpha_d: float
    alpha_v: float
    missed_detection_prob: float
    P0: FloatArray
    bound_prior: str
    ekf_iterations: int
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    battery: BatteryConfig = field(default_factory=BatteryConfig)
    """The simulated vehicles' energy model (uavs.battery)."""
    security: SecurityConfig = field(default_factory=SecurityConfig)
    mavlink_signing_key: MavlinkSigningKey | None = None
    """Resolved from security.mavlink_signing; None when signing is off. Never traced."""
    impairment: ImpairmentConfig = field(default_factory=ImpairmentConfig)
    """Fault injection on the simulated world's links (read by `sim` only; not traced)."""
    links: LinksConfig = field(default_factory=LinksConfig)
    """MAVLink ports of the live system (PX4 SITL's layout; the CLI's options override them)."""
    targets: tuple[TargetSpec, ...] = ()
    """Every intruder (config/targets.py); () on a Scenario built by hand: the one at x0. On the
    single-target path the loops read x0, kappa and rcs_m2 (which `with_changes` may change),
    never targets[0]."""
    detection: DetectionSpec | None = None
    """The detection model (detection:); None on a Scenario built by hand: fixed, no clutter."""
    multi_tracker: MultiTrackerConfig = field(default_factory=MultiTrackerConfig)
    """The multi-target tracker (multi_target:), read on the multi-target path only."""

    @property
    def multi_target(self) -> bool:
        """More than one target, a target that turns, flies waypoints, comes, goes or must be
        found, or detections with false alarms or an SNR model: the multi-target path; False on
        every single-target scenario as before."""
        if len(self.targets) > 1 or (self.detection is not None and not self.detection.is_default):
            return True
        return bool(self.targets) and not self.targets[0].is_plain(self.N)

    @property
    def radar_gain(self) -> float:
        """c0 in SNR^s = c0 / d^4 [m^4]: lambda^2 Pu sigma_RCS / ((4 pi)^3 sigma_0^2)."""
        return self.wavelength**2 * self.Pu * self.rcs_m2 / ((4 * math.pi) ** 3 * self.noise_w)

    def with_changes(self, **changes: Any) -> Scenario:
        """A copy with some fields replaced (no re-validation: for studies and tests). A new N
        keeps a target that was in the scene to the end in it to the new end (a longer mission
        of paper.yaml is still its one plain target, not the multi-target path)."""
        if "N" in changes and "targets" not in changes:
            n_slots = int(changes["N"])
            changes["targets"] = tuple(
                dataclasses.replace(t, last_slot=n_slots) if t.last_slot >= self.N else t
                for t in self.targets
            )
        return replace(self, **changes)

    def trace_config(self) -> dict[str, Any]:
        """Every resolved parameter under the trace's names (docs/trace.md), JSON-ready."""
        return {
            "mission_id": self.mission_id,
            "M": self.M,
            "K": self.K,
            "N": self.N,
            "dt": self.dt,
            "area": self.area.tolist(),
            "B": self.B,
            "fc": self.fc,
            "Pu": self.Pu,
            "P_bs": self.P_bs,
            "noise_w": self.noise_w,
            "rcs_m2": self.rcs_m2,
            "H": self.H,
            "H_bs": self.H_bs,
            "alpha_d": self.alpha_d,
            "alpha_v": self.alpha_v,
            "Ts": self.Ts,
            "kappa": self.kappa,
            "v_max": self.v_max,
            "d_safe": self.d_safe,
            "a_max": self.a_max,
            "a_target": self.a_target,
            "gamma_th": self.gamma_th,
            "r_th": self.r_th,
            "n_a": self.n_a,
            "beta0": self.beta0,
            "rho0": self.rho0,
            "d_th": self.d_th,
            "bs_xy": self.bs_xy.tolist(),
            "uav_start_xy": self.uav_start_xy.tolist(),
            "x0": self.x0.tolist(),
            "P0": self.P0.tolist(),
            "sensing_model": self.sensing_model,
            "missed_detection_prob": self.missed_detection_prob,
            "bound_prior": self.bound_prior,
            "ekf_iterations": self.ekf_iterations,
            "planner": self.planner.model_dump(),
            **(self._multi_target_config() if self.multi_target else {}),
        }

    def _multi_target_config(self) -> dict[str, Any]:
        """The trace config of the multi-target path (absent from single-target traces)."""
        return {
            "targets": [dataclasses.asdict(t) for t in self.targets],
            "detection": None if self.detection is None else dataclasses.asdict(self.detection),
            "multi_target": self.multi_tracker.model_dump(),
        }


def single_target_problem(s: Scenario) -> str | None:
    """Why `sweep` and `replay` cannot take `s` yet, or None: the multi-target path (several
    targets, false alarms, an SNR detection model, a target that turns, comes late or must be
    found) has its tracker, its offline closed loop (`simulate`) and its live service (`run`,
    `serve`, `sim`), but not yet a sweep or a replay."""
    if not s.multi_target:
        return None
    return (
        "targets/detection: this scenario takes the multi-target path (docs/model.md, "
        "'Several targets'): `simulate`, `run`, `serve` and `sim` fly it; `sweep` and "
        "`replay` take single-target scenarios only, so far"
    )
