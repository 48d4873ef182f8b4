"""Evasion under the vehicle model (planning/evasion.py, planning/fallback.py; docs/model.md,
"Evasion").

- `evasive_velocity` is the best end velocity within a_max and V_max: against a polar grid;
- the viability test is the braking bound: pairs braked along their line of sight, simulated
  finely, stop closing before D_s exactly when the test says viable;
- the guard's invariant: two UAVs that start viable and coast at each other, planned by the worst
  plan (coasting on) and guarded slot by slot, never come within D_s along their legs, and every
  evasive leg keeps a_max and V_max;
- the trap that found it: a 12-UAV fleet of the horizon bench, `proposed` with the vehicle
  model, whose pair came to 16.6 m of D_s = 30 m before the guard, keeps every pair >= D_s
  along the flown legs;
- a UAV between two threats moves away from both (the soak's arrival), on the direction that is
  the best on a fine grid of the circle.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from isac_mission.experiment.closed_loop import SlotOutcome, draw_run_noise, run_closed_loop
from isac_mission.model.vehicle import VehicleModel, hermite_position
from isac_mission.planning.evasion import (
    Parties,
    away_from_all,
    coasting_threats,
    evasive_legs,
    evasive_velocity,
    target_escape,
    unviable_pairs,
)
from isac_mission.planning.fallback import kept_viable
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.margins import SafetyMargins
from isac_mission.planning.problem import SlotInput
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.pcrb import SensingParams
from isac_mission.types import SlotPlan, SolveReport

A_MAX, V_MAX, DT, SEP = 8.0, 22.5, 1.0, 30.0
FAR = np.array([1e6, 1e6])
"""The target, far away: these tests are about UAV pairs."""


def pair_parties(xy: np.ndarray, v: np.ndarray) -> Parties:
    return Parties.of(xy, v, SEP, FAR, np.zeros(2), SEP, None)


def test_the_evasive_velocity_is_the_best_within_a_max_and_v_max(
    rng: np.random.Generator,
) -> None:
    radius = np.linspace(0, A_MAX * DT, 201)[:, None]
    angle = np.linspace(0, 2 * np.pi, 721)[None]
    disk = np.stack([radius * np.cos(angle), radius * np.sin(angle)], -1).reshape(-1, 2)
    for _ in range(300):
        v0 = rng.uniform(-1, 1, 2) * rng.uniform(0, 1.05) * V_MAX / np.sqrt(2) * 1.4
        u = rng.normal(size=2)
        u /= np.linalg.norm(u)
        v1 = evasive_velocity(v0, u, A_MAX, V_MAX, DT)
        grid = v0 + disk
        grid = grid[np.linalg.norm(grid, axis=1) <= V_MAX]
        if len(grid) == 0:  # faster than V_max + a_max dt: it brakes
            assert np.linalg.norm(v1) < np.linalg.norm(v0)
            continue
        assert np.linalg.norm(v1 - v0) <= A_MAX * DT * (1 + 1e-9)
        assert np.linalg.norm(v1) <= V_MAX
        best = float(np.max((grid - v0) @ u))
        assert float((v1 - v0) @ u) >= best - 1e-2 * A_MAX * DT


def braked_minimum_gap_m(gap_m: float, closing_mps: float) -> float:
    """Two UAVs closing head-on, each braking at a_max: their smallest gap, simulated."""
    t = np.linspace(0, closing_mps / (2 * A_MAX), 20001)
    return float(np.min(gap_m - closing_mps * t + A_MAX * t**2))


@pytest.mark.parametrize("closing_mps", [2.0, 10.0, 25.0, 40.0])
def test_the_viability_test_is_the_braking_bound(closing_mps: float) -> None:
    for gap in np.linspace(SEP + 0.5, SEP + 120, 60):
        xy = np.array([[0.0, 0.0], [gap, 0.0]])
        v = np.array([[closing_mps / 2, 0.0], [-closing_mps / 2, 0.0]])
        unviable = unviable_pairs(pair_parties(xy, v), xy, v, A_MAX)
        assert unviable[0, 1] == unviable[1, 0]
        assert bool(unviable[0, 1]) == (braked_minimum_gap_m(gap, closing_mps) < SEP - 1e-3)
        # Opening pairs are always viable.
        assert not unviable_pairs(pair_parties(xy, -v), xy, -v, A_MAX)[0, 1]


def fly_guarded(xy: np.ndarray, v: np.ndarray, slots: int) -> tuple[float, bool]:
    """Slots of the worst plan (every UAV coasting on), each guarded: the smallest gap along
    the legs (dense samples) and whether every leg kept a_max and V_max."""
    model = VehicleModel(V_MAX, A_MAX, DT)
    smallest, within = np.inf, True
    for _ in range(slots):
        parties = pair_parties(xy, v)
        end_xy, end_v = xy + v * DT, v.copy()
        unviable = unviable_pairs(parties, end_xy, end_v, A_MAX)
        if unviable.any():
            end_xy, end_v, _ = evasive_legs(parties, unviable, end_xy, end_v, A_MAX, V_MAX, DT)
        legs = np.stack(
            [hermite_position(xy, v, end_xy, end_v, DT, f) for f in np.linspace(0, 1, 101)]
        )
        smallest = min(smallest, float(np.min(np.linalg.norm(legs[:, 0] - legs[:, 1], axis=-1))))
        within &= bool(np.all(model.check_leg(xy, v, end_xy, end_v, tol=1e-6).feasible))
        xy, v = end_xy, end_v
    return smallest, within


def test_guarded_pairs_that_start_viable_never_come_within_d_s(rng: np.random.Generator) -> None:
    tried = 0
    while tried < 150:
        xy = np.array([[0.0, 0.0], rng.uniform(-150, 150, 2)])
        v = rng.uniform(-1, 1, (2, 2)) * V_MAX / np.sqrt(2)
        if unviable_pairs(pair_parties(xy, v), xy, v, A_MAX).any():
            continue  # not a viable start: no plan can promise anything
        if np.linalg.norm(xy[1] - xy[0]) < SEP + 1:
            continue
        tried += 1
        smallest, within = fly_guarded(xy, v, 12)
        assert within
        assert smallest >= SEP - 0.05, (xy.tolist(), v.tolist(), smallest)


def test_unguarded_coasting_pairs_do_collide() -> None:
    """The guard test can fail: the same worst plan without it flies head-on pairs together."""
    xy = np.array([[0.0, 0.0], [80.0, 0.0]])
    v = np.array([[10.0, 0.0], [-10.0, 0.0]])
    assert not unviable_pairs(pair_parties(xy, v), xy, v, A_MAX).any()
    assert fly_guarded(xy, v, 6)[0] >= SEP - 0.05
    legs = xy[None] + np.linspace(0, 6, 601)[:, None, None] * v[None]
    assert np.min(np.linalg.norm(legs[:, 0] - legs[:, 1], axis=-1)) < SEP


def test_a_coasting_threat_is_what_the_closest_approach_says() -> None:
    """UAVs 0 and 1 pass 10 m apart at t = 3 s, inside the look-ahead 1 + 20 / 8 s; UAVs 0 and 2
    would too, but at t = 10 s, beyond it; UAV 3 is still and far from every path."""
    xy = np.array([[0.0, 0.0], [60.0, 10.0], [200.0, -10.0], [0.0, 500.0]])
    v = np.array([[10.0, 0.0], [-10.0, 0.0], [-10.0, 0.0], [0.0, 0.0]])
    threat, t = coasting_threats(pair_parties(xy, v), A_MAX, DT)
    assert threat[0, 1] and threat[1, 0]
    assert t[0, 1] == pytest.approx(3.0)
    assert not threat[0, 2] and not threat[2, 0]
    assert t[0, 2] == pytest.approx(1 + 20 / A_MAX)
    assert not threat[3].any() and not threat[:, 3].any()


def load_bench() -> ModuleType:
    path = Path(__file__).resolve().parents[2] / "bench" / "horizon_fleet.py"
    spec = importlib.util.spec_from_file_location("bench_horizon_fleet", path)
    assert spec is not None and spec.loader is not None
    module = sys.modules.setdefault("bench_horizon_fleet", importlib.util.module_from_spec(spec))
    spec.loader.exec_module(module)
    return module


def test_the_twelve_uav_trap_keeps_every_pair_apart() -> None:
    bench = load_bench()
    s = bench.fleet_scenario(12, 60)
    assert s.planner.vehicle_model
    outcomes: list[SlotOutcome] = []
    run_closed_loop(s, "proposed", draw_run_noise(s, 1), SolverKit(s), outcomes.append)
    gaps, _ = bench.flown_gaps_m(s, outcomes)
    assert min(gaps) >= s.d_safe, [
        (o.slot, g) for o, g in zip(outcomes, gaps, strict=True) if g < s.d_safe
    ]
    evasive = [o for o in outcomes if o.plan.report.fallback == "evasive"]
    assert evasive, "the guard never acted: the trap is gone and this test no longer tests it"
    for o in evasive:
        assert "evasive legs for UAVs" in o.plan.report.reason
    assert SafetyMargins.of(s).separation_m >= s.d_safe


A_TARGET, TARGET_SPEED = 2.0, 30.0
"""The target of the guard's tests: faster than V_max, turning toward the UAV at a_T."""
CLEARANCE_14J = SEP + 0.5 * A_TARGET * DT**2 + (A_TARGET * DT) ** 2 / (2 * (A_MAX - A_TARGET))
"""What 14j keeps with the vehicle model (docs/model.md, "Safety"): D_s, the manoeuvre within the
slot, the reaction margin; target_escape keeps D_s plus its own reach."""


def end_state_viable(xy: np.ndarray, v: np.ndarray, p: np.ndarray, vt: np.ndarray) -> bool:
    """target_escape's verdict on one UAV's end state (xy [2], v [2]) against the target's
    predicted end state (p [2], vt [2]), known a slot before, as the guard asks it."""
    viable, _ = target_escape(xy[None], v[None], p, vt, SEP, A_MAX, A_TARGET, V_MAX, DT, known_s=DT)
    return bool(viable[0])


def fly_against_target(
    xy: np.ndarray, v: np.ndarray, p: np.ndarray, vt: np.ndarray, guarded: bool, slots: int = 15
) -> float:
    """One UAV planned by the worst plan that keeps 14j along its leg (coasting on; a leg that
    does not keep it is no plan: it evades, as the best effort does), guarded by
    target_escape (end state, known a slot ago) when `guarded`; the target turns toward the UAV
    at A_TARGET at constant speed. The smallest true distance along the legs (40 samples a
    slot)."""
    smallest = np.inf
    frac = np.linspace(0, 1, 41)[:, None]
    for _ in range(slots):
        parties = Parties.of(xy[None], v[None], SEP, p, vt, CLEARANCE_14J, None)
        end_xy, end_v = xy + v * DT, v.copy()
        coasting_gap = np.linalg.norm(xy + v * DT * frac - (p + vt * DT * frac), axis=1)
        dodge_now = bool(np.min(coasting_gap) < CLEARANCE_14J)
        if guarded:
            dodge_now |= not end_state_viable(end_xy, end_v, p + vt * DT, vt)
        if dodge_now:
            _, direction = target_escape(xy[None], v[None], p, vt, SEP, A_MAX, A_TARGET, V_MAX, DT)
            threat = np.array([[False, True]])
            e_xy, e_v, _ = evasive_legs(
                parties, threat, end_xy[None], end_v[None], A_MAX, V_MAX, DT, direction
            )
            end_xy, end_v = e_xy[0], e_v[0]
        pp, vv, h = p.copy(), vt.copy(), DT / 40
        for k in range(1, 41):
            u = vv / np.linalg.norm(vv)
            n = np.array([-u[1], u[0]]) * np.sign((xy - pp) @ np.array([-u[1], u[0]]) or 1.0)
            vn = vv + A_TARGET * h * n
            vn *= TARGET_SPEED / np.linalg.norm(vn)
            pp, vv = pp + 0.5 * (vv + vn) * h, vn
            uav = hermite_position(xy[None], v[None], end_xy[None], end_v[None], DT, k / 40)[0]
            smallest = min(smallest, float(np.linalg.norm(uav - pp)))
        xy, v, p, vt = end_xy, end_v, pp, vv
    return smallest


def random_viable_encounters(rng: np.random.Generator, count: int) -> list[tuple[np.ndarray, ...]]:
    """UAV at the origin, the target 60-400 m away on any heading at TARGET_SPEED; kept where
    target_escape says the start is viable."""
    out: list[tuple[np.ndarray, ...]] = []
    while len(out) < count:
        xy, v = np.zeros(2), rng.uniform(-1, 1, 2) * V_MAX / np.sqrt(2)
        bearing, heading = rng.uniform(0, 2 * np.pi, 2)
        p = rng.uniform(60, 400) * np.array([np.cos(bearing), np.sin(bearing)])
        vt = TARGET_SPEED * np.array([np.cos(heading), np.sin(heading)])
        viable, _ = target_escape(xy[None], v[None], p, vt, SEP, A_MAX, A_TARGET, V_MAX, DT)
        if viable[0]:
            out.append((xy, v, p, vt))
    return out


def test_guarded_uavs_dodge_a_faster_target_manoeuvring_at_the_bound(
    rng: np.random.Generator,
) -> None:
    """From 150 viable starts, a target faster than V_max that turns toward the UAV at a_T
    never comes within D_s of a guarded UAV; without the guard (14j along the leg only) it
    does."""
    unguarded = []
    for xy, v, p, vt in random_viable_encounters(rng, 150):
        assert fly_against_target(xy, v, p, vt, guarded=True) >= SEP, (v, p, vt)
        unguarded.append(fly_against_target(xy, v, p, vt, guarded=False))
    assert sum(g < SEP for g in unguarded) >= 5, sorted(unguarded)[:10]


def escape_from_rest(target_x_m: float, target_y_m: float = 0.0) -> tuple[bool, np.ndarray]:
    """target_escape of a UAV at rest at the origin from a 30 m/s target at (target_x_m,
    target_y_m) flying +x, clearance D_s + 1 m: (viable, dodge direction [2])."""
    viable, direction = target_escape(
        np.zeros((1, 2)),
        np.zeros((1, 2)),
        np.array([target_x_m, target_y_m]),
        np.array([TARGET_SPEED, 0.0]),
        SEP + 1.0,
        A_MAX,
        A_TARGET,
        V_MAX,
        DT,
    )
    return bool(viable[0]), direction[0]


def test_a_target_far_off_any_course_is_viable_and_one_head_on_and_close_is_not() -> None:
    assert escape_from_rest(-300.0, 200.0)[0]
    assert escape_from_rest(-400.0)[0] and not escape_from_rest(-60.0)[0]
    # Head-on at 150 m (5 s away), the dodge goes across the target's path, not away from it.
    direction = escape_from_rest(-150.0)[1]
    assert abs(direction[1]) >= abs(direction[0])


def test_the_six_uav_trap_keeps_the_target_away() -> None:
    """The fleet bench's M = 6, seed 2, `horizon`, the constant-velocity target (a_T = 0): before
    the target was in the guard, capped slots flew per-slot plans that left UAV 4 in the path of
    the 30 m/s target, the next slots were infeasible and their best effort came within 10.9 m
    of it; the guard then dodged it. Since the horizon's warm start converges there (docs/model.md,
    "Start points") no slot leaves a UAV in its path: no flown leg comes within D_s, and the
    dodge itself is tested on the slot below (`test_a_plan_ending_in_the_targets_path_...`)."""
    bench = load_bench()
    s = bench.fleet_scenario(6, 30).with_changes(a_target=0.0)
    outcomes: list[SlotOutcome] = []
    run_closed_loop(s, "horizon", draw_run_noise(s, 2), SolverKit(s), outcomes.append)
    _, target_gaps = bench.flown_gaps_m(s, outcomes)
    assert min(target_gaps) >= s.d_safe, [
        (o.slot, round(g, 1)) for o, g in zip(outcomes, target_gaps, strict=True) if g < s.d_safe
    ]


def test_a_plan_ending_in_the_targets_path_flies_an_evasive_leg_that_dodges_it() -> None:
    """A plan whose end state leaves UAV 0 at rest 120 m ahead of a 30 m/s target flying at it
    (4 s away, faster than V_max): the guard (`kept_viable`) flies UAV 0 on an evasive leg that
    says it dodges the target and ends farther from the target's path; UAV 1, far off, keeps
    its planned end."""
    s = load_bench().fleet_scenario(2, 5)
    s = s.with_changes(planner=s.planner.model_copy(update={"vehicle_model": True}))
    start_xy = np.array([[1500.0, 1500.0], [2500.0, 500.0]])
    target_pred = np.array([1500.0 - 150.0 + 30.0, 1500.0, 30.0, 0.0])
    inp = SlotInput(
        prev_xy_m=start_xy,
        prev_bandwidth_share=np.full(2, 0.5),
        prev_bs_of_uav=None,
        targets=(TargetBelief(target_pred, np.eye(4), s.motion, np.eye(4)),),
        prev_velocity_mps=np.zeros((2, 2)),
    )
    plan = SlotPlan(
        uav_xy_m=start_xy.copy(),
        bs_of_uav=np.zeros(2, dtype=np.int64),
        bandwidth_share=np.full(2, 0.5),
        pcrb_trace=1.0,
        report=SolveReport(status="ok"),
        uav_velocity_mps=np.zeros((2, 2)),
    )
    guarded = kept_viable(plan, inp, s, SensingParams.from_scenario(s))
    assert guarded.report.fallback == "evasive"
    assert "dodge the target" in guarded.report.reason, guarded.report.reason
    assert abs(guarded.uav_xy_m[0, 1] - start_xy[0, 1]) > 1.0  # off the target's line
    np.testing.assert_array_equal(guarded.uav_xy_m[1], start_xy[1])
    assert guarded.uav_velocity_mps is not None
    assert np.linalg.norm(guarded.uav_velocity_mps[0]) <= s.a_max * s.dt + 1e-9


@pytest.mark.parametrize("target_speed_mps", [15.0, 22.0])
def test_a_uav_at_the_14j_clearance_beside_the_target_is_viable_thanks_to_the_reaction_margin(
    target_speed_mps: float,
) -> None:
    """A UAV that ends its slot beside the target at 14j's clearance, moving with it, can keep
    away from every target motion within a_T: the reaction margin is what makes it so (0.2 m
    less and the target, its velocity a_T dt off toward the UAV, gets within D_s first)."""
    vt = np.array([target_speed_mps, 0.0])

    def viable(gap_m: float) -> bool:
        return end_state_viable(np.array([0.0, gap_m]), vt, np.zeros(2), vt)

    assert viable(CLEARANCE_14J)
    assert not viable(CLEARANCE_14J - 0.2)


def test_a_uav_between_a_uav_and_the_target_dodges_sideways_not_into_the_target() -> None:
    """The M = 3 soak's arrival (slot 72 of `bench/soak.py --offline --slots 1200`): UAV 0 has
    UAV 1 31 m behind it (closest now: the heavier weight of the push) and the target 45 m ahead,
    closing at 5 m/s. The push away from UAV 1 alone would fly it at a_max into the target; its
    evasive leg instead moves it away from both, at a_max."""
    xy = np.array([[0.0, 0.0], [0.0, -31.0]])
    v = np.zeros((2, 2))
    target_xy, target_v = np.array([5.0, 45.0]), np.array([0.0, -5.0])
    parties = Parties.of(xy, v, SEP, target_xy, target_v, SEP + 4.0, None)
    threat = np.array([[False, True, True], [True, False, False]])
    end_xy, end_v, evading = evasive_legs(parties, threat, xy, v, A_MAX, V_MAX, DT)
    assert evading.all()
    dv = end_v[0] - v[0]
    assert np.linalg.norm(dv) == pytest.approx(A_MAX * DT)
    to_uav_1 = xy[1] - xy[0]
    to_target = target_xy - xy[0]
    assert dv @ to_uav_1 < 0 and dv @ to_target < 0, dv
    # Farther from both than coasting leaves it (UAV 1 evades too; the target coasts on).
    coasting_uav_1 = xy[1] + v[1] * DT
    assert np.linalg.norm(end_xy[0] - end_xy[1]) > np.linalg.norm(xy[0] - coasting_uav_1)
    target_end = target_xy + target_v * DT
    assert np.linalg.norm(end_xy[0] - target_end) > np.linalg.norm(xy[0] - target_end)


def test_the_direction_away_from_all_threats_is_the_best_on_a_grid(
    rng: np.random.Generator,
) -> None:
    """away_from_all maximises min_p u . aways[p] over unit u: against 7200 directions on the
    circle, for 300 random sets of 2-5 threats (and exactly opposite pairs)."""
    angle = np.linspace(0, 2 * np.pi, 7200, endpoint=False)
    grid = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    sets = [rng.normal(size=(int(rng.integers(2, 6)), 2)) for _ in range(300)]
    sets += [np.array([[0.0, 1.0], [0.0, -1.0]]), np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]])]
    for aways in sets:
        aways = aways / np.linalg.norm(aways, axis=1)[:, None]
        push = rng.normal(size=2)
        u = away_from_all(aways, push / np.linalg.norm(push))
        assert np.linalg.norm(u) == pytest.approx(1.0)
        best_on_grid = float(np.max(np.min(grid @ aways.T, axis=1)))
        assert float(np.min(aways @ u)) >= best_on_grid - 1e-9, aways
