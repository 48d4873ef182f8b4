"""Constant-velocity target motion (eq. 3-4). State x = [x, y, vx, vy] in m and m/s."""

from __future__ import annotations

import numpy as np

from isac_mission.types import FloatArray


def transition_matrix(dt: float) -> FloatArray:
    """F [4, 4] = [[1, dt], [0, 1]] kron I2 (eq. 3); dt in s."""
    return np.kron(np.array([[1.0, dt], [0.0, 1.0]]), np.eye(2))


def process_noise(dt: float, kappa: float) -> FloatArray:
    """W [4, 4] = kappa [[dt^3/3, dt^2/2], [dt^2/2, dt]] kron I2 (eq. 4); kappa in m^2/s^3."""
    block = np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    return kappa * np.kron(block, np.eye(2))
