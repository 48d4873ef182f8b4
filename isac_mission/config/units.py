"""Unit conversions of the scenario files: dB and dBm to linear SI values, the speed of light."""

from __future__ import annotations

SPEED_OF_LIGHT_MPS = 299_792_458.0


def db_to_linear(db: float) -> float:
    """10^(dB/10)."""
    return float(10.0 ** (db / 10.0))


def dbm_to_w(dbm: float) -> float:
    """Power in dBm to watts."""
    return db_to_linear(dbm) * 1e-3
