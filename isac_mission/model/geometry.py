"""Distances in the scenario plane. Positions are [..., 2] arrays in metres."""

from __future__ import annotations

import numpy as np

from isac_mission.types import FloatArray


def horizontal_distance(a_xy: FloatArray, b_xy: FloatArray) -> FloatArray:
    """||a - b|| over the last axis, broadcasting; metres."""
    return np.asarray(np.linalg.norm(np.asarray(a_xy) - np.asarray(b_xy), axis=-1))


def pairwise_distances(xy: FloatArray) -> FloatArray:
    """[M, M] distances between the rows of xy [M, 2]."""
    diff = xy[:, None, :] - xy[None, :, :]
    return np.asarray(np.linalg.norm(diff, axis=-1))


def uav_bs_distances(uav_xy: FloatArray, bs_xy: FloatArray) -> FloatArray:
    """[M, K] horizontal UAV-BS distances from uav_xy [M, 2] and bs_xy [K, 2]."""
    return np.asarray(np.linalg.norm(uav_xy[:, None, :] - bs_xy[None, :, :], axis=-1))
