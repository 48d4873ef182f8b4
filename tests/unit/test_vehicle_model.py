"""model/vehicle.py: the Hermite leg formulas and VehicleModel, checked independently.

Derivatives by finite differences of hermite_position; the end accelerations, the peak speed and
the mean-velocity leg's reach by brute-force sampling along legs; CasADi symbols give the same
numbers as numpy arrays.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from isac_mission.model.vehicle import (
    VehicleModel,
    end_accelerations,
    hermite_position,
    hermite_velocity,
    peak_speed,
    velocity_control_points,
)

T = 1.0
MODEL = VehicleModel(v_max_mps=25.0, a_max_mps2=10.0, dt_s=T)
S_FINE = np.linspace(0.0, 1.0, 2001)


def random_legs(rng: np.random.Generator, n: int, scale: float = 20.0) -> tuple[np.ndarray, ...]:
    """n random legs (p0, v0, p1, v1), each [n, 2]."""
    p0 = rng.uniform(-500, 500, (n, 2))
    v0 = rng.normal(0, scale, (n, 2))
    p1 = p0 + v0 * T + rng.normal(0, scale / 4, (n, 2))
    v1 = rng.normal(0, scale, (n, 2))
    return p0, v0, p1, v1


def sampled(p0, v0, p1, v1, s=S_FINE):  # type: ignore[no-untyped-def]
    """[S, n, 2] positions by the formula at the fractions s."""
    return np.array([hermite_position(p0, v0, p1, v1, T, float(x)) for x in s])


def test_the_leg_meets_its_end_conditions() -> None:
    p0, v0, p1, v1 = random_legs(np.random.default_rng(1), 50)
    assert hermite_position(p0, v0, p1, v1, T, 0.0) == pytest.approx(p0)
    assert hermite_position(p0, v0, p1, v1, T, 1.0) == pytest.approx(p1)
    assert hermite_velocity(p0, v0, p1, v1, T, 0.0) == pytest.approx(v0)
    assert hermite_velocity(p0, v0, p1, v1, T, 1.0) == pytest.approx(v1)


@pytest.mark.parametrize("T_s", [0.5, 1.0, 2.0])
def test_velocity_and_end_accelerations_match_finite_differences(T_s: float) -> None:
    p0, v0, p1, v1 = random_legs(np.random.default_rng(2), 50)
    h = 1e-4
    for s in (0.1, 0.37, 0.5, 0.9):
        fd = (
            hermite_position(p0, v0, p1, v1, T_s, s + h)
            - hermite_position(p0, v0, p1, v1, T_s, s - h)
        ) / (2 * h * T_s)
        assert hermite_velocity(p0, v0, p1, v1, T_s, s) == pytest.approx(fd, rel=1e-6, abs=1e-5)

    # Second differences (one-sided at the ends, exact for a cubic up to rounding).
    def pos(s: float) -> np.ndarray:
        return np.asarray(hermite_position(p0, v0, p1, v1, T_s, s))

    hh = 1e-3
    a0_fd = (2 * pos(0) - 5 * pos(hh) + 4 * pos(2 * hh) - pos(3 * hh)) / (hh * T_s) ** 2
    a1_fd = (2 * pos(1) - 5 * pos(1 - hh) + 4 * pos(1 - 2 * hh) - pos(1 - 3 * hh)) / (hh * T_s) ** 2
    a0, a1 = end_accelerations(p0, v0, p1, v1, T_s)
    assert a0 == pytest.approx(a0_fd, rel=1e-4, abs=1e-3)
    assert a1 == pytest.approx(a1_fd, rel=1e-4, abs=1e-3)


def test_the_acceleration_norm_peaks_at_an_end_of_the_leg() -> None:
    p0, v0, p1, v1 = random_legs(np.random.default_rng(3), 200)
    xy = sampled(p0, v0, p1, v1)
    ds = (S_FINE[1] - S_FINE[0]) * T
    acc = np.linalg.norm(np.diff(xy, 2, axis=0) / ds**2, axis=-1)  # [S - 2, n]
    a0, a1 = end_accelerations(p0, v0, p1, v1, T)
    ends = np.maximum(np.linalg.norm(a0, axis=-1), np.linalg.norm(a1, axis=-1))
    assert np.all(acc.max(axis=0) <= ends * (1 + 1e-6) + 1e-6)
    assert acc.max(axis=0) == pytest.approx(ends, rel=1e-2)


def test_peak_speed_is_the_sampled_maximum_and_the_hull_bounds_it() -> None:
    p0, v0, p1, v1 = random_legs(np.random.default_rng(4), 300)
    # Brute force: the speed on a fine grid (the velocity formula is checked against finite
    # differences above), never above the exact peak and within the grid's resolution of it.
    v = np.array([hermite_velocity(p0, v0, p1, v1, T, float(x)) for x in S_FINE])
    speed_grid = np.linalg.norm(v, axis=-1).max(axis=0)
    exact = peak_speed(p0, v0, p1, v1, T)
    assert exact.shape == (300,)
    assert np.all(exact >= speed_grid * (1 - 1e-12))
    assert exact == pytest.approx(speed_grid, rel=1e-5)
    hull = np.max(
        [np.linalg.norm(b, axis=-1) for b in velocity_control_points(p0, v0, p1, v1, T)], 0
    )
    assert np.all(hull >= exact - 1e-9)
    assert np.any(hull > exact * 1.05), "the hull is conservative on some legs"


def test_a_mean_velocity_leg_has_the_stated_end_accelerations() -> None:
    rng = np.random.default_rng(5)
    p0, v0, p1, _ = random_legs(rng, 200)
    v1 = (p1 - p0) / T
    a0, a1 = end_accelerations(p0, v0, p1, v1, T)
    off = np.linalg.norm(p1 - (p0 + v0 * T), axis=-1)
    assert np.linalg.norm(a0, axis=-1) == pytest.approx(4 * off / T**2)
    assert np.linalg.norm(a1, axis=-1) == pytest.approx(2 * off / T**2)
    # and the peak speed of the derivation: max(|v0|, |v0 + 4 d / (3 T)|)
    d = p1 - (p0 + v0 * T)
    stated = np.maximum(np.linalg.norm(v0, axis=-1), np.linalg.norm(v0 + 4 * d / (3 * T), axis=-1))
    assert peak_speed(p0, v0, p1, v1, T) == pytest.approx(stated, rel=1e-9)


def test_the_reach_of_the_mean_velocity_leg_is_the_disk_of_radius_a_max_dt2_over_4() -> None:
    """Brute force: end points on rays from the coasting point, the largest feasible offset
    (acceleration sampled along the leg) is a_max dt^2 / 4 in every direction."""
    model = VehicleModel(v_max_mps=1e6, a_max_mps2=8.0, dt_s=0.8)  # speed never binds here
    p0, v0 = np.array([100.0, -50.0]), np.array([12.0, 5.0])
    coast = model.coasting_point(p0, v0)
    s = np.linspace(0.0, 1.0, 2001)
    for angle in np.linspace(0, 2 * np.pi, 13)[:-1]:
        u = np.array([np.cos(angle), np.sin(angle)])
        radii = np.linspace(0.0, 3 * model.reach_radius_m, 1001)
        p1 = coast + radii[:, None] * u
        xy = np.array(
            [hermite_position(p0, v0, p1, (p1 - p0) / model.dt_s, model.dt_s, x) for x in s]
        )
        acc = np.linalg.norm(np.diff(xy, 2, axis=0), axis=-1) / (model.dt_s * (s[1] - s[0])) ** 2
        ok = acc.max(axis=0) <= model.a_max_mps2
        reach = radii[ok].max()
        assert reach == pytest.approx(model.reach_radius_m, rel=5e-3)  # grids: 0.3 %, 0.08 %
        assert np.array_equal(
            model.check_leg(p0, v0, p1).feasible, radii <= model.reach_radius_m * (1 + 1e-9)
        )


def test_check_leg_flags_speed_and_acceleration_separately() -> None:
    p0, v0 = np.zeros(2), np.array([24.0, 0.0])
    inside = MODEL.check_leg(p0, v0, MODEL.coasting_point(p0, v0) + np.array([0.0, 2.0]))
    assert bool(inside.feasible) and float(inside.accel_mps2) == pytest.approx(8.0)
    # Along the velocity, 2 m ahead: within a_max but 24 + 4 * 2 / 3 = 26.7 m/s mid-leg > V_max.
    fast = MODEL.check_leg(p0, v0, MODEL.coasting_point(p0, v0) + np.array([2.0, 0.0]))
    assert float(fast.peak_speed_mps) == pytest.approx(24.0 + 8.0 / 3.0)
    assert not bool(fast.feasible)
    far = MODEL.check_leg(p0, np.zeros(2), np.array([3.0, 0.0]))  # 12 m/s^2 at the start
    assert float(far.accel_mps2) == pytest.approx(12.0) and not bool(far.feasible)
    assert not bool(
        MODEL.check_leg(p0, np.zeros(2), np.array([1.0, 0.0]), np.array([0, 30.0])).feasible
    )


def test_sample_returns_fractions_first_and_the_mean_velocity_end() -> None:
    p0 = np.array([[0.0, 0.0], [10.0, 0.0]])
    v0 = np.array([[5.0, 0.0], [0.0, 0.0]])
    p1 = np.array([[6.0, 1.0], [10.0, 2.0]])
    xy, v = MODEL.sample(p0, v0, p1, None, [0.0, 0.5, 1.0])
    assert xy.shape == v.shape == (3, 2, 2)
    assert xy[0] == pytest.approx(p0) and xy[-1] == pytest.approx(p1)
    assert v[-1] == pytest.approx(MODEL.end_velocity(p0, p1))
    # p(1/2) = p0 + v0 T / 2 + d (1/4)(3/2) by the derivation's closed form
    d = p1 - (p0 + v0 * T)
    assert xy[1] == pytest.approx(p0 + v0 * T / 2 + d * 0.375)


def test_casadi_symbols_give_the_numpy_numbers() -> None:
    p0, v0, p1, v1 = (x[0] for x in random_legs(np.random.default_rng(6), 1))
    syms = [ca.SX.sym(n, 2) for n in ("p0", "v0", "p1", "v1")]
    outputs = [
        hermite_position(*syms, T, 0.3),
        hermite_velocity(*syms, T, 0.3),
        *end_accelerations(*syms, T),
        *velocity_control_points(*syms, T),
    ]
    f = ca.Function("leg", syms, outputs)
    got = [np.asarray(x).ravel() for x in f(p0, v0, p1, v1)]
    want = [
        hermite_position(p0, v0, p1, v1, T, 0.3),
        hermite_velocity(p0, v0, p1, v1, T, 0.3),
        *end_accelerations(p0, v0, p1, v1, T),
        *velocity_control_points(p0, v0, p1, v1, T),
    ]
    for g, w in zip(got, want, strict=True):
        assert g == pytest.approx(w, rel=1e-12, abs=1e-12)


def test_the_model_refuses_bad_limits_and_reads_a_scenario() -> None:
    with pytest.raises(ValueError, match="a_max_mps2"):
        VehicleModel(25.0, 0.0, 1.0)

    class Limits:
        v_max, a_max, dt = 22.5, 10.0, 1.0

    assert VehicleModel.of(Limits()) == VehicleModel(22.5, 10.0, 1.0)
    assert VehicleModel.of(Limits()).reach_radius_m == pytest.approx(2.5)
