"""experiment/bootstrap.py: seeded, paired, degenerate and bad inputs."""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.experiment.bootstrap import (
    paired_bootstrap,
    reduction_of_means,
    reduction_of_rms,
)


def test_statistics_on_known_values() -> None:
    b, o = np.array([2.0, 4.0]), np.array([1.0, 2.0])
    assert float(reduction_of_means(b, o)) == pytest.approx(50.0)
    assert float(reduction_of_rms(b, o)) == pytest.approx(100 * (1 - np.sqrt(0.5)))
    # resampled rows: one statistic per row
    assert reduction_of_means(np.ones((3, 2)), np.full((3, 2), 0.9)).shape == (3,)


def test_same_seed_same_interval_and_estimate_inside() -> None:
    rng = np.random.default_rng(1)
    b = rng.gamma(3.0, 1.0, 12)
    o = b * rng.uniform(0.6, 0.9, 12)
    a1 = paired_bootstrap(b, o, seed=5)
    assert a1 == paired_bootstrap(b, o, seed=5)
    assert a1.low < a1.estimate < a1.high
    assert a1.estimate == pytest.approx(float(reduction_of_means(b, o)))


def test_a_method_against_itself_gives_a_zero_width_interval() -> None:
    b = np.array([1.0, 2.0, 3.0, 5.0])
    iv = paired_bootstrap(b, b)
    assert (iv.estimate, iv.low, iv.high) == (0.0, 0.0, 0.0)


def test_a_constant_ratio_is_found_exactly_whatever_the_spread_of_runs() -> None:
    """Pairing: other = 0.7 baseline run by run, however much the runs differ, gives 30 % with
    no uncertainty (an unpaired bootstrap would give a wide interval)."""
    b = np.array([0.1, 10.0, 3.0, 50.0, 0.5])
    iv = paired_bootstrap(b, 0.7 * b)
    assert iv.low == pytest.approx(30.0) and iv.high == pytest.approx(30.0)


@pytest.mark.parametrize(
    ("b", "o"),
    [
        ([1.0], [1.0]),
        ([1.0, 2.0], [1.0]),
        ([1.0, np.nan], [1.0, 2.0]),
        ([[1.0, 2.0]], [[1.0, 2.0]]),
    ],
)
def test_bad_inputs_are_refused(b: list[float], o: list[float]) -> None:
    with pytest.raises(ValueError, match=r"runs|\[R\] arrays|finite"):
        paired_bootstrap(b, o)
