"""The paired bootstrap's 95 % interval covers a known reduction in about 95 % of Monte Carlo cases.

The case: R = 30 runs of two methods with paired per-run values, baseline x_r ~ Gamma(10, 1) (a
per-run mean bound or MSE: positive, skewed) and other y_r = x_r v_r with v_r ~ Gamma(50, 0.8/50)
independent of x_r, so E y / E x = 0.8: the true reduction of the means is 20 % and of the RMS
100 (1 - sqrt 0.8) = 10.56 %. Each of CASES cases draws fresh runs and one interval.

Tolerance: the observed coverage of CASES cases has binomial standard deviation
sqrt(0.95 * 0.05 / CASES) (1.09 % at 400); the check allows 3 of them either side, and below also
the interval's own finite-sample error at R = 30 (BCa is second-order accurate, error O(1/R); 2 %
allowed, measured 1.5 % with 1000 cases). An unpaired bootstrap (the two methods resampled
independently) over-covers this strongly correlated case (~100 %) and fails the upper bound; the
last test checks that this test can tell the two apart.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from isac_mission.experiment.bootstrap import (
    paired_bootstrap,
    reduction_of_means,
    reduction_of_rms,
)
from isac_mission.types import FloatArray

RUNS = 30
CASES = 400
RESAMPLES = 2000
RATIO = 0.8
LEVEL = 0.95
SIGMA = math.sqrt(LEVEL * (1 - LEVEL) / CASES)
LOW, HIGH = LEVEL - 3 * SIGMA - 0.02, LEVEL + 3 * SIGMA


def _case(rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    x = rng.gamma(10.0, 1.0, RUNS)
    return x, x * rng.gamma(50.0, RATIO / 50.0, RUNS)


@pytest.mark.parametrize(
    ("statistic", "truth"),
    [(reduction_of_means, 100 * (1 - RATIO)), (reduction_of_rms, 100 * (1 - math.sqrt(RATIO)))],
)
def test_paired_interval_covers_the_true_reduction_at_its_level(statistic, truth) -> None:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(2026)
    hits = 0
    for case in range(CASES):
        x, y = _case(rng)
        hits += paired_bootstrap(x, y, statistic, resamples=RESAMPLES, seed=case).contains(truth)
    assert LOW <= hits / CASES <= HIGH, hits / CASES


def _unpaired(x: FloatArray, y: FloatArray, seed: int) -> tuple[float, float]:
    """Percentile interval of the reduction of means with x and y resampled independently."""
    g = np.random.default_rng(seed)
    ix = g.integers(0, RUNS, size=(RESAMPLES, RUNS))
    iy = g.integers(0, RUNS, size=(RESAMPLES, RUNS))
    boot = 100 * (1 - y[iy].mean(axis=1) / x[ix].mean(axis=1))
    lo, hi = np.quantile(boot, [(1 - LEVEL) / 2, (1 + LEVEL) / 2])
    return float(lo), float(hi)


def test_an_unpaired_bootstrap_would_fail_the_coverage_check() -> None:
    rng = np.random.default_rng(2026)
    hits, width_ratio = 0, []
    for case in range(CASES):
        x, y = _case(rng)
        lo, hi = _unpaired(x, y, case)
        hits += lo <= 100 * (1 - RATIO) <= hi
        paired = paired_bootstrap(x, y, resamples=RESAMPLES, seed=case)
        width_ratio.append((hi - lo) / (paired.high - paired.low))
    assert hits / CASES > HIGH
    assert float(np.median(width_ratio)) > 2.0
