"""Resolution: a validated `ScenarioFile` to a `Scenario` in SI units, with the paper's derived
constants (beta0, rho0, d_th, Gamma_th, the sensing alphas, the BS layout) and the cross-field
feasibility checks (M <= K N_a, start points in range and apart, ...)."""

from __future__ import annotations

import math

import numpy as np

from isac_mission.config.priorities import priority_problems
from isac_mission.config.scenario import Scenario, ScenarioFile, multi_target_reasons
from isac_mission.config.sections import ImmSpec
from isac_mission.config.signing import mavlink_signing_key
from isac_mission.config.targets import DetectionSpec, Leg, TargetSpec
from isac_mission.config.units import SPEED_OF_LIGHT_MPS, db_to_linear, dbm_to_w
from isac_mission.errors import ConfigError
from isac_mission.types import FloatArray


def radar_crb_alphas(bandwidth_hz: float, wavelength_m: float, cpi_s: float) -> tuple[float, float]:
    """alpha_d [m^2 Hz^2] and alpha_v [m^2/s^2 s^2] of eq. 8 from the matched-filter CRB.

    With noise PSD N0 = sigma_0^2 / B, the echo energy-to-noise ratio over the CPI is
    SNR^s B T^s whatever the share eta; a flat spectrum of width eta B has rms bandwidth
    eta B / sqrt(12) and a constant envelope of length T^s has rms duration T^s / sqrt(12).
    The delay and Doppler CRBs then give (docs/model.md, "Sensing noise"):
      sigma_d^2 = 3 c^2 / (8 pi^2 B T^s) / (SNR^s (eta B)^2)
      sigma_v^2 = 3 lambda^2 / (8 pi^2 B T^s) / (SNR^s (T^s)^2).
    """
    scale = 3.0 / (8.0 * math.pi**2 * bandwidth_hz * cpi_s)
    return scale * SPEED_OF_LIGHT_MPS**2, scale * wavelength_m**2


def random_bs_layout(count: int, area_m: FloatArray, seed: int) -> FloatArray:
    """[K, 2] BS positions drawn uniformly in the area with a fixed seed."""
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 1.0, size=(count, 2)) * area_m


def resolve(spec: ScenarioFile) -> Scenario:
    """Convert a validated file to SI units and derive the paper's constants. A file with the
    deprecated sections (`target:`, `multi_target:`) is read in the one schema
    (`ScenarioFile.in_one_schema`); `parse_scenario` is what warns about them.

    Raises ConfigError for cross-field problems (UAVs closer than D_s, out of control range, ...).
    """
    single_section = spec.target is not None and "targets" not in spec.model_fields_set
    spec = spec.in_one_schema()
    radio, bs, uav, sens = spec.radio, spec.base_stations, spec.uavs, spec.sensing
    motion = spec.target_motion
    wavelength = SPEED_OF_LIGHT_MPS / radio.carrier_hz
    beta0 = (
        db_to_linear(radio.ref_gain_db)
        if radio.ref_gain_db is not None
        else (wavelength / (4 * math.pi)) ** 2
    )
    Pu, P_bs, noise_w = (
        dbm_to_w(radio.uav_tx_power_dbm),
        dbm_to_w(radio.bs_tx_power_dbm),
        dbm_to_w(radio.noise_power_dbm),
    )
    gamma_th = db_to_linear(radio.control_snr_min_db)
    dH = uav.altitude_m - bs.height_m
    area = np.asarray(spec.area.size_m, dtype=float)
    bs_xy = (
        np.asarray(bs.xy_m, dtype=float)
        if bs.xy_m is not None
        else random_bs_layout(bs.count, area, bs.placement_seed)
    )
    d_th_sq = P_bs * beta0 / (noise_w * gamma_th) - dH**2
    if sens.model == "radar_crb":
        alpha_d, alpha_v = radar_crb_alphas(radio.bandwidth_hz, wavelength, sens.cpi_s)
    else:
        assert sens.alpha_d is not None and sens.alpha_v is not None
        alpha_d, alpha_v = sens.alpha_d, sens.alpha_v
    sp, sv = spec.tracker.initial_position_std_m, spec.tracker.initial_velocity_std_mps
    n_slots = spec.timing.duration_s / spec.timing.slot_s
    targets = resolve_targets(spec, round(n_slots))
    scenario = Scenario(
        mission_id=spec.mission_id,
        seed=spec.seed,
        M=len(uav.start_xy_m),
        K=bs.count,
        N=round(n_slots),
        dt=spec.timing.slot_s,
        area=area,
        B=radio.bandwidth_hz,
        fc=radio.carrier_hz,
        wavelength=wavelength,
        Pu=Pu,
        P_bs=P_bs,
        noise_w=noise_w,
        beta0=beta0,
        rho0=Pu * beta0 / noise_w,
        r_th=radio.rate_min_bps,
        gamma_th=gamma_th,
        n_a=radio.bs_capacity,
        d_th=math.sqrt(d_th_sq) if d_th_sq > 0 else 0.0,
        H=uav.altitude_m,
        H_bs=bs.height_m,
        dH=dH,
        bs_xy=bs_xy,
        uav_start_xy=np.asarray(uav.start_xy_m, dtype=float),
        v_max=uav.max_speed_mps,
        d_safe=uav.safe_distance_m,
        a_max=uav.max_accel_mps2,
        x0=np.asarray(targets[0].x0, dtype=float),
        kappa=motion.process_noise_intensity,
        a_target=motion.max_accel_mps2,
        rcs_m2=targets[0].rcs_m2,
        sensing_model=sens.model,
        Ts=sens.cpi_s,
        alpha_d=alpha_d,
        alpha_v=alpha_v,
        missed_detection_prob=sens.missed_detection_prob,
        P0=np.diag([sp**2, sp**2, sv**2, sv**2]),
        bound_prior=spec.tracker.bound_prior,
        ekf_iterations=spec.tracker.update_iterations,
        planner=spec.planner,
        battery=uav.battery,
        security=spec.security,
        mavlink_signing_key=mavlink_signing_key(spec.security.mavlink_signing),
        impairment=spec.impairment,
        links=spec.links,
        targets=targets,
        detection=resolve_detection(spec),
        multi_tracker=spec.tracker.multi,
        tracker_kind=spec.tracker.kind,
        tracker_motion=spec.tracker.motion,
        imm=None if spec.tracker.imm is None else ImmSpec.from_config(spec.tracker.imm),
        priority_changes=tuple(e.change() for e in spec.priorities),
    )
    problems = _cross_field_problems(scenario, n_slots, single_section)
    problems += priority_problems(spec.priorities, scenario.N)
    if problems:
        raise ConfigError("\n".join(problems))
    return scenario


def resolve_targets(spec: ScenarioFile, n_slots: int) -> tuple[TargetSpec, ...]:
    """The scenario's targets, `targets:` in order (the deprecated `target:` read as its one
    entry). A target's slots are those from ceil(appears_s / dt) to floor(leaves_s / dt) (N at
    most); motion legs' legs are timed from its first slot."""
    dt = spec.timing.slot_s
    out = []
    for i, e in enumerate(spec.in_one_schema().targets):
        first = math.ceil(e.appears_s / dt - 1e-9)
        last = n_slots if e.leaves_s is None else min(n_slots, math.floor(e.leaves_s / dt + 1e-9))
        out.append(
            TargetSpec(
                name=e.name or f"target-{i}",
                x0=e.initial_state,
                rcs_m2=db_to_linear(e.rcs_dbsm),
                motion=e.motion,
                turn_rate_radps=e.turn_rate_radps or 0.0,
                waypoints_xy_m=tuple(e.waypoints_xy_m or ()),
                first_slot=first,
                last_slot=last,
                prior_known=e.prior == "known",
                legs=tuple(
                    Leg(leg.kind, leg.duration_s, leg.turn_rate_radps or 0.0, leg.accel_mps2 or 0.0)
                    for leg in e.legs or ()
                ),
            )
        )
    return tuple(out)


def resolve_detection(spec: ScenarioFile) -> DetectionSpec:
    """The detection model in SI units, its windows' defaults filled in (config/targets.py)."""
    d = spec.detection
    diagonal = math.hypot(*spec.area.size_m)
    height = spec.uavs.altitude_m
    return DetectionSpec(
        model=d.model,
        detection_prob=1.0 - spec.sensing.missed_detection_prob,
        snr_threshold=0.0 if d.snr_threshold_db is None else db_to_linear(d.snr_threshold_db),
        false_alarms_per_slot=d.false_alarms_per_slot,
        range_window_m=d.range_window_m or (0.0, math.hypot(diagonal, height)),
        doppler_window_mps=d.doppler_window_mps or (-60.0, 60.0),
    )


def _cross_field_problems(s: Scenario, n_slots: float, single_section: bool = False) -> list[str]:
    """Feasibility checks that involve several sections; one message per problem. With
    `single_section` the one target came from the deprecated `target:`, and is named so."""
    out: list[str] = []
    if abs(n_slots - round(n_slots)) > 1e-9:
        out.append(f"timing: duration_s / slot_s must be a whole number of slots (got {n_slots})")
    if s.M > s.K * s.n_a:
        out.append(
            f"uavs.start_xy_m: {s.M} UAVs cannot be served by {s.K} BSs of capacity {s.n_a} "
            f"(M > K * N_a)"
        )
    if s.d_th <= 0:
        out.append(
            "radio: control link never closes: P_bs beta0 / (sigma0^2 Gamma_th) <= (H - H^B)^2 "
            f"(d_th^2 = {s.P_bs * s.beta0 / (s.noise_w * s.gamma_th) - s.dH**2:.3g} m^2)"
        )
    for m, q in enumerate(s.uav_start_xy):
        if not (0 <= q[0] <= s.area[0] and 0 <= q[1] <= s.area[1]):
            out.append(f"uavs.start_xy_m[{m}]: {q.tolist()} is outside the area {s.area.tolist()}")
        nearest = float(np.min(np.linalg.norm(s.bs_xy - q, axis=1)))
        if s.d_th > 0 and nearest > s.d_th:
            out.append(
                f"uavs.start_xy_m[{m}]: {q.tolist()} is {nearest:.0f} m from the nearest BS, "
                f"beyond the control range d_th = {s.d_th:.0f} m"
            )
    for i in range(s.M):
        for j in range(i + 1, s.M):
            gap = float(np.linalg.norm(s.uav_start_xy[i] - s.uav_start_xy[j]))
            if gap < s.d_safe:
                out.append(
                    f"uavs.start_xy_m[{i}], [{j}]: {gap:.1f} m apart, closer than "
                    f"safe_distance_m = {s.d_safe} m"
                )
    for m in sorted(s.impairment.vehicles):
        if m >= s.M:
            out.append(f"impairment.vehicles.{m}: no vehicle {m} (M = {s.M})")
    for m in s.battery.capacity_wh_by_uav:
        if m >= s.M:
            out.append(f"uavs.battery.capacity_wh_by_uav: no UAV {m} (M = {s.M})")
    many = len(s.targets) > 1 or s.targets[0].first_slot > 0
    for i, t in enumerate(s.targets):
        where = "target.initial_state" if single_section else f"targets[{i}].initial_state"
        p = np.asarray(t.x0[:2])
        if not (0 <= p[0] <= s.area[0] and 0 <= p[1] <= s.area[1]):
            out.append(f"{where}: position {p.tolist()} is outside the area")
        if t.first_slot > s.N:
            out.append(f"targets[{i}].appears_s: after the mission's end ({s.N * s.dt} s)")
        if t.first_slot > 0:
            continue  # the UAVs have moved by the time it appears
        for m, q in enumerate(s.uav_start_xy):
            gap = float(np.linalg.norm(q - p))
            if gap < s.d_safe:
                whose = f"target {t.name}'s" if many else "the target's"
                out.append(
                    f"uavs.start_xy_m[{m}]: {gap:.1f} m from {whose} start, closer than "
                    f"safe_distance_m = {s.d_safe} m"
                )
    reasons = multi_target_reasons(s)
    if s.tracker_kind == "labelled" and reasons:
        out.append(
            "tracker.kind: labelled tracks one known constant-velocity target in the scene "
            "throughout, with the fixed detection model and no false alarms; this scenario has "
            f"{', '.join(reasons)}: use kind auto or multi"
        )
    return out
