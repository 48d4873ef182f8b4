"""The physical sections of a scenario file (timing, area, radio, base stations, UAVs, the
targets' motion, sensing, tracker, planner), as written in the YAML: dB and dBm where engineers
expect them. The targets themselves and the detection model: config/targets.py.

Each section is a frozen pydantic model that forbids unknown keys; every choice the paper leaves
open is a field whose description points at docs/model.md. `TargetConfig` (`target:`) is the
deprecated single-target section (docs/decisions/0001-one-scenario-schema.md).

The tracker's motion model (`tracker.motion`): cv, the paper's constant velocity, or imm, the
interacting multiple model of `tracker.imm:` (`ImmConfig`), resolved as `ImmSpec` on
`Scenario.imm` (config/resolve.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    ValidationInfo,
    field_validator,
    model_serializer,
    model_validator,
)

from isac_mission.tracking.gospa import CUTOFF_M


class Section(BaseModel):
    """Base of every scenario section: frozen, unknown keys rejected."""

    model_config = ConfigDict(frozen=True, extra="forbid")


class TimingConfig(Section):
    duration_s: float = Field(60.0, gt=0, description="T, mission duration.")
    slot_s: float = Field(1.0, gt=0, description="Delta t, slot length.")


class AreaConfig(Section):
    size_m: tuple[float, float] = Field(
        (3000.0, 3000.0), description="Width (x, east) and height (y, north) of the area."
    )

    @model_validator(mode="after")
    def _positive(self) -> AreaConfig:
        if min(self.size_m) <= 0:
            raise ValueError(f"size_m: both sides must be > 0 (got {list(self.size_m)})")
        return self


class RadioConfig(Section):
    bandwidth_hz: float = Field(20e6, gt=0, description="B, total bandwidth shared by FDMA.")
    carrier_hz: float = Field(28e9, gt=0, description="f_c, carrier frequency.")
    uav_tx_power_dbm: float = Field(20.0, description="P_t^u (0.1 W = 20 dBm).")
    bs_tx_power_dbm: float = Field(30.0, description="P_t^BS (1 W = 30 dBm).")
    noise_power_dbm: float = Field(
        -130.0, description="sigma_0^2, noise power over the whole band B (docs/model.md)."
    )
    ref_gain_db: float | None = Field(
        None,
        description="beta_0, channel gain at 1 m; null = free space (lambda/4pi)^2 (docs/model.md).",
    )
    rate_min_bps: float = Field(10e6, gt=0, description="R_th, minimum rate per UAV.")
    control_snr_min_db: float = Field(11.0, description="Gamma_th, control-link SNR threshold.")
    bs_capacity: int = Field(3, ge=1, description="N_a, UAVs one BS can serve.")


class BaseStationConfig(Section):
    count: int = Field(5, ge=1, description="K.")
    height_m: float = Field(15.0, ge=0, description="H^B.")
    placement_seed: int = Field(
        2025, ge=0, description="Seed of the uniform random BS layout (docs/model.md)."
    )
    xy_m: list[tuple[float, float]] | None = Field(
        None, description="Explicit BS positions; overrides the random layout."
    )

    @model_validator(mode="after")
    def _count_matches(self) -> BaseStationConfig:
        if self.xy_m is not None and len(self.xy_m) != self.count:
            raise ValueError(f"xy_m: has {len(self.xy_m)} positions but count is {self.count}")
        return self


class BatteryConfig(Section):
    """The simulated vehicles' energy model (docs/service.md, "Battery and the low-battery
    failsafe"): P = hover + per-speed * |v_h| + per-climb * climb rate while armed."""

    capacity_wh: float = Field(80.0, gt=0, description="Usable energy of a full pack, Wh.")
    capacity_wh_by_uav: dict[int, float] = Field(
        default_factory=dict,
        description="Per-UAV capacity overrides, Wh, by UAV index (e.g. {1: 2.0} for a test "
        "whose vehicle 1 runs low).",
    )
    start_remaining: float = Field(1.0, gt=0, le=1, description="Charge at start, (0, 1].")
    min_remaining: float = Field(
        0.5,
        ge=0,
        lt=1,
        description="Floor of the charge (PX4 SITL's SIM_BAT_MIN_PCT): 0 lets a pack run out "
        "and the low-battery failsafe fire.",
    )
    hover_power_w: float = Field(250.0, gt=0, description="Power drawn armed at rest, W.")
    speed_power_w_per_mps: float = Field(
        4.0, ge=0, description="Extra power per m/s of horizontal speed, W/(m/s)."
    )
    climb_power_w_per_mps: float = Field(
        30.0, ge=0, description="Extra power per m/s of climb rate, W/(m/s)."
    )
    low_thr: float = Field(0.15, ge=0, lt=1, description="BAT_LOW_THR, warning.")
    critical_thr: float = Field(0.07, ge=0, lt=1, description="BAT_CRIT_THR, return.")
    emergency_thr: float = Field(0.05, ge=0, lt=1, description="BAT_EMERGEN_THR, land.")

    @model_validator(mode="after")
    def _overrides_positive(self) -> BatteryConfig:
        if not self.emergency_thr <= self.critical_thr <= self.low_thr:
            raise ValueError(
                "thresholds must satisfy emergency_thr <= critical_thr <= low_thr "
                f"(got {self.emergency_thr}, {self.critical_thr}, {self.low_thr})"
            )
        for m, wh in self.capacity_wh_by_uav.items():
            if m < 0 or not wh > 0:
                raise ValueError(
                    f"capacity_wh_by_uav: UAV {m}: needs an index >= 0 and a capacity > 0 "
                    f"(got {wh})"
                )
        return self


class UavConfig(Section):
    altitude_m: float = Field(100.0, gt=0, description="H, flight altitude of UAVs and target.")
    start_xy_m: list[tuple[float, float]] = Field(
        default_factory=lambda: [(1500.0, 2300.0), (807.0, 1100.0), (2193.0, 1100.0)],
        min_length=1,
        description="q_{m,0}; M is its length.",
    )
    max_speed_mps: float = Field(25.0, gt=0, description="V_max.")
    safe_distance_m: float = Field(30.0, ge=0, description="D_s.")
    max_accel_mps2: float = Field(
        10.0,
        gt=0,
        description="Horizontal acceleration limit of the simulated vehicles (not in the paper's "
        "model, which has none; docs/model.md, 'Live service').",
    )
    battery: BatteryConfig = BatteryConfig()


PROCESS_NOISE_DESCRIPTION = (
    "kappa in W (eq. 4), m^2/s^3: the process noise of every target's constant-velocity or "
    "coordinated-turn motion, and the single-target tracker's and bound's model (docs/model.md)."
)
MAX_ACCEL_DESCRIPTION = (
    "a_T, how hard a target may manoeuvre off its constant-velocity prediction, m/s^2: the "
    "safety rule keeps D_s against every such motion over each leg and the evasion guard keeps "
    "each UAV able to dodge it (docs/model.md, 'Safety'). 0: the constant-velocity model only."
)


class TargetMotionConfig(Section):
    """`target_motion:`: how every target of `targets:` may move, scenario-wide (docs/model.md,
    "Several targets"): the process noise kappa (m^2/s^3) and the manoeuvre bound a_T (m/s^2)."""

    process_noise_intensity: float = Field(0.5, ge=0, description=PROCESS_NOISE_DESCRIPTION)
    max_accel_mps2: float = Field(2.0, ge=0, description=MAX_ACCEL_DESCRIPTION)


class TargetConfig(Section):
    """`target:`, deprecated (removed in 0.5.0): one target and the scenario's target motion in
    one section. Read as `targets:` with one entry (initial_state, rcs_dbsm) and
    `target_motion:` (process_noise_intensity, max_accel_mps2); see ScenarioFile."""

    initial_state: tuple[float, float, float, float] = Field(
        (600.0, 1600.0, 30.0, 0.0), description="x_0 = [x, y, vx, vy] in m and m/s."
    )
    process_noise_intensity: float = Field(0.5, ge=0, description=PROCESS_NOISE_DESCRIPTION)
    rcs_dbsm: float = Field(-10.0, description="sigma_RCS, dBsm.")
    max_accel_mps2: float = Field(2.0, ge=0, description=MAX_ACCEL_DESCRIPTION)


class SensingConfig(Section):
    model: Literal["radar_crb", "literal"] = Field(
        "radar_crb",
        description="radar_crb: alpha_d, alpha_v from the matched-filter CRB; literal: as printed.",
    )
    cpi_s: float = Field(
        0.01, gt=0, description="T^s, coherent processing interval (docs/model.md)."
    )
    alpha_d: float | None = Field(None, gt=0, description="literal model only.")
    alpha_v: float | None = Field(None, gt=0, description="literal model only.")
    missed_detection_prob: float = Field(0.0, ge=0, lt=1)

    @model_validator(mode="after")
    def _alphas_match_model(self) -> SensingConfig:
        given = self.alpha_d is not None or self.alpha_v is not None
        if self.model == "literal" and (self.alpha_d is None or self.alpha_v is None):
            raise ValueError("model literal needs both alpha_d and alpha_v")
        if self.model == "radar_crb" and given:
            raise ValueError(
                "alpha_d/alpha_v are derived by model radar_crb; remove them or use model: literal"
            )
        return self


class MultiTrackerConfig(Section):
    """`tracker.multi:`: the multi-target tracker and its metric (docs/model.md, "The
    multi-target tracker"); read on the multi-target path only. Given as the top-level
    `multi_target:` section before 0.5.0 (deprecated)."""

    association: Literal["jpda", "gnn"] = Field(
        "jpda",
        description="jpda: joint probabilistic data association; gnn: global nearest "
        "neighbour (docs/model.md, 'The multi-target tracker').",
    )
    gate_prob: float = Field(0.99, gt=0, lt=1, description="P_g of the association gate.")
    process_noise_intensity: float | None = Field(
        None,
        ge=0,
        description="kappa of the tracks' constant-velocity model, m^2/s^3; null: "
        "target_motion.process_noise_intensity. A turning target needs more (docs/model.md).",
    )
    hit_weight: float = Field(
        2.5,
        gt=0,
        description="A slot is a hit for a track when sum_m (1 - beta_m0) >= this (about three "
        "UAVs' measurements: two coarse ranges fit a ghost, docs/model.md).",
    )
    confirm_hits: int = Field(3, ge=1, description="Hits that confirm a tentative track...")
    confirm_window: int = Field(4, ge=1, description="... within its first this many slots.")
    delete_after_misses: int = Field(
        3,
        ge=1,
        description="A confirmed track is deleted after this many slots in a row without a hit.",
    )
    initiation_gate_prob: float = Field(
        0.999, gt=0, lt=1, description="Gate and residual test of a new track's measurements."
    )
    max_initial_position_std_m: float = Field(
        150.0, gt=0, description="A new track's largest position std, m."
    )
    max_target_speed_mps: float = Field(
        60.0, gt=0, description="The fastest intruder: a faster new track is clutter, m/s."
    )
    gospa_cutoff_m: float = Field(
        CUTOFF_M, gt=0, description="GOSPA's cut-off c, m (p = 2, alpha = 2)."
    )

    @model_validator(mode="after")
    def _window_holds_the_hits(self) -> MultiTrackerConfig:
        if self.confirm_hits > self.confirm_window:
            raise ValueError(
                f"confirm_hits {self.confirm_hits} cannot happen within confirm_window "
                f"{self.confirm_window} slots"
            )
        return self


TrackerKind = Literal["auto", "labelled", "multi"]
"""Which tracker a scenario uses (`tracker.kind`; docs/model.md, "Several targets")."""

TrackerMotion = Literal["cv", "imm"]
"""The tracker's motion model (`tracker.motion`): constant velocity, or the IMM of `tracker.imm:`."""

PROBABILITY_SUM_TOL = 1e-9
"""How far a row of the switching matrix, or the initial probabilities, may sum from 1."""


class ImmModeConfig(Section):
    """One mode of `tracker.imm.modes:`: its motion model and its process noise."""

    model: Literal["cv", "ct"] = Field(
        description="cv: constant velocity (eq. 3) with kappa; ct: a coordinated turn with the "
        "turn rate in the state, kappa on the velocity and q_omega on the turn rate."
    )
    process_noise_intensity: float = Field(
        ge=0, allow_inf_nan=False, description="kappa of this mode, m^2/s^3."
    )
    turn_rate_noise: float = Field(
        0.0,
        ge=0,
        allow_inf_nan=False,
        description="ct only: q_omega, the turn rate's process noise, rad^2/s^3 (0 on cv).",
    )

    @model_validator(mode="after")
    def _turn_noise_on_ct(self) -> ImmModeConfig:
        if self.model == "cv" and self.turn_rate_noise > 0:
            raise ValueError(
                f"turn_rate_noise is for model ct: a cv mode has no turn rate "
                f"(got {self.turn_rate_noise:g})"
            )
        return self


class ImmConfig(Section):
    """`tracker.imm:`: the interacting multiple model of `tracker.motion: imm` (its modes, the
    Markov switching between them, where it starts)."""

    modes: list[ImmModeConfig] = Field(
        min_length=2, max_length=4, description="The r models it mixes (2 to 4), in order."
    )
    switching: list[list[float]] = Field(
        description="The Markov matrix [r, r] per slot: row i the probabilities of going from "
        "mode i to each mode (entries in [0, 1], rows summing to 1)."
    )
    initial_probabilities: list[float] = Field(
        description="[r] each mode's probability at a track's start (summing to 1)."
    )
    initial_turn_rate_std_radps: float = Field(
        0.1,
        gt=0,
        allow_inf_nan=False,
        description="Std of the turn rate (mean 0) where a mode knows none: a new track's ct "
        "modes, and every cv mode (so that a ct mode mixed from it can take up a turn), rad/s.",
    )

    @field_validator("switching")
    @classmethod
    def _markov_matrix(cls, value: list[list[float]], info: ValidationInfo) -> list[list[float]]:
        modes = info.data.get("modes")
        r = len(value)
        if modes is not None and r != len(modes):
            raise ValueError(
                f"{r} rows for {len(modes)} modes: it must be {len(modes)} x {len(modes)}"
            )
        for i, row in enumerate(value):
            if len(row) != r:
                raise ValueError(f"row {i} has {len(row)} entries, not {r}: it must be square")
            _check_distribution(row, f"row {i}: ", f"row {i} sums")
        return value

    @field_validator("initial_probabilities")
    @classmethod
    def _distribution(cls, value: list[float], info: ValidationInfo) -> list[float]:
        modes = info.data.get("modes")
        if modes is not None and len(value) != len(modes):
            raise ValueError(f"{len(value)} probabilities for {len(modes)} modes")
        _check_distribution(value, "", "they sum")
        return value


def _check_distribution(values: list[float], where: str, sums: str) -> None:
    """ValueError unless values are probabilities summing to 1 (within PROBABILITY_SUM_TOL);
    the message starts with `where` (an entry out of [0, 1]) or `sums` (the total)."""
    bad = [p for p in values if not 0.0 <= p <= 1.0]
    if bad:
        raise ValueError(f"{where}{bad[0]:g} is not a probability in [0, 1]")
    total = math.fsum(values)
    if abs(total - 1.0) > PROBABILITY_SUM_TOL:
        raise ValueError(f"{sums} to {total:.12g}, not 1")


@dataclass(frozen=True)
class ImmModeSpec:
    """One resolved IMM mode: model ("cv" or "ct"), kappa_m2ps3 (kappa, m^2/s^3),
    turn_noise_rad2ps3 (q_omega, rad^2/s^3; 0 on cv)."""

    model: str
    kappa_m2ps3: float
    turn_noise_rad2ps3: float = 0.0


@dataclass(frozen=True)
class ImmSpec:
    """The resolved `tracker.imm:`: modes [r], switching [r][r] (row i: from mode i),
    initial_probabilities [r], initial_turn_rate_std_radps (rad/s)."""

    modes: tuple[ImmModeSpec, ...]
    switching: tuple[tuple[float, ...], ...]
    initial_probabilities: tuple[float, ...]
    initial_turn_rate_std_radps: float = 0.1

    @classmethod
    def from_config(cls, cfg: ImmConfig) -> ImmSpec:
        """The section in SI units (it is already: the names change, lists become tuples)."""
        return cls(
            modes=tuple(
                ImmModeSpec(m.model, m.process_noise_intensity, m.turn_rate_noise)
                for m in cfg.modes
            ),
            switching=tuple(tuple(row) for row in cfg.switching),
            initial_probabilities=tuple(cfg.initial_probabilities),
            initial_turn_rate_std_radps=cfg.initial_turn_rate_std_radps,
        )


class TrackerConfig(Section):
    """`tracker:`: which tracker the scenario uses (`kind`), the start of every track (P0) and
    the labelled tracker's settings (flat keys), and the multi-target tracker's (`multi:`)."""

    kind: TrackerKind = Field(
        "auto",
        description="auto: the labelled single-target EKF for one known constant-velocity "
        "target in the scene throughout with no false alarms and the fixed detection model, "
        "else the multi-target tracker (Scenario.multi_target); labelled: the labelled EKF, "
        "refused for a scenario that needs the multi-target tracker; multi: the multi-target "
        "tracker even for one plain target (docs/model.md, 'Several targets').",
    )
    initial_position_std_m: float = Field(
        10.0, gt=0, description="Std of the tracker's initial position error (P0), m."
    )
    initial_velocity_std_mps: float = Field(
        2.0, gt=0, description="Std of the tracker's initial velocity error (P0), m/s."
    )
    update_iterations: int = Field(
        1,
        ge=1,
        le=50,
        description="Labelled EKF: 1 is the paper's EKF; > 1 an iterated EKF (relinearised "
        "updates, docs/model.md).",
    )
    bound_prior: Literal["pcrb", "ekf"] = Field(
        "pcrb",
        description="Labelled EKF: the prior information of the planner's bound: its own "
        "recursion, or the EKF's P.",
    )
    multi: MultiTrackerConfig = Field(
        default_factory=MultiTrackerConfig,
        description="The multi-target tracker (association, initiation, confirmation, "
        "deletion, GOSPA); read on the multi-target path only.",
    )
    motion: TrackerMotion = Field(
        "cv",
        description="cv: constant velocity (eq. 3), every existing scenario; imm: the "
        "interacting multiple model of `imm:`.",
    )
    imm: ImmConfig | None = Field(
        None, description="motion imm only: its modes, switching and start (ImmConfig)."
    )

    @model_validator(mode="after")
    def _imm_with_motion_imm(self) -> TrackerConfig:
        if self.motion == "imm" and self.imm is None:
            raise ValueError(
                "motion imm needs imm (its modes, switching and initial_probabilities)"
            )
        if self.motion != "imm" and self.imm is not None:
            raise ValueError(f"imm is for motion imm, not {self.motion}")
        return self

    @model_serializer(mode="wrap")
    def _motion_when_set(self, handler: SerializerFunctionWrapHandler) -> Any:
        """The section as dumped: motion cv and imm null left out, so that every scenario of
        before the keys existed dumps as it did."""
        out = handler(self)
        if isinstance(out, dict) and out.get("motion") == "cv" and out.get("imm") is None:
            out.pop("motion", None)
            out.pop("imm", None)
        return out


class HorizonConfig(Section):
    """The receding-horizon planner (method `horizon`, planning/horizon.py; docs/model.md,
    "Receding horizon")."""

    length: int = Field(
        5, ge=1, le=10, description="L, slots planned ahead (slot n..n+L-1; docs/model.md)."
    )
    discount: float = Field(
        1.0, gt=0, le=1, description="gamma: horizon slot l's tr(PCRB) weighs gamma^l."
    )
    terminal_weight: float = Field(
        6.0,
        ge=0,
        description="Weight of the last horizon slot's tr(PCRB), a stand-in for the slots "
        "beyond the horizon (1 = none; docs/model.md).",
    )
    terminal_braking: bool = Field(
        True,
        description="Vehicle model: the horizon ends where each UAV could match the predicted "
        "target's velocity braking at a_max and still keep the last slot's clearance, so that "
        "the plan shifted by a slot can be continued (docs/model.md, 'The terminal row').",
    )
    max_iterations: int = Field(
        60,
        ge=1,
        description="IPOPT's iteration cap (no wall-clock limit): at the cap the last iterate "
        "is flown if it is feasible and below the start, else the per-slot plan (docs/model.md).",
    )
    leg_samples: int = Field(
        4,
        ge=1,
        le=16,
        description="Points per leg (interior and end) at which the safety distances are kept.",
    )
    pair_band: int = Field(
        4,
        ge=1,
        description="UAV-UAV rows of the horizon NLP: a fleet of more than 2 pair_band + 1 UAVs "
        "is planned on two problems with the rows of only the pairs up to pair_band and up to "
        "2 pair_band apart in an order of the fleet that every pair within reach fits; a slot "
        "whose pairs within reach fit neither flies the per-slot plan (planning/pairs.py; "
        "docs/model.md, 'The pairs within reach').",
    )
    decompose: Literal["none", "targets"] = Field(
        "none",
        description="none: one NLP for the whole fleet (the reference); targets: the UAVs "
        "grouped by their nearest target, groups that can couple within the horizon merged, "
        "each group planned on its own with its share of the band and the fleet's association, "
        "the plans recombined and checked, the per-slot plan where that fails "
        "(planning/decomposed.py).",
    )

    @model_serializer(mode="wrap")
    def _decompose_when_set(self, handler: SerializerFunctionWrapHandler) -> Any:
        """The section as dumped (the trace's config): decompose left out at none, so that every
        scenario of before the key existed dumps as it did."""
        out = handler(self)
        if isinstance(out, dict) and out.get("decompose") == "none":
            del out["decompose"]
        return out


class PlannerConfig(Section):
    association: Literal["resolve", "keep"] = Field(
        "resolve",
        description="resolve: P1-F.1 from q_{n-1} each slot; keep: Lemma 2 (docs/model.md).",
    )
    epsilon: float = Field(1e-3, gt=0, lt=1, description="Relative-decrease stop (Alg. 1, 2).")
    line_search_step: float = Field(0.05, gt=0, le=1, description="Delta omega of the line search.")
    max_ao_iterations: int = Field(8, ge=1)
    max_position_iterations: int = Field(8, ge=1)
    max_bandwidth_iterations: int = Field(8, ge=1)
    per_uav_steps: bool = Field(
        True,
        description="Line-search each UAV's own step after Algorithm 1's common one (docs/model.md).",
    )
    accel_limit_mps2: float | None = Field(
        None,
        gt=0,
        description="If set, each waypoint stays within a dt^2 / 4 of the vehicle's ballistic "
        "point q + v dt (reachable on a smooth leg); null = the paper's kinematics (docs/model.md).",
    )
    keep_in_area: bool = Field(
        True,
        description="Keep every waypoint inside the operating area (the vehicles' geofence; "
        "not in the paper, docs/model.md).",
    )
    polish: bool = Field(
        False,
        description="After Algorithm 2, solve the slot's exact problem with IPOPT from the SCA "
        "point and keep the better feasible plan (docs/model.md, 'Polish').",
    )
    polish_max_iterations: int = Field(
        50, ge=1, description="IPOPT's iteration cap of the polish (no wall-clock limit)."
    )
    solver: str = Field("CLARABEL", description="cvxpy solver for the SOCP subproblems.")
    vehicle_model: bool = Field(
        False,
        description="Plan on the vehicles' dynamics (model/vehicle.py: V_max and uavs.max_accel_"
        "mps2, positions and velocities at slot boundaries); false = the paper's kinematics.",
    )
    safety_margin: Literal["covariance", "none"] = Field(
        "covariance",
        description="covariance: 14j keeps D_s plus a margin from the predicted target "
        "covariance and 14i/14a a margin for the vehicles' tracking error (docs/model.md, "
        "'Safety'); none: D_s as printed in the paper.",
    )
    safety_confidence_sigma: float = Field(
        5.0,
        ge=0,
        description="k of the 14j margin: k standard deviations of the predicted target position.",
    )
    tracking_margin_m: float = Field(
        1.0,
        ge=0,
        description="The vehicles' tracking error of a planned leg, kept on 14i (twice), 14j "
        "and the rate and control ranges when safety_margin is on (docs/model.md, 'Safety'). "
        "Default: the measured worst deviation of the simulated vehicle from plans at the "
        "limits and from live-settings simulate runs (proposed, horizon), flown through the "
        "bridge's setpoints (0.72 m, lockstep; tests/numerics/test_tracking_error.py), rounded "
        "up (docs/model.md, 'Vehicle model').",
    )
    newcomer_weight: float = Field(
        1.0,
        ge=0,
        le=1,
        description="A tentative track's weight in the objective, times its existence (its hits "
        "over the hits that confirm it) and its priority: the fleet places a newcomer before "
        "it is confirmed (docs/model.md, 'Planning for several targets'); 0 = tentative tracks "
        "are only kept clear of, as before the key existed (a trace's config without it).",
    )
    horizon: HorizonConfig = HorizonConfig()
    feasibility_tol_m: float = Field(
        1e-6, gt=0, description="Slack allowed when re-checking 14a-14j on a returned plan."
    )

    @model_serializer(mode="wrap")
    def _newcomer_weight_when_set(self, handler: SerializerFunctionWrapHandler) -> Any:
        """The section as dumped (the trace's config): newcomer_weight left out at 0, so that a
        trace without it reads as what it is, planned with tentative tracks kept clear of only
        (as every trace written before the key existed)."""
        out = handler(self)
        if isinstance(out, dict) and out.get("newcomer_weight") == 0.0:
            del out["newcomer_weight"]
        return out
