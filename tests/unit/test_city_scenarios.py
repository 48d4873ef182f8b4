"""The city-scale scenarios (config/city-48.yaml, config/city-96.yaml; docs/model.md, "City-scale
scenarios"): they load with their fleet, their ten intruders enter over the mission and stay inside
the 6 km x 6 km area, the base stations can serve the whole fleet (K N_a >= M, a control link
everywhere, each UAV's equal share of the band meets R_th from where it starts and anywhere in the
area), the association LP is feasible at the start points, and no two MAVLink links of the live
fleet share a port. Every rate, range and assignment comes from the project's own functions."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from isac_mission.cli.ports import mission_ports
from isac_mission.config import Scenario, load_scenario
from isac_mission.model.channel import control_range, rate, rate_radius
from isac_mission.model.geometry import uav_bs_distances
from isac_mission.model.run_noise import draw_multi_target_noise
from isac_mission.model.targets import target_paths
from isac_mission.planning.association import AssociationLP, associate, association_costs
from isac_mission.planning.communication import communication_optimal
from isac_mission.types import FloatArray

CITIES = [("city-48", 48), ("city-96", 96)]
"""Each city-scale scenario (shipped name) and its fleet size M."""
NAMES = [name for name, _ in CITIES]
AREA_M = 6000.0
RUNS = 10
"""Monte Carlo runs whose noisy target paths are checked (noise seeds seed .. seed + RUNS - 1)."""
EDGE_MARGIN_M = 500.0
"""How far inside the area every noise-free target path stays: room for the process noise."""


@functools.cache
def city(name: str) -> Scenario:
    return load_scenario(name)


def area_points(s: Scenario, step_m: float = 50.0) -> FloatArray:
    """[P, 2] a grid over the whole area, its edges and corners included."""
    xs = np.linspace(0.0, s.area[0], round(s.area[0] / step_m) + 1)
    ys = np.linspace(0.0, s.area[1], round(s.area[1] / step_m) + 1)
    return np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)


def equal_shares(s: Scenario) -> FloatArray:
    """[M] every UAV's equal share of the band, 1 / M."""
    return np.full(s.M, 1.0 / s.M)


def inside(xy: FloatArray, s: Scenario, margin_m: float = 0.0) -> bool:
    return bool(np.all(xy >= margin_m) and np.all(xy <= s.area - margin_m))


@pytest.mark.parametrize(("name", "m"), CITIES, ids=NAMES)
def test_a_city_scenario_loads_with_its_fleet_over_the_larger_area(name: str, m: int) -> None:
    s = city(name)
    assert s.mission_id == name
    assert s.M == m == len(s.uav_start_xy)
    assert s.area.tolist() == [AREA_M, AREA_M]
    assert (s.N, s.dt, s.H) == (60, 1.0, 100.0)
    assert s.multi_target
    assert all(inside(q, s) for q in s.uav_start_xy)


@pytest.mark.parametrize("name", NAMES)
def test_ten_targets_enter_at_different_times_within_the_mission(name: str) -> None:
    s = city(name)
    assert len(s.targets) == 10
    first = np.array([t.first_slot for t in s.targets])
    assert np.all((first >= 0) & (first < s.N))
    assert np.all(np.array([t.last_slot for t in s.targets]) == s.N)  # none leaves early
    known_at_start = [t for t in s.targets if t.prior_known and t.first_slot == 0]
    to_find = [t for t in s.targets if not t.prior_known]
    assert 2 <= len(known_at_start) <= 4 and len(to_find) == 10 - len(known_at_start)
    late = sorted({int(f) for f in first if f > 0})
    assert len(late) >= 6  # each entering at a time of its own...
    assert late[-1] * s.dt <= 40.0 and late[-1] - late[0] >= 30  # ...spread over 0-40 s
    speeds = [math.hypot(t.x0[2], t.x0[3]) for t in s.targets]
    assert min(speeds) >= 10.0 and max(speeds) <= 30.0
    assert sum(t.motion == "coordinated_turn" for t in s.targets) >= 2


@pytest.mark.parametrize("name", NAMES)
def test_every_target_stays_inside_the_area_at_every_slot(name: str) -> None:
    s = city(name)
    T = len(s.targets)
    nominal = target_paths(s.targets, s.dt, s.kappa, s.N, np.zeros((T, s.N, 4)))
    for t, spec in enumerate(s.targets):
        slots = np.flatnonzero(nominal.present[:, t])
        assert slots.tolist() == list(range(spec.first_slot, s.N + 1))
        xy = nominal.states[slots, t, :2]
        assert inside(xy, s, EDGE_MARGIN_M), f"{spec.name}: noise-free path within the margin"
    for r in range(RUNS):
        noise = draw_multi_target_noise(s, s.seed + r)
        paths = target_paths(s.targets, s.dt, s.kappa, s.N, noise.target_normals)
        xy = paths.states[..., :2][paths.present]
        assert not np.isnan(xy).any()
        assert inside(xy, s), f"run {r}: a target leaves the area"


@pytest.mark.parametrize("name", NAMES)
def test_the_base_stations_can_serve_the_whole_fleet(name: str) -> None:
    s = city(name)
    assert s.K == len(s.bs_xy)
    assert s.K * s.n_a >= s.M
    # With room to spare (docs/model.md, "City-scale scenarios"): a UAV that its nearest BS
    # cannot take finds another near it.
    assert s.K * s.n_a >= 1.5 * s.M
    assert inside(s.bs_xy, s)


@pytest.mark.parametrize("name", NAMES)
def test_every_point_of_the_area_has_enough_bs_in_control_range(name: str) -> None:
    s = city(name)
    assert s.d_th == pytest.approx(control_range(s.P_bs, s.beta0, s.noise_w, s.gamma_th, s.dH))
    reach = uav_bs_distances(area_points(s), s.bs_xy) <= s.d_th
    # Wherever the fleet gathers, enough BSs reach it to serve every UAV within N_a each.
    assert reach.sum(axis=1).min() >= math.ceil(s.M / s.n_a)


@pytest.mark.parametrize("name", NAMES)
def test_an_equal_share_meets_r_th_from_every_start_point(name: str) -> None:
    s = city(name)
    nearest = uav_bs_distances(s.uav_start_xy, s.bs_xy).min(axis=1)
    assert np.all(nearest <= s.d_th)
    fair = rate(equal_shares(s), nearest, s.dH, s.rho0, s.B)
    assert np.all(fair >= s.r_th)


@pytest.mark.parametrize("name", NAMES)
def test_an_equal_share_meets_r_th_anywhere_in_the_area_with_margin(name: str) -> None:
    s = city(name)
    farthest = uav_bs_distances(area_points(s), s.bs_xy).min(axis=1).max()
    share = np.array(1.0 / s.M)
    assert farthest <= rate_radius(share, s.r_th, s.dH, s.rho0, s.B)
    # The margin of the band's sizing (docs/model.md, "City-scale scenarios"): 1.5 R_th.
    assert rate(share, farthest, s.dH, s.rho0, s.B) >= 1.5 * s.r_th


@pytest.mark.parametrize("name", NAMES)
def test_the_association_lp_is_feasible_at_the_start_points(name: str) -> None:
    s = city(name)
    lp = AssociationLP(s.M, s.K, s.n_a)
    costs = association_costs(s.uav_start_xy, s.bs_xy, dH=s.dH, rho0=s.rho0, B=s.B)
    relaxed = lp.solve(costs)
    assert relaxed is not None  # HiGHS found the LP feasible and solved it
    assert np.allclose(relaxed.sum(axis=1), 1.0, atol=1e-6)
    assert np.all(relaxed.sum(axis=0) <= s.n_a + 1e-6)
    chosen = associate(s.uav_start_xy, s.bs_xy, capacity=s.n_a, dH=s.dH, rho0=s.rho0, B=s.B, lp=lp)
    assert chosen.shape == (s.M,)
    assert np.all((chosen >= 0) & (chosen < s.K))  # every UAV gets a BS...
    assert np.bincount(chosen, minlength=s.K).max() <= s.n_a  # ...and no BS serves above N_a
    served = np.linalg.norm(s.uav_start_xy - s.bs_xy[chosen], axis=1)
    assert np.all(served <= s.d_th)
    assert np.all(rate(equal_shares(s), served, s.dH, s.rho0, s.B) >= s.r_th)
    # P1 is feasible at the start: the communication-optimal plan's common rate meets R_th.
    plan = communication_optimal(
        s.uav_start_xy, s.bs_xy[chosen], max_step_m=0.0, dH=s.dH, rho0=s.rho0, B=s.B
    )
    assert plan.worst_rate_bps >= s.r_th


@pytest.mark.parametrize("name", NAMES)
def test_no_two_mavlink_links_of_the_fleet_share_a_port(name: str) -> None:
    s = city(name)
    ports = [p for use in mission_ports(s).table(s.M).values() for p in use]
    assert len(ports) == len(set(ports))
