"""The safety rule (planning/margins.py, planning/legs.py; docs/model.md, "Safety").

- the clearance: D_s with "none", D_s + k sigma + e with the rule, sigma over the slot's leg
  samples against a forward prediction computed here;
- the legs: a leg the sampled chord check accepts never comes closer than allowed on a dense
  brute-force sampling (straight and Hermite legs), and the SCA's per-sample distances cover the
  chords between samples;
- the confidence level by Monte Carlo, without the formula: the true target is beyond the planned
  clearance minus D_s + e with at least probability Phi(k), along the worst direction and on the
  tracker's own closed-loop errors;
- the exact check rejects a plan that crosses the target's disk between slot instants;
- a scripted target that turns into a UAV: every UAV, sampled along its legs, stays >= D_s from
  the true target with the rule on; with "none" the paper's plans come closer than D_s;
- every plan of a simulate trace passes the independent checker with the rule's clearances.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.experiment.closed_loop import (
    RunResult,
    SlotOutcome,
    draw_run_noise,
    run_closed_loop,
    true_trajectory,
)
from isac_mission.experiment.montecarlo import run_monte_carlo, trace_path
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.model.vehicle import hermite_position
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.legs import (
    chord_shortfall,
    leg_accel_bound_mps2,
    leg_fractions,
    sample_clearances_m,
    uav_leg_points,
)
from isac_mission.planning.margins import SafetyMargins, slot_sigma_max_m, target_clearance_m
from isac_mission.planning.slot import Method
from isac_mission.records import SlotRecord, read_trace
from tests.support.independent.constraints import check_constraints

PHI_TAIL = {1.0: 0.15865525393145707, 2.0: 0.022750131948179195}
"""1 - Phi(k), the one-sided normal tail."""


def target_leg_points(
    target_xy: np.ndarray, target_velocity_mps: np.ndarray, fractions: np.ndarray, dt_s: float
) -> np.ndarray:
    """The constant-velocity target [S, 2] at the fractions [S] of the slot ending at
    target_xy [2] (this test's own, independent of the planner's motion model)."""
    tau = np.asarray(fractions, dtype=float)[:, None]
    return np.asarray(target_xy - (1.0 - tau) * dt_s * np.asarray(target_velocity_mps))


def _with(s: Scenario, **planner: object) -> Scenario:
    return s.with_changes(planner=s.planner.model_copy(update=planner))


def test_clearance_is_d_safe_with_none_and_d_safe_plus_k_sigma_plus_e_plus_manoeuvre_with_the_rule(
    paper: Scenario,
) -> None:
    P = np.diag([4.0, 9.0, 0.01, 0.01])  # position sigma_max = 3 m
    assert target_clearance_m(_with(paper, safety_margin="none"), P) == paper.d_safe
    s = _with(paper, safety_confidence_sigma=5.0, tracking_margin_m=1.5).with_changes(
        a_target=3.0, dt=2.0
    )
    assert target_clearance_m(_with(s, safety_margin="none"), P) == paper.d_safe
    sigma = slot_sigma_max_m(s, P)
    assert sigma >= 3.0
    manoeuvre = 0.5 * 3.0 * 2.0**2  # a_T dt^2 / 2: 6 m off the prediction by the slot's end
    assert target_clearance_m(s, P) == pytest.approx(paper.d_safe + 5.0 * sigma + 1.5 + manoeuvre)
    assert target_clearance_m(s, None) == paper.d_safe + 1.5 + manoeuvre
    assert paper.a_target == 2.0  # the shipped bound (docs/model.md, "Safety")
    m = SafetyMargins.of(s)
    assert (m.tracking_m, m.separation_m, m.link_m) == (1.5, paper.d_safe + 3.0, 1.5)
    off = SafetyMargins.of(_with(paper, safety_margin="none"))
    assert (off.tracking_m, off.separation_m, off.link_m) == (0.0, paper.d_safe, 0.0)


def test_sigma_over_the_slot_is_the_forward_prediction_at_the_leg_samples(paper: Scenario) -> None:
    s = paper
    rng = np.random.default_rng(4)
    S = s.planner.horizon.leg_samples
    cases = [np.diag([100.0, 100.0, 100.0, 100.0])]
    # Position and velocity errors strongly anti-correlated: the covariance shrinks toward the
    # slot's end, so the largest sigma of the slot is at an interior sample.
    anti = np.array([[100.0, -99.0], [-99.0, 100.0]])
    cases.append(np.kron(anti, np.eye(2)))
    for _ in range(5):
        A = rng.normal(size=(4, 4))
        cases.append(A @ A.T + 0.1 * np.eye(4))
    for P_prev in cases:
        P_pred = transition_matrix(s.dt) @ P_prev @ transition_matrix(s.dt).T + process_noise(
            s.dt, s.kappa
        )
        expected = 0.0
        for i in range(1, S + 1):  # forward from the slot's start, at t = i dt / S
            t = i * s.dt / S
            F = np.eye(4)
            F[0, 2] = F[1, 3] = t
            q = s.kappa * np.array([[t**3 / 3, t**2 / 2], [t**2 / 2, t]])
            Pt = F @ P_prev @ F.T + np.kron(q, np.eye(2))
            expected = max(expected, float(np.max(np.linalg.eigvalsh(Pt[:2, :2]))))
        assert slot_sigma_max_m(s, P_pred) == pytest.approx(math.sqrt(expected), rel=1e-6)
    P_pred = transition_matrix(s.dt) @ cases[1] @ transition_matrix(s.dt).T + process_noise(
        s.dt, s.kappa
    )
    end = math.sqrt(float(np.max(np.linalg.eigvalsh(P_pred[:2, :2]))))
    assert slot_sigma_max_m(s, P_pred) > 2 * end


def _dense_min(rel: np.ndarray) -> float:
    return float(np.min(np.linalg.norm(rel, axis=-1)))


@pytest.mark.parametrize("hermite", [False, True])
def test_a_leg_the_sampled_check_accepts_keeps_its_distance_on_a_dense_sampling(
    hermite: bool,
) -> None:
    rng = np.random.default_rng(7 + hermite)
    dt, S, c = 1.0, 4, 30.0
    fine = np.linspace(0.0, 1.0, 2001)
    accepted = rejected = 0
    for _ in range(400):
        prev = rng.uniform(-60, 60, (1, 2))
        end = prev + rng.uniform(-25, 25, (1, 2))
        v0 = rng.uniform(-25, 25, (1, 2)) if hermite else None
        v1 = rng.uniform(-25, 25, (1, 2)) if hermite else None
        p_end, v_t = rng.uniform(-20, 20, 2), rng.uniform(-30, 30, 2)
        pts = uav_leg_points(prev, end, leg_fractions(S), dt, v0, v1)[:, 0]  # [S, 2]
        rel = pts - target_leg_points(p_end, v_t, leg_fractions(S), dt)
        rel0 = prev[0] - (p_end - dt * v_t)
        sag = leg_accel_bound_mps2(prev, end, dt, v0, v1)[0] * (dt / S) ** 2 / 8
        ok = chord_shortfall(rel0, rel, c, sag) <= 0
        if hermite:
            assert v0 is not None and v1 is not None
            q = np.array([hermite_position(prev[0], v0[0], end[0], v1[0], dt, f) for f in fine])
        else:
            q = prev[0] + fine[:, None] * (end[0] - prev[0])
        truth = _dense_min(q - (p_end - (1 - fine[:, None]) * dt * v_t))
        need = min(c, float(np.linalg.norm(rel0)))
        if ok:
            accepted += 1
            assert truth >= need - 1e-9
        else:
            rejected += 1
    assert accepted > 50 and rejected > 50


def test_the_sca_sample_distances_cover_the_chords_between_samples() -> None:
    rng = np.random.default_rng(11)
    S, c = 4, 35.0
    n = 0
    for _ in range(3000):
        start = rng.uniform(-80, 80, 2)
        step = rng.uniform(-55, 55, 2) / S  # a straight relative motion, chord <= |step|
        rel = start + np.arange(1, S + 1)[:, None] * step
        chord = float(np.linalg.norm(step))
        need = sample_clearances_m(c, np.array([np.hypot(*start)]), chord, S)[:, 0]
        if np.all(np.linalg.norm(rel, axis=1) >= need) and np.linalg.norm(start) >= need[0]:
            n += 1
            assert chord_shortfall(start, rel, c) <= 1e-9
    assert n > 200


def test_the_true_target_is_beyond_the_planned_clearance_with_probability_phi_k(
    paper: Scenario,
) -> None:
    # Without the formula: a UAV planned exactly at the clearance in the worst direction (the
    # largest eigenvector of the position covariance); the true target drawn from the covariance.
    rng = np.random.default_rng(3)
    n = 200_000
    for k in (1.0, 2.0):
        # The Gaussian part alone: no manoeuvre margin.
        s = _with(paper, safety_confidence_sigma=k, tracking_margin_m=1.0).with_changes(
            a_target=0.0
        )
        P = np.array([[4.0, 1.5], [1.5, 1.0]])
        _, V = np.linalg.eigh(P)
        c = target_clearance_m(s, P)
        uav = c * V[:, -1]  # the predicted target at the origin
        truth = rng.multivariate_normal(np.zeros(2), P, size=n)
        closer = np.mean(np.linalg.norm(uav - truth, axis=1) < s.d_safe + 1.0)
        sd = math.sqrt(PHI_TAIL[k] * (1 - PHI_TAIL[k]) / n)
        assert closer <= PHI_TAIL[k] + 5 * sd  # the stated level holds ...
        assert closer >= PHI_TAIL[k] - 5 * sd  # ... and is tight in the worst direction


def test_the_trackers_own_errors_meet_the_stated_level_along_the_planned_directions(
    paper: Scenario,
) -> None:
    # The closed loop's true prediction errors, projected on the direction from the predicted
    # target to each planned UAV, exceed k sigma_max no more often than 1 - Phi(k) (+ 3 sd).
    s = paper.with_changes(N=30)
    kit = SolverKit(s)
    z: list[float] = []
    for seed in range(4):
        outcomes: list[SlotOutcome] = []
        run_closed_loop(s, "proposed", draw_run_noise(s, 100 + seed), kit, outcomes.append)
        for o in outcomes:
            assert o.slot_input.lead.cov_pred is not None
            err = o.target_true[:2] - o.target_pred[:2]
            sigma = slot_sigma_max_m(s, o.slot_input.lead.cov_pred)
            away = o.plan.uav_xy_m - o.target_pred[:2]
            u = away / np.linalg.norm(away, axis=1, keepdims=True)
            z += list((u @ err) / sigma)
    z_arr = np.asarray(z)
    for k, tail in PHI_TAIL.items():
        sd = math.sqrt(tail * (1 - tail) / len(z_arr))
        assert np.mean(z_arr > k) <= tail + 3 * sd, (k, np.mean(z_arr > k))


def test_a_plan_that_crosses_the_targets_disk_between_instants_is_rejected(
    paper: Scenario,
) -> None:
    # The target flies (-15, 0) -> (15, 0) (about (1000, 1000)) in the slot; a UAV holding at
    # (0, 30.5) is 34 m from it at both instants but 30.5 m halfway, inside D_s + e = 31 m.
    s = _with(paper, tracking_margin_m=1.0).with_changes(a_target=0.0)
    o = np.array([1000.0, 1000.0])
    prev = o + np.array([[0.0, 30.5], [500.0, 500.0], [-500.0, 500.0]])
    target, v = o + np.array([15.0, 0.0]), np.array([30.0, 0.0])
    c = target_clearance_m(s, None)
    assert c == s.d_safe + 1.0
    cons = SlotConstraints(prev, prev, prev, target, s, target_clearance_m=c, target_velocity_mps=v)
    bad = cons.position_violations(prev[None])
    assert not bad["14j target distance"][0]
    assert bad["14j along the legs"][0]
    off = _with(paper, safety_margin="none")
    cons_off = SlotConstraints(prev, prev, prev, target, off, target_velocity_mps=v)
    assert not any(x[0] for x in cons_off.position_violations(prev[None]).values())
    # Climbing away to (0, 50) keeps the clearance all along; the one-UAV check agrees.
    eta = np.full(3, 1 / 3)
    away = prev.copy()
    away[0] = o + np.array([0.0, 50.0])
    assert bool(cons.feasible(away[None], eta[None])[0]), cons.describe_violations(away, eta)
    assert list(cons.feasible_moving_one(away, eta, 0, np.stack([prev[0], away[0]]))) == [
        False,
        True,
    ]


def _turning_truth(s: Scenario, seed: int, aim_xy: np.ndarray, n_turn: int) -> np.ndarray:
    """[N + 1, 4]: the run's constant-velocity target until slot n_turn, then at 30 m/s turning
    at 0.2 rad/s (6 m/s^2) toward aim_xy; straight between slot instants."""
    xs = true_trajectory(s, draw_run_noise(s, seed)).copy()
    x = xs[n_turn].copy()
    for n in range(n_turn + 1, s.N + 1):
        v, want = x[2:], aim_xy - x[:2]
        heading = math.atan2(v[1], v[0])
        turn = (math.atan2(want[1], want[0]) - heading + math.pi) % (2 * math.pi) - math.pi
        heading += float(np.clip(turn, -0.2 * s.dt, 0.2 * s.dt))
        v_new = 30.0 * np.array([math.cos(heading), math.sin(heading)])
        x = np.concatenate([x[:2] + 0.5 * (v + v_new) * s.dt, v_new])
        xs[n] = x
    return xs


def _nearest_along_legs(s: Scenario, res: RunResult, truth: np.ndarray) -> float:
    """The smallest UAV-true target distance over 200 points of every leg (both straight)."""
    q = np.concatenate([s.uav_start_xy[None], res.uav_xy])  # [N + 1, M, 2]
    t = np.linspace(0.0, 1.0, 201)[:, None, None]
    uav = q[:-1, None] + t[None] * (q[1:, None] - q[:-1, None])  # [N, T, M, 2]
    tgt = truth[:-1, None, None, :2] + t[None] * (
        truth[1:, None, None, :2] - truth[:-1, None, None, :2]
    )
    return float(np.min(np.linalg.norm(uav - tgt, axis=-1)))


@pytest.mark.parametrize("method", ["proposed", "horizon"])
@pytest.mark.parametrize("aim_uav", [0, 1])
def test_a_target_that_turns_into_a_uav_stays_d_safe_away_with_the_rule(
    paper: Scenario, aim_uav: int, method: Method
) -> None:
    s = paper.with_changes(N=40)
    seed, n_turn = 3, 12
    none = _with(s, safety_margin="none")
    noise = draw_run_noise(s, seed)
    straight = run_closed_loop(none, "proposed", noise, SolverKit(none))
    # Aim where the UAV is eight slots after the turn begins (on the paper's plan).
    truth = _turning_truth(s, seed, straight.uav_xy[n_turn + 8, aim_uav], n_turn)
    ruled = run_closed_loop(s, method, noise, SolverKit(s), truth=truth)
    paper_plans = run_closed_loop(none, method, noise, SolverKit(none), truth=truth)
    assert np.allclose(ruled.true, truth[1:])
    nearest_ruled = _nearest_along_legs(s, ruled, truth)
    nearest_paper = _nearest_along_legs(s, paper_plans, truth)
    assert nearest_ruled >= s.d_safe, nearest_ruled
    assert nearest_paper < s.d_safe, nearest_paper  # the paper's plans do come closer
    if method == "proposed":
        assert all(st == "ok" for st in ruled.status)


def test_every_plan_of_a_simulate_trace_passes_the_independent_check_with_the_clearances(
    tmp_path: Path,
) -> None:
    s = load_scenario("paper").with_changes(N=30)
    assert s.planner.safety_margin == "covariance"
    methods: list[Method] = ["proposed", "proposed-sca", "sd", "aba", "crb", "horizon"]
    run_monte_carlo(s, methods, runs=1, seed=5, trace_dir=tmp_path)
    for method in methods:
        path = trace_path(tmp_path, method, 0)
        assert check_constraints(path, safety=True) == [], method
    # The check can fail: the proposed plan's UAV 0 moved onto the paper's D_s at one slot.
    trace = read_trace(trace_path(tmp_path, "proposed", 0))
    rec = trace.slots[10]
    away = rec.uav_xy_m[0] - rec.target_pred[:2]
    moved = rec.target_pred[:2] + s.d_safe * 1.01 * away / np.linalg.norm(away)
    xy = rec.uav_xy_m.copy()
    xy[0] = moved
    broken = type(trace)(
        config=trace.config,
        slots=[*trace.slots[:10], _replace_xy(rec, xy), *trace.slots[11:]],
    )
    found = {v.constraint for v in check_constraints(broken, safety=True) if v.slot == rec.slot}
    assert "14j" in found


def _replace_xy(rec: SlotRecord, xy: np.ndarray) -> SlotRecord:
    return replace(rec, uav_xy_m=xy)


@pytest.mark.parametrize("vehicle_model", [False, True])
def test_the_one_uav_check_agrees_with_the_full_check_along_the_legs(
    paper: Scenario, vehicle_model: bool
) -> None:
    # UAVs 40-60 m apart and near the target, so that the leg constraints decide; with the
    # vehicle model the legs are Hermite legs from the current velocities to the mean velocity.
    s = _with(paper, vehicle_model=vehicle_model)
    rng = np.random.default_rng(21)
    o = np.array([1500.0, 1500.0])
    prev = o + np.array([[0.0, 0.0], [45.0, 5.0], [10.0, 50.0]])
    velocity = rng.uniform(-20, 20, (3, 2))
    target, v_t = o + np.array([-20.0, -38.0]), np.array([25.0, 10.0])
    cons = SlotConstraints(
        prev,
        prev,
        prev,
        target,
        s,
        target_clearance_m=33.0,
        target_velocity_mps=v_t,
        start_velocity_mps=velocity,
    )
    eta = np.full(3, 1 / 3)
    current = prev + np.array([[-5.0, 20.0], [20.0, 0.0], [0.0, 20.0]])
    assert bool(cons.feasible(current[None], eta[None])[0]), cons.describe_violations(current, eta)
    agree = {True: 0, False: 0}
    for m in range(3):
        cands = current[m] + rng.uniform(-25, 25, (300, 2))
        plans = np.repeat(current[None], len(cands), axis=0)
        plans[:, m] = cands
        full = cons.feasible(plans, np.broadcast_to(eta, (len(cands), 3)))
        one = cons.feasible_moving_one(current, eta, m, cands)
        assert list(one) == list(full)
        for ok in full:
            agree[bool(ok)] += 1
    assert agree[True] > 50 and agree[False] > 50
