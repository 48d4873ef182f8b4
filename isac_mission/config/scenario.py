"""The scenario: `ScenarioFile` (the YAML as written) and `Scenario` (resolved, SI units, named
after the paper's symbols).

One schema (docs/decisions/0001-one-scenario-schema.md): the targets under `targets:` (a list),
how they may move under `target_motion:`, one `tracker:` section (`kind`, the labelled EKF's keys,
the multi-target tracker's under `multi:`). The sections of before, `target:` and
`multi_target:`, are still read, each with a DeprecationWarning (`ScenarioFile.deprecations`),
until 0.5.0.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from pydantic import Field, model_validator

from isac_mission.config.impairment import ImpairmentConfig
from isac_mission.config.links import LinksConfig
from isac_mission.config.priorities import PriorityEntry
from isac_mission.config.sections import (
    AreaConfig,
    BaseStationConfig,
    BatteryConfig,
    ImmSpec,
    PlannerConfig,
    RadioConfig,
    Section,
    SensingConfig,
    TargetConfig,
    TargetMotionConfig,
    TimingConfig,
    TrackerConfig,
    TrackerKind,
    TrackerMotion,
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
from isac_mission.deprecation import REMOVAL_VERSION
from isac_mission.model.motion import ConstantVelocity, MotionModel, stationary_probabilities
from isac_mission.tracking.priorities import PriorityChange
from isac_mission.types import FloatArray

SCHEMA_REMOVAL_VERSION = REMOVAL_VERSION
"""The release that drops the deprecated sections `target:` and `multi_target:` (the package's
next minor)."""

DEFAULT_TARGET_STATE: tuple[float, float, float, float] = (600.0, 1600.0, 30.0, 0.0)
"""x_0 = [x, y, vx, vy] (m, m/s) of the default target: the paper's."""

TARGET_ENTRY_KEYS = ("initial_state", "rcs_dbsm")
"""The keys of the deprecated `target:` that are its one entry of `targets:`."""

TARGET_MOTION_KEYS = ("process_noise_intensity", "max_accel_mps2")
"""The keys of the deprecated `target:` that are `target_motion:`'s."""


class ScenarioFile(Section):
    """The YAML file as written (dB units). See config/paper.yaml for every key."""

    mission_id: str = Field("paper", pattern=r"^[A-Za-z0-9_-]+$")
    seed: int = Field(1, ge=0, description="Base seed of the Monte Carlo runs.")
    timing: TimingConfig = TimingConfig()
    area: AreaConfig = AreaConfig()
    radio: RadioConfig = RadioConfig()
    base_stations: BaseStationConfig = BaseStationConfig()
    uavs: UavConfig = UavConfig()
    targets: list[TargetEntry] = Field(
        default_factory=lambda: [TargetEntry(initial_state=DEFAULT_TARGET_STATE)],
        min_length=1,
        description="The intruders (config/targets.py), one entry per target; default: the "
        "paper's one target.",
    )
    target_motion: TargetMotionConfig = TargetMotionConfig()
    sensing: SensingConfig = SensingConfig()
    detection: DetectionConfig = DetectionConfig()
    tracker: TrackerConfig = TrackerConfig()
    planner: PlannerConfig = PlannerConfig()
    security: SecurityConfig = SecurityConfig()
    impairment: ImpairmentConfig = ImpairmentConfig()
    links: LinksConfig = LinksConfig()
    priorities: list[PriorityEntry] = Field(
        default_factory=list,
        description="Scripted changes of the tracks' priorities (config/priorities.py): "
        "[{slot, track, weight}, ...]; none by default (every track weighs 1).",
    )
    target: TargetConfig | None = Field(
        None,
        description=f"Deprecated, removed in {SCHEMA_REMOVAL_VERSION}: one target "
        "(initial_state, rcs_dbsm: use targets:) and the targets' motion "
        "(process_noise_intensity, max_accel_mps2: use target_motion:).",
        json_schema_extra={"deprecated": True},
    )
    multi_target: MultiTrackerConfig | None = Field(
        None,
        description=f"Deprecated, removed in {SCHEMA_REMOVAL_VERSION}: use tracker.multi: "
        "(the same keys).",
        json_schema_extra={"deprecated": True},
    )

    @model_validator(mode="after")
    def _each_setting_given_once(self) -> ScenarioFile:
        given = self.model_fields_set
        if self.target is not None:
            placed = sorted(set(TARGET_ENTRY_KEYS) & self.target.model_fields_set)
            if placed and "targets" in given:
                raise ValueError(
                    f"target.{placed[0]}: give the targets under targets: only (a list; "
                    "target: is deprecated)"
                )
            moved = sorted(set(TARGET_MOTION_KEYS) & self.target.model_fields_set)
            if moved and "target_motion" in given:
                raise ValueError(
                    f"target.{moved[0]}: give it under target_motion: only (target: is deprecated)"
                )
        if self.multi_target is not None and "multi" in self.tracker.model_fields_set:
            raise ValueError(
                "multi_target: give the multi-target tracker under tracker.multi: only "
                "(multi_target: is deprecated)"
            )
        return self

    def deprecations(self) -> list[str]:
        """One message per deprecated section this file uses (none for the one schema); each
        reads "<section> is deprecated: use <replacement>" and names the version that removes
        it."""
        out = []
        if self.target is not None:
            keys = self.target.model_fields_set
            use = []
            if not keys or keys & set(TARGET_ENTRY_KEYS):
                use.append("targets: (a list; one entry with initial_state and rcs_dbsm)")
            if not keys or keys & set(TARGET_MOTION_KEYS):
                use.append("target_motion: (process_noise_intensity, max_accel_mps2)")
            out.append(
                f"target: is deprecated: use {' and '.join(use)}; target: is removed in "
                f"{SCHEMA_REMOVAL_VERSION} (docs/decisions/0001-one-scenario-schema.md)"
            )
        if self.multi_target is not None:
            out.append(
                "multi_target: is deprecated: use tracker.multi: (the same keys); "
                f"multi_target: is removed in {SCHEMA_REMOVAL_VERSION} "
                "(docs/decisions/0001-one-scenario-schema.md)"
            )
        return out

    def in_one_schema(self) -> ScenarioFile:
        """This file in the one schema: `target:` read as `targets:` with one entry and
        `target_motion:`, `multi_target:` as `tracker.multi:`; neither deprecated section left.
        The same file when it uses neither."""
        if self.target is None and self.multi_target is None:
            return self
        update: dict[str, Any] = {"target": None, "multi_target": None}
        t = self.target
        if t is not None:
            if "targets" not in self.model_fields_set:
                update["targets"] = [
                    TargetEntry(initial_state=t.initial_state, rcs_dbsm=t.rcs_dbsm)
                ]
            if "target_motion" not in self.model_fields_set:
                update["target_motion"] = TargetMotionConfig(
                    process_noise_intensity=t.process_noise_intensity,
                    max_accel_mps2=t.max_accel_mps2,
                )
        if self.multi_target is not None:
            update["tracker"] = self.tracker.model_copy(update={"multi": self.multi_target})
        return self.model_copy(update=update)


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
    """target_motion.max_accel_mps2 (m/s^2): the targets' manoeuvre bound (docs/model.md,
    "Safety")."""
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
    """The multi-target tracker (tracker.multi:), read on the multi-target path only."""
    tracker_kind: TrackerKind = "auto"
    """tracker.kind: auto (the rule of `multi_target`), labelled (resolve refused it for a
    scenario that needs the multi-target tracker) or multi (the multi-target tracker always)."""
    priority_changes: tuple[PriorityChange, ...] = ()
    """The scripted priority changes (priorities:; tracking/priorities.py), in the file's
    order; () by default."""
    tracker_motion: TrackerMotion = "cv"
    """tracker.motion: cv (constant velocity, eq. 3; every scenario before the key) or imm (the
    interacting multiple model of `imm`)."""
    imm: ImmSpec | None = None
    """tracker.imm resolved (config/sections.py): set exactly when tracker_motion is imm."""

    @property
    def multi_target(self) -> bool:
        """The multi-target path: tracker.kind multi, or tracker.motion imm (the IMM runs on
        that tracker's tracks, for one target as for several), or (auto, labelled) more than one
        target, a target that turns, flies waypoints or legs, comes, goes or must be found, or
        detections with false alarms or an SNR model (`multi_target_reasons`); False on every
        single-target scenario as before."""
        if self.tracker_kind == "multi" or self.tracker_motion == "imm":
            return True
        if len(self.targets) > 1 or (self.detection is not None and not self.detection.is_default):
            return True
        return bool(self.targets) and not self.targets[0].is_plain(self.N)

    @property
    def motion(self) -> MotionModel:
        """How the bounds and the planner believe a target moves (model/motion.py): constant
        velocity with kappa (eq. 3-4); with the IMM (tracker.motion imm), constant velocity with
        its modes' intensities mixed by the long-run share of each mode (the stationary
        distribution of its switching; docs/model.md, "The interacting multiple model")."""
        if self.imm is None:
            return self.truth_motion
        share = stationary_probabilities(np.array(self.imm.switching))
        return ConstantVelocity(float(share @ [m.kappa_m2ps3 for m in self.imm.modes]))

    @property
    def truth_motion(self) -> ConstantVelocity:
        """How a noisy true target moves (model/targets.py, the labelled target's truth):
        constant velocity with kappa (eq. 3-4)."""
        return ConstantVelocity(self.kappa)

    @property
    def radar_gain(self) -> float:
        """c0 in SNR^s = c0 / d^4 [m^4]: lambda^2 Pu sigma_RCS / ((4 pi)^3 sigma_0^2)."""
        return self.wavelength**2 * self.Pu * self.rcs_m2 / ((4 * math.pi) ** 3 * self.noise_w)

    def with_changes(self, **changes: Any) -> Scenario:
        """A copy with some fields replaced (no re-validation: for studies and tests). A new N
        keeps a target that was in the scene to the end in it to the new end (a longer mission
        of paper.yaml is still its one plain target, not the multi-target path); a new x0 is
        the first target's initial state, as `targets[0].x0` (the tracker's cue for it)."""
        targets = changes.get("targets", self.targets)
        if "N" in changes and "targets" not in changes:
            n_slots = int(changes["N"])
            targets = tuple(
                dataclasses.replace(t, last_slot=n_slots) if t.last_slot >= self.N else t
                for t in targets
            )
        if "x0" in changes and "targets" not in changes and targets:
            x0 = tuple(float(v) for v in changes["x0"])
            targets = (dataclasses.replace(targets[0], x0=x0), *targets[1:])
        if targets is not self.targets:
            changes["targets"] = targets
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
            **(self._priorities_config() if self.priority_changes else {}),
            **(self._tracker_motion_config() if self.tracker_motion != "cv" else {}),
        }

    def _tracker_motion_config(self) -> dict[str, Any]:
        """The tracker's motion model as the trace config states it (absent: cv, as every trace
        written before tracker.motion existed)."""
        return {
            "tracker_motion": self.tracker_motion,
            "imm": None if self.imm is None else dataclasses.asdict(self.imm),
        }

    def _priorities_config(self) -> dict[str, Any]:
        """The scripted priority changes as the trace config states them (absent: none)."""
        return {
            "priorities": [
                {"slot": c.slot, "track": c.track_id, "weight": c.priority}
                for c in self.priority_changes
            ]
        }

    def _multi_target_config(self) -> dict[str, Any]:
        """The trace config of the multi-target path (absent from single-target traces)."""
        return {
            "targets": [_target_config(t) for t in self.targets],
            "detection": None if self.detection is None else dataclasses.asdict(self.detection),
            "multi_target": self.multi_tracker.model_dump(),
        }


def _target_config(t: TargetSpec) -> dict[str, Any]:
    """A target as the trace config states it: its fields, legs left out when it has none (as
    every trace written before motion legs existed)."""
    out = dataclasses.asdict(t)
    if not t.legs:
        del out["legs"]
    return out


def multi_target_reasons(s: Scenario) -> list[str]:
    """Why the labelled single-target tracker cannot track `s` (what makes `tracker.kind: auto`
    take the multi-target path), in words; [] for one known constant-velocity target in the scene
    throughout with the fixed detection model and no false alarms (or a Scenario built by hand
    without targets)."""
    out = []
    if len(s.targets) > 1:
        out.append(f"{len(s.targets)} targets")
    elif s.targets and not s.targets[0].is_plain(s.N):
        t = s.targets[0]
        if t.motion != "constant_velocity":
            out.append(f"target {t.name} moves by {t.motion}")
        if not t.prior_known:
            out.append(f"target {t.name} must be found (prior unknown)")
        if t.first_slot > 0:
            out.append(f"target {t.name} appears at slot {t.first_slot}")
        if t.last_slot < s.N:
            out.append(f"target {t.name} leaves at slot {t.last_slot}")
    if s.tracker_motion == "imm":
        out.append("tracker.motion imm (the IMM runs on the multi-target tracker's tracks)")
    d = s.detection
    if d is not None and d.model != "fixed":
        out.append(f"detection model {d.model}")
    if d is not None and d.false_alarms_per_slot > 0:
        out.append("false alarms")
    return out


def single_target_problem(s: Scenario) -> str | None:
    """Why `replay` (and `closed_loop.run_closed_loop`, the labelled target's loop) cannot take
    `s` yet, or None: the multi-target path (several targets, false alarms, an SNR detection
    model, a target that turns, comes late or must be found) has its tracker, its offline closed
    loop (`simulate`, `sweep`) and its live service (`run`, `serve`, `sim`), but not yet a
    replay."""
    if not s.multi_target:
        return None
    why = "targets/detection" if multi_target_reasons(s) else "tracker.kind multi"
    return (
        f"{why}: this scenario takes the multi-target path (docs/model.md, "
        "'Several targets'): `simulate`, `sweep`, `run`, `serve` and `sim` fly it; "
        "`replay` takes single-target scenarios only, so far"
    )
