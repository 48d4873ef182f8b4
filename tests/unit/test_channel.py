"""Channel, rate and radii (eq. 1-2, 14b, 19a, 20a), and the radar noise of eq. 8."""

from __future__ import annotations

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.model.channel import (
    channel_gain,
    control_range,
    full_band_rate,
    min_share,
    rate,
    rate_radius,
)
from isac_mission.model.radar import echo_snr, noise_variances


def test_gain_falls_with_square_of_3d_distance(paper: Scenario) -> None:
    d = np.array([0.0, 100.0, 1000.0])
    g = channel_gain(d, paper.dH, paper.beta0)
    np.testing.assert_allclose(g * (d**2 + paper.dH**2), paper.beta0)


def test_full_band_rates_match_paper_notes(paper: Scenario) -> None:
    # The full-band rate from the paper's constants: about 332 / 190 / 127 Mbit/s at 0 / 1 / 3 km.
    r = full_band_rate(np.array([0.0, 1000.0, 3000.0]), paper.dH, paper.rho0, paper.B) / 1e6
    np.testing.assert_allclose(r, [332, 190, 127], atol=1.0)


def test_rate_radius_is_where_share_just_meets_threshold(paper: Scenario) -> None:
    eta = np.array([0.05, 0.1, 0.3])
    r = rate_radius(eta, paper.r_th, paper.dH, paper.rho0, paper.B)
    np.testing.assert_allclose(rate(eta, r, paper.dH, paper.rho0, paper.B), paper.r_th, rtol=1e-9)
    np.testing.assert_allclose(
        min_share(r, paper.r_th, paper.dH, paper.rho0, paper.B), eta, rtol=1e-9
    )


def test_rate_radius_is_zero_when_no_distance_suffices(paper: Scenario) -> None:
    assert rate_radius(np.array([1e-4]), paper.r_th, paper.dH, paper.rho0, paper.B)[0] == 0.0


def test_control_snr_at_control_range_equals_threshold(paper: Scenario) -> None:
    d = control_range(paper.P_bs, paper.beta0, paper.noise_w, paper.gamma_th, paper.dH)
    snr = paper.P_bs * channel_gain(np.array(d), paper.dH, paper.beta0) / paper.noise_w
    assert float(snr) == pytest.approx(paper.gamma_th, rel=1e-9)
    assert control_range(1e-9, paper.beta0, paper.noise_w, paper.gamma_th, paper.dH) == 0.0


def test_echo_snr_matches_paper_notes(paper: Scenario) -> None:
    snr = echo_snr(np.array([100.0, 500.0, 1000.0]), paper.radar_gain)
    np.testing.assert_allclose(snr, [5.8e-2, 9.2e-5, 5.8e-6], rtol=0.02)


def test_range_noise_is_metres_at_half_to_one_km_and_scales_with_share(paper: Scenario) -> None:
    d = np.array([500.0, 1000.0])
    kw = {"radar_gain": paper.radar_gain, "alpha_d": paper.alpha_d, "alpha_v": paper.alpha_v}
    var_d, var_v = noise_variances(d, np.full(2, 1 / 3), B=paper.B, Ts=paper.Ts, **kw)
    assert 0.5 < np.sqrt(var_d[0]) < 5 and 2 < np.sqrt(var_d[1]) < 20
    var_d2, var_v2 = noise_variances(d, np.full(2, 2 / 3), B=paper.B, Ts=paper.Ts, **kw)
    np.testing.assert_allclose(var_d / var_d2, 4.0)
    np.testing.assert_allclose(var_v, var_v2)
    np.testing.assert_allclose(var_d[1] / var_d[0], 16.0)
