"""sim/target.py: the CV target has the model's process noise and stays in the area."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from isac_mission.config import parse_scenario
from isac_mission.model.kinematics import process_noise, transition_matrix
from sim.target import CvTarget, ScriptedTarget, reflect_into_area

ALPHA = 1e-3  # two-sided: 99.9 % intervals


def _increments(target: CvTarget, n: int, dt: float) -> np.ndarray:
    F = transition_matrix(dt)
    out = np.empty((n, 4))
    x = target.state
    for i in range(n):
        nxt = target.advance()
        out[i] = nxt - F @ x
        x = nxt
    return out


def test_cv_increments_have_covariance_w_within_chi_square_bounds() -> None:
    s = parse_scenario({})
    n = 20_000
    target = CvTarget(s.x0, s.dt, s.kappa, np.random.default_rng(7), bounds_m=None)
    w = _increments(target, n, s.dt)
    W = process_noise(s.dt, s.kappa)
    lo, hi = stats.chi2.ppf(ALPHA / 2, n), stats.chi2.ppf(1 - ALPHA / 2, n)
    # Each component: sum of squares / W_ii ~ chi2(n) (zero mean known).
    for i in range(4):
        q = float(np.sum(w[:, i] ** 2) / W[i, i])
        assert lo < q < hi, f"component {i}: {q:.0f} outside chi2({n}) [{lo:.0f}, {hi:.0f}]"
    # Whitened increments are iid N(0, 1): the cross terms (position-velocity correlation of W)
    # are right when the whitened components are uncorrelated.
    z = np.linalg.solve(np.linalg.cholesky(W), w.T).T
    z_bound = stats.norm.ppf(1 - ALPHA / 2)
    for i in range(4):
        for j in range(i + 1, 4):
            r = float(np.sum(z[:, i] * z[:, j]) / np.sqrt(n))
            assert abs(r) < z_bound, f"whitened components {i}, {j} correlate: {r:.2f}"
    total = float(np.sum(z**2))
    assert stats.chi2.ppf(ALPHA / 2, 4 * n) < total < stats.chi2.ppf(1 - ALPHA / 2, 4 * n)


def test_cv_target_never_leaves_the_area() -> None:
    s = parse_scenario({})
    # A fast, very noisy target so that it hits the walls many times.
    target = CvTarget(
        np.array([100.0, 2900.0, -300.0, 250.0]),
        s.dt,
        kappa=2000.0,
        rng=np.random.default_rng(3),
        bounds_m=s.area,
    )
    xs = np.array([target.advance() for _ in range(5000)])
    assert np.all(xs[:, 0] >= 0) and np.all(xs[:, 0] <= s.area[0])
    assert np.all(xs[:, 1] >= 0) and np.all(xs[:, 1] <= s.area[1])
    # and it did reach both sides of the area (the bounds were exercised)
    assert xs[:, 0].min() < 300 and xs[:, 0].max() > s.area[0] - 300


@pytest.mark.parametrize(
    ("state", "expected"),
    [
        ([-5.0, 10.0, -3.0, 2.0], [5.0, 10.0, 3.0, 2.0]),  # below 0: mirrored, vx flipped
        ([105.0, 10.0, 3.0, 2.0], [95.0, 10.0, -3.0, 2.0]),  # above W
        ([10.0, 130.0, 3.0, 2.0], [10.0, 70.0, 3.0, -2.0]),  # above H
        ([205.0, 10.0, 3.0, 2.0], [5.0, 10.0, 3.0, 2.0]),  # two bounces: no net flip
        ([50.0, 50.0, 3.0, 2.0], [50.0, 50.0, 3.0, 2.0]),  # inside: unchanged
    ],
)
def test_reflection_mirrors_position_and_flips_velocity(
    state: list[float], expected: list[float]
) -> None:
    out = reflect_into_area(np.array(state), np.array([100.0, 100.0]))
    np.testing.assert_allclose(out, expected)


def test_cv_target_starts_at_x0_and_is_reproducible_from_its_seed() -> None:
    s = parse_scenario({})
    a = CvTarget(s.x0, s.dt, s.kappa, np.random.default_rng(11), bounds_m=s.area)
    b = CvTarget(s.x0, s.dt, s.kappa, np.random.default_rng(11), bounds_m=s.area)
    np.testing.assert_array_equal(a.state, s.x0)
    for _ in range(20):
        np.testing.assert_array_equal(a.advance(), b.advance())
    assert a.slot == 20


def test_cv_target_rejects_a_start_outside_the_area() -> None:
    with pytest.raises(ValueError, match="outside"):
        CvTarget(
            np.array([-1.0, 5.0, 0, 0]), 1.0, 0.5, np.random.default_rng(0), np.array([10.0, 10])
        )


def test_scripted_target_flies_the_polyline_at_constant_speed_and_stops() -> None:
    t = ScriptedTarget([[0.0, 0.0], [100.0, 0.0], [100.0, 50.0]], speed_mps=10.0, dt_s=1.0)
    np.testing.assert_allclose(t.state, [0, 0, 10, 0])
    for _ in range(12):
        t.advance()
    np.testing.assert_allclose(t.state, [100, 20, 0, 10])
    np.testing.assert_allclose(t.state_at(100.0), [100, 50, 0, 0])


def test_scripted_target_loops_back_to_its_first_waypoint() -> None:
    t = ScriptedTarget([[0.0, 0.0], [30.0, 0.0]], speed_mps=10.0, dt_s=1.0, loop=True)
    np.testing.assert_allclose(t.state_at(4.0), [20, 0, -10, 0])
    np.testing.assert_allclose(t.state_at(6.0)[:2], [0, 0], atol=1e-9)


def test_world_target_starts_at_a_seeded_draw_from_p0_around_the_cue() -> None:
    """The configured x0 is the tracker's cue; the true start is x0 + e, e ~ N(0, P0), by seed."""
    from isac_mission.config import parse_scenario
    from sim.world_assembly import make_target
    from sim.world_options import WorldOptions

    s = parse_scenario({})
    rng = np.random.default_rng
    starts = np.array([make_target(s, WorldOptions(), rng(k), k).state for k in range(400)])
    again = make_target(s, WorldOptions(), rng(0), 0).state
    np.testing.assert_array_equal(again, starts[0])
    err = starts - s.x0
    # Sample covariance of 400 draws within a few standard errors of P0's diagonal.
    np.testing.assert_allclose(err.var(axis=0), np.diag(s.P0), rtol=0.25)
    exact = make_target(s, WorldOptions(initial_error=False), rng(0), 0).state
    np.testing.assert_array_equal(exact, s.x0)


def test_the_world_target_flies_simulates_path_for_the_seed() -> None:
    """`run --seed S` and `simulate --seed S` (run 0) see the same target: the world draws the
    offline run's process noise (model/run_noise.py), and its initial error as the cue's."""
    from isac_mission.config import parse_scenario
    from isac_mission.experiment.closed_loop import draw_run_noise, true_trajectory
    from sim.world_assembly import make_target
    from sim.world_options import WorldOptions

    s = parse_scenario({})
    for seed in (1, 31):
        want = true_trajectory(s, draw_run_noise(s, seed))
        options = WorldOptions(initial_error=False, reflect_target=False)
        target = make_target(s, options, np.random.default_rng(99), seed)
        got = np.array([target.state, *(target.advance() for _ in range(s.N))])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
        # Past the mission the world's own stream goes on (a long-lived service).
        assert np.all(np.isfinite(target.advance()))
        cued = make_target(s, WorldOptions(), np.random.default_rng(99), seed)
        np.testing.assert_allclose(cued.state, s.x0 - draw_run_noise(s, seed).initial_error)
